"""twin live's clocks and gates as an installation meets them: a re-subscription that resends each node's
current value, a node that lags, a clock that jumps back with a straggler on its way or right after the first
sample; the innovation gate with one or two readings a sample; a speed read before the first room air; a node
two keys share; the command's --duration and --overwrite.  Fast: no ROM beyond the cached one, no server."""
from __future__ import annotations

import logging

import numpy as np
import pytest

from twin.cli import main as twin_main
from twin.errors import TwinInputError
from twin.live.nodemap import load_node_map
from twin.live.readings import ReadingChecks
from twin.live.samples import SampleAssembler

KEYS = ["spindle_speed", "room_air", "A", "B"]


class _Map:
    source = "machine.toml"

    def where(self, key):
        return key


def _assembler():
    return SampleAssembler(KEYS, 1.0, "opc.tcp://x", ReadingChecks(_Map(), ["A", "B"]))


class _Session:
    """An assembler fed by hand on a wall clock; ``fused`` the machine times it let through, in order."""

    def __init__(self):
        self.samples, self.fused, self.values, self.wall = _assembler(), [], {}, 0.0

    def add(self, key, t, value=20.0):
        self.samples.add(key, t, value, None, self.wall)

    def tick(self, wall_s):
        self.wall += wall_s
        for t in self.samples.ready(self.wall):
            self.values[t] = {key: value for key, (value, _) in self.samples.pop(t).items()}
            self.fused.append(t)


def _jumps(caplog):
    return [r.getMessage() for r in caplog.records if "jumped back" in r.getMessage()]


# ----------------------------------------------------------------------------- samples: the node's own clock
def test_a_resubscription_resending_an_on_change_speed_is_a_repeat_not_a_clock_jump(caplog):
    caplog.set_level(logging.WARNING, logger="thermal_twin")
    s = _Session()
    s.add("spindle_speed", 0.0)                         # reported on change: set at t = 0, never again
    for k in range(11):
        for key in KEYS[1:]:
            s.add(key, 10.0 * k)
        s.tick(1.5)
    # the reconnection: every node's current value again, the speed's stamped when it was set
    for key, t in [("spindle_speed", 0.0), ("room_air", 100.0), ("A", 100.0), ("B", 100.0)]:
        s.add(key, t)
    for k in range(11, 16):
        for key in KEYS[1:]:
            s.add(key, 10.0 * k)
        s.tick(1.5)
    assert s.fused == [10.0 * k for k in range(16)]
    assert s.samples.offset == 0.0 and s.samples.late == 4 and not _jumps(caplog)


def test_a_node_that_lags_a_sample_behind_is_late_not_a_clock_jump(caplog):
    caplog.set_level(logging.WARNING, logger="thermal_twin")
    s = _Session()
    s.wall = 100.0
    events = sorted([(100.0 + k, key, 100.0 + k) for k in range(20) for key in KEYS[:3]]
                    + [(101.5 + k, "B", 100.0 + k) for k in range(20)])   # B: 1.5 intervals late, always
    for wall, key, t in events:
        while s.wall < wall:
            s.tick(0.05)
        s.add(key, t)
    assert s.fused == [100.0 + k for k in range(20)]
    assert s.samples.offset == 0.0 and s.samples.late == 20 and not _jumps(caplog)


def test_a_straggler_of_the_last_sample_before_a_jump_is_late_never_shifted(caplog):
    caplog.set_level(logging.WARNING, logger="thermal_twin")
    s = _Session()
    for k in range(10):
        for key in KEYS:
            s.add(key, 10.0 * k)
        s.tick(0.1)
    for key in KEYS[:3]:
        s.add(key, 100.0)                               # B's value of t = 100 still on its way
    s.tick(1.5)
    # the clock set back 1 h; the batch brings B's straggler between the jumped values
    for key, t in [("A", 110 - 3600.0), ("spindle_speed", 110 - 3600.0), ("room_air", 110 - 3600.0),
                   ("B", 100.0), ("B", 110 - 3600.0)]:
        s.add(key, t)
    s.tick(0.1)
    for k in range(12, 20):
        for key in KEYS:
            s.add(key, 10.0 * k - 3600.0)
        s.tick(1.5)
    assert s.fused == [10.0 * k for k in range(20)]
    assert s.samples.late == 1
    jumps = _jumps(caplog)
    assert len(jumps) == 1 and "jumped back 3590 s" in jumps[0] and "continue at t = 110 s" in jumps[0]


def test_a_speed_reported_on_change_after_a_jump_takes_the_new_clock(caplog):
    caplog.set_level(logging.WARNING, logger="thermal_twin")
    s = _Session()
    s.add("spindle_speed", 0.0, 0.0)                    # reported on change: set at t = 0
    for k in range(20):
        stamp = 10.0 * k - (60.0 if k >= 10 else 0.0)              # the clock set back 1 min at k = 10
        if k == 13:
            s.add("spindle_speed", stamp, 9000.0)       # its first value since: later than its last, t = 0
        for key in KEYS[1:]:
            s.add(key, stamp)
        s.tick(1.5)
    assert s.fused == [10.0 * k for k in range(20)]
    assert s.values[130.0]["spindle_speed"] == 9000.0 and s.samples.late == 0
    assert len(_jumps(caplog)) == 1


def test_a_jump_right_after_the_first_sample_is_re_anchored(caplog):
    caplog.set_level(logging.WARNING, logger="thermal_twin")
    s = _Session()
    for k in range(30):
        for key in KEYS:
            s.add(key, 3600.0 if k == 0 else 10.0 * k)
        s.tick(0.5)
    assert s.fused == [3600.0 + 10.0 * k for k in range(30)]
    assert s.samples.late == 0
    jumps = _jumps(caplog)
    assert len(jumps) == 1 and "jumped back 3590 s" in jumps[0]


# ----------------------------------------------------------------------------- observer: gate and held speed
@pytest.fixture(scope="module")
def rom(machine):
    from twin.rom.reduction import cached_rom

    return cached_rom(machine, 80)


THERMOMETERS = ["T18", "T26", "T23", "T22", "T16", "T09"]


def _glitch_rejected(rom, thermometers, apart):
    """Readings rejected when T09 reads a DS18x20's 85 °C power-on value once on an idle machine in 20 °C air."""
    from twin.live.observer import DriftObserver

    observer, p, rejected = DriftObserver(rom, thermometers), len(thermometers), 0
    for k in range(12):
        t, y = 10.0 * k, np.full(p, 20.0)
        if k == 8:
            y[thermometers.index("T09")] = 85.0
        if not apart:
            e = observer.step(t, 0.0, 20.0, y)
            rejected += 0 if e is None else int(e.rejected.sum())
            continue
        observer.step(t, 0.0, 20.0, np.full(p, np.nan))              # each node its own sample
        for j in range(p):
            one = np.full(p, np.nan)
            one[j] = y[j]
            rejected += int(observer.step(t + 0.001 * (j + 1), np.nan, np.nan, one).rejected.sum())
    return rejected


@pytest.mark.parametrize("thermometers, apart", [(THERMOMETERS, True), (["T18", "T09"], False)],
                         ids=["stamped-apart", "two-thermometers"])
def test_a_power_on_spike_is_gated_with_one_or_two_readings_a_sample(rom, thermometers, apart):
    assert _glitch_rejected(rom, thermometers, apart) == 1


def test_two_thermometers_failing_together_are_kept(rom):
    """Both of two off at once is the model (a warm start), not a sensor: the filter follows them."""
    from twin.live.observer import DriftObserver

    observer = DriftObserver(rom, ["T18", "T09"])
    observer.step(0.0, 0.0, 20.0, [20.0, 20.0])
    e = observer.step(10.0, 0.0, 20.0, [45.0, 48.0])
    assert not e.rejected.any()


def test_a_speed_read_before_the_first_room_air_drives_the_model(rom):
    from twin.live.multiple_model import live_observer

    nan = np.full(len(THERMOMETERS), np.nan)
    every, once = live_observer(rom, THERMOMETERS), live_observer(rom, THERMOMETERS)
    once.step(-5.0, 9000.0, np.nan, nan)                 # reported on change: set before the room air came
    for k in range(31):
        a = every.step(10.0 * k, 9000.0, 20.0, nan)
        b = once.step(10.0 * k, np.nan, 20.0, nan)
    assert a.drift_um[2] < -1.0 and b.drift_um[2] == pytest.approx(a.drift_um[2], rel=1e-9)


@pytest.mark.parametrize("value, refused", [(1e9, True), (-1.2e5, True), (-9000.0, False), (24000.0, False)])
def test_an_implausible_spindle_speed_is_left_out(value, refused, caplog):
    checks = ReadingChecks(_Map(), ["A"])
    caplog.set_level(logging.WARNING, logger="thermal_twin")
    got = checks.reading("spindle_speed", value, None, 10.0)
    assert np.isnan(got) == refused
    if refused:
        assert checks.summary() == "spindle_speed 1 (outside the plausible range)"
        assert f"{value:g} rpm, outside the plausible -100000 … 100000 rpm of a spindle" in caplog.text


# ----------------------------------------------------------------------------- node map: one node, one key
MAP = '[inputs]\nspindle_speed = "ns=2;s=S"\nroom_air = "ns=2;s=T15"\n[thermometers]\nT18 = "ns=2;s=T18"\n'


@pytest.mark.parametrize("text, message", [
    (MAP + '[outputs]\nZ = "ns=2;s=T15"\n', "[outputs] Z = 'ns=2;s=T15': the node of [inputs] room_air too"),
    (MAP + '[outputs]\nZ = "ns=2;s=Z"\nZ_band = "ns=2;s=Z"\n',
     "[outputs] Z_band = 'ns=2;s=Z': the node of [outputs] Z too"),
    (MAP + 'T26 = "ns=2;s=T18"\n', "[thermometers] T26 = 'ns=2;s=T18': the node of [thermometers] T18 too"),
], ids=["output-on-input", "two-outputs", "two-thermometers"])
def test_a_node_two_keys_share_is_refused(tmp_path, text, message):
    path = tmp_path / "machine.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(TwinInputError) as info:
        load_node_map(path)
    assert str(info.value).startswith(f"{path}: {message}")


# ----------------------------------------------------------------------------- the command
@pytest.mark.parametrize("duration", ["0", "nan", "-5", "inf"])
def test_a_duration_that_never_or_at_once_ends_is_refused(tmp_path, capsys, monkeypatch, duration):
    import twin.live.cli as live_cli

    def observe(args):                                    # never reached: a session that may never end
        raise live_cli._Ended(1)

    monkeypatch.setattr(live_cli, "_observe", observe)
    node_map = tmp_path / "machine.toml"
    node_map.write_text(MAP, encoding="utf-8")
    assert twin_main(["live", "--endpoint", "opc.tcp://127.0.0.1:1/x/", "--node-map", str(node_map),
                      "--duration", duration]) == 2
    assert f"--duration must be a finite number of seconds > 0, got {float(duration):g}" in capsys.readouterr().err


def test_overwrite_removes_the_previous_sessions_complete_log(tmp_path, monkeypatch):
    """A session with --overwrite that ends disconnected leaves its partial log and no older complete one."""
    import twin.live.cli as live_cli

    log = tmp_path / "drift.csv"
    log.write_text("time_s\n1\n", encoding="utf-8")

    def observe(args):
        assert not log.exists()                           # gone before the session starts
        raise live_cli._Ended(1)

    monkeypatch.setattr(live_cli, "_observe", observe)
    node_map = tmp_path / "machine.toml"
    node_map.write_text(MAP, encoding="utf-8")
    assert twin_main(["live", "--endpoint", "opc.tcp://127.0.0.1:1/x/", "--node-map", str(node_map),
                      "--log", str(log), "--overwrite"]) == 1
    assert not log.exists()
