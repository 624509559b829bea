"""twin live against the faults of a real installation: long gaps, inputs stamped apart, servers without source
timestamps, interrupted sessions, implausible readings, unwritable output nodes, clocks that jump back, sensors
that stop.  Observer tests on the ROM; client tests against a real asyncua server on 127.0.0.1."""
from __future__ import annotations

import asyncio
import logging

import numpy as np
import pytest

from twin.cli import main as twin_main
from twin.errors import TwinInputError
from twin.live.cli import DEFAULT_THERMOMETERS, free_port
from twin.live.client import LiveClient
from twin.live.multiple_model import live_observer
from twin.live.observer import DriftObserver, Estimate
from twin.live.replay import ReplayServer, default_node_map, timestamp

THERMOMETERS = list(DEFAULT_THERMOMETERS)
CHANNELS = ["spindle", "T15", *THERMOMETERS]
NAN6 = np.full(len(THERMOMETERS), np.nan)


@pytest.fixture(scope="module")
def rom(machine):
    from twin.rom.reduction import cached_rom

    return cached_rom(machine, 80)


def _sample(t, rpm=0.0):
    return [rpm, 20.0] + [20.0] * len(THERMOMETERS)


def _client(server, rom, **kw):
    node_map = default_node_map(THERMOMETERS, "T15", index=server.index)
    return LiveClient(server.endpoint, node_map, DriftObserver(rom, THERMOMETERS), **kw)


async def _until_subscribed(client, task):
    while not client._subscribed and not task.done():
        await asyncio.sleep(0.01)


async def _write(server, name, value, *, source=None, server_stamp=None, status=None):
    """One value as a server of the field may send it: any timestamps, any status."""
    from asyncua import ua

    dv = ua.DataValue(ua.Variant(float(value), ua.VariantType.Double), SourceTimestamp=source,
                      ServerTimestamp=server_stamp, StatusCode=ua.StatusCode(status or ua.StatusCodes.Good))
    await server.server.write_attribute_value(server.nodes[name].nodeid, dv)


def _warnings(caplog, text):
    return [r.getMessage() for r in caplog.records if text in r.getMessage()]


# ----------------------------------------------------------------------------- D1: a long gap
@pytest.mark.parametrize("gap_s", [2400.0, 3600.0, 86400.0])
def test_a_long_gap_is_a_longer_prediction_not_nan_for_ever(rom, gap_s):
    """A machine idle in 20 °C air, readings 20 °C, then silence for ``gap_s`` (a network down for hours)."""
    ob = DriftObserver(rom, THERMOMETERS)
    y = np.full(len(THERMOMETERS), 20.0)
    for t in (0.0, 10.0, 10.0 + gap_s, 20.0 + gap_s, 30.0 + gap_s):
        e = ob.step(t, 0.0, 20.0, y)
        assert np.all(np.isfinite(e.drift_um)) and np.all(e.band_um > 0) and np.all(np.isfinite(e.band_um))
        assert np.abs(e.drift_um).max() < 0.5          # idle in the same air: still no drift


def test_an_estimate_that_is_not_finite_stops_the_session_and_is_never_written(tmp_path, capsys, monkeypatch):
    """Whatever makes the filter fail, NaN must not reach the log or the nodes as an estimate, nor exit 0."""
    class FailsAtThird:
        thermometers = THERMOMETERS
        k = 0

        def step(self, t, rpm, room, y):
            if not np.isfinite(room):
                return None
            self.k += 1
            value = np.nan if self.k >= 3 else -float(self.k)
            return Estimate(t, np.full(3, value), np.full(3, 1.0), np.zeros(0), 6)

    monkeypatch.setattr("twin.live.cli._observer", lambda args, default: (FailsAtThird(), THERMOMETERS))
    log = tmp_path / "drift.csv"
    code = twin_main(["live", "--replay", str(_dataset(tmp_path / "rec.csv", 6)), "--speed", "50", "--log", str(log)])
    err = capsys.readouterr().err
    assert code == 1
    assert "twin live: the observer's estimate at t = 20 s is not finite (X nan ± 1.00 µm" in err
    assert f"its partial log is kept as {log}.part" in err and "Traceback" not in err
    assert not log.exists()
    rows = np.genfromtxt(f"{log}.part", delimiter=",", names=True)
    assert list(rows["time_s"]) == [0.0, 10.0] and np.all(np.isfinite(rows["Z_estimate_um"]))


def _dataset(path, n, dt_s=10.0):
    from twin.core.dataset import ChannelInfo, Dataset

    channels = [ChannelInfo("spindle", "rpm", "spindle_speed", "", None), ChannelInfo("T15", "degC", "air", "", None),
                *(ChannelInfo(t, "degC", "temperature", "", None) for t in THERMOMETERS)]
    Dataset(np.arange(n) * dt_s, np.full((n, len(channels)), 20.0), channels).write(path)
    return path


# ----------------------------------------------------------------------------- D3: inputs held one by one
def test_each_input_is_held_on_its_own(rom):
    """Same heat-up and air swing (a) with both inputs in one sample, (b) the room air stamped 5 ms after the speed
    (per-node source timestamps) and the speed reported only when it changes."""
    t = np.arange(0.0, 7200.0 + 1, 60.0)
    rpm = np.where(t < 3600.0, 9000.0, 0.0)
    room = 20.0 + 3.0 * np.sin(t / 1500.0)
    a, b = DriftObserver(rom, THERMOMETERS), DriftObserver(rom, THERMOMETERS)
    za, zb, previous = [], [], None
    for ti, s, r in zip(t, rpm, room):
        za.append(a.step(ti, s, r, NAN6).drift_um[2])
        b.step(ti, s if s != previous else np.nan, np.nan if ti else r, NAN6)
        if ti:
            zb.append(b.step(ti + 0.005, np.nan, r, NAN6).drift_um[2])
        else:
            zb.append(za[0])
        previous = s
    assert np.abs(za).max() > 10.0
    # (b) has each room air reading one sample later (over the 5 ms after it, not the 60 s before): 2 % at most
    assert np.abs(np.subtract(zb, za)).max() < 0.02 * np.abs(za).max()


# ----------------------------------------------------------------------------- D2: readings not to be fused
def test_a_power_on_spike_is_left_out_by_the_innovation_gate_but_a_warm_start_is_followed(rom):
    ob, reference = live_observer(rom, THERMOMETERS), live_observer(rom, THERMOMETERS)
    y = np.full(len(THERMOMETERS), 20.0)
    spiked, left_out = y.copy(), y.copy()
    spiked[3], left_out[3] = 85.0, np.nan                     # a DS18x20's power-on value at t = 200 s
    times = np.arange(0.0, 300.0, 10.0)
    estimates = [ob.step(t, 0.0, 20.0, spiked if t == 200.0 else y) for t in times]
    expected = [reference.step(t, 0.0, 20.0, left_out if t == 200.0 else y) for t in times]
    np.testing.assert_allclose([e.drift_um for e in estimates], [e.drift_um for e in expected], atol=1e-9)
    assert [list(np.flatnonzero(e.rejected)) for e in estimates] == [[3] if t == 200.0 else [] for t in times]
    warm = live_observer(rom, THERMOMETERS)
    e = warm.step(0.0, 0.0, 20.0, np.full(len(THERMOMETERS), 26.0))     # 6 K above the room: the model is off
    assert e.used == len(THERMOMETERS) and not e.rejected.any()


def test_readings_with_a_bad_status_or_out_of_range_or_off_the_model_are_left_out_and_named_once(rom, caplog):
    from asyncua import ua

    async def main():
        async with ReplayServer(CHANNELS, port=free_port()) as server:
            client = _client(server, rom, late_after_s=0.3)
            reference = DriftObserver(rom, THERMOMETERS)
            task = asyncio.create_task(client.run(until_time_s=90.0, max_wall_s=60))
            await _until_subscribed(client, task)
            for k in range(10):
                t = 10.0 * k
                y = np.full(len(THERMOMETERS), 20.0)
                faults = {THERMOMETERS[0]: (-127.0, None), THERMOMETERS[1]: (85.0, ua.StatusCodes.UncertainSensorNotAccurate),
                          "T15": (20.0, ua.StatusCodes.BadSensorFailure)} if k >= 3 else {}
                if k == 6:
                    faults[THERMOMETERS[3]] = (85.0, None)           # a power-on spike: the gate's
                for name, value in zip(CHANNELS, _sample(t)):
                    value, status = faults.get(name, (value, None))
                    await _write(server, name, value, source=timestamp(t), status=status)
                expected = reference.step(t, 0.0, 20.0, np.where(
                    [k >= 3, k >= 3, False, k == 6, False, False], np.nan, y))
            return await task, expected

    caplog.set_level(logging.INFO, logger="thermal_twin")
    stats, expected = asyncio.run(main())
    np.testing.assert_allclose(stats.last.drift_um, expected.drift_um, atol=1e-9)
    assert stats.rejected == (f"{THERMOMETERS[0]} 7 (outside the plausible range), {THERMOMETERS[1]} 7 (status not Good), "
                              f"room_air 7 (status not Good), {THERMOMETERS[3]} 1 (innovation gate)")
    assert len(_warnings(caplog, f"[thermometers] {THERMOMETERS[0]} = ")) == 1
    assert len(_warnings(caplog, "UncertainSensorNotAccurate")) == 1
    assert len(_warnings(caplog, "more than 20 σ from what the model predicts")) == 1


# ----------------------------------------------------------------------------- D4: timestamps a server may not send
@pytest.mark.parametrize("stamps", ["server", "none"])
def test_values_without_a_source_timestamp_are_timed_by_the_server_timestamp_or_their_arrival(rom, caplog, stamps):
    async def main():
        async with ReplayServer(CHANNELS, port=free_port()) as server:
            client = _client(server, rom, late_after_s=0.2)
            task = asyncio.create_task(client.run(max_wall_s=60))
            await _until_subscribed(client, task)
            for k in range(5):
                # values that change: without a SourceTimestamp, an equal value is no data change to notify
                for name, value in zip(CHANNELS, np.add(_sample(10.0 * k), 0.01 * k)):
                    await _write(server, name, value, server_stamp=timestamp(10.0 * k) if stamps == "server" else None)
                await asyncio.sleep(0.05)
            while client.stats.samples < (5 if stamps == "server" else 1) and not task.done():
                await asyncio.sleep(0.02)
            task.cancel()
            return client.stats

    caplog.set_level(logging.INFO, logger="thermal_twin")
    stats = asyncio.run(main())
    if stamps == "server":
        assert [h[0] for h in stats.history][-5:] == [0.0, 10.0, 20.0, 30.0, 40.0]
    assert np.all(np.isfinite(stats.last.drift_um))
    clock = "ServerTimestamp" if stamps == "server" else "the client's receive time"
    assert len(_warnings(caplog, f"without a SourceTimestamp: those samples are timed by {clock}")) == 1
    assert not _warnings(caplog, "Exception calling")


# ----------------------------------------------------------------------------- D8: how the session ended
def test_ctrl_c_leaves_a_partial_log_under_a_name_that_says_so(tmp_path, capsys, monkeypatch, rom):
    class InterruptedAtThird(DriftObserver):
        k = 0

        def step(self, t, rpm, room, y):
            self.k += 1
            if self.k == 4:                      # the empty start sample, two fused, then Ctrl-C
                raise KeyboardInterrupt
            return super().step(t, rpm, room, y)

    observer = InterruptedAtThird(rom, THERMOMETERS)
    monkeypatch.setattr("twin.live.cli._observer", lambda args, default: (observer, THERMOMETERS))
    log = tmp_path / "drift.csv"
    code = twin_main(["live", "--replay", str(_dataset(tmp_path / "rec.csv", 6)), "--speed", "50", "--log", str(log)])
    err = capsys.readouterr().err
    assert code == 130
    assert f"twin live: interrupted; its partial log is kept as {log}.part" in err
    assert "no result was written" not in err
    assert not log.exists()
    assert list(np.genfromtxt(f"{log}.part", delimiter=",", names=True)["time_s"]) == [0.0, 10.0]
    # the next session does not write over it unasked
    assert twin_main(["live", "--replay", str(tmp_path / "rec.csv"), "--log", str(log)]) == 2
    assert f"{log}.part: exists; pass --overwrite" in capsys.readouterr().err


def test_a_session_that_ends_disconnected_keeps_its_log_partial(tmp_path, rom):
    class LostAfterTwoSamples(LiveClient):
        """Fuses two samples, loses the connection, and never gets it back."""

        async def _session(self, stop):
            self._subscribed = not self.stats.samples
            for t in (0.0, 10.0) if self._subscribed else ():
                self.csv.write(self.observer.step(t, 0.0, 20.0, np.full(len(THERMOMETERS), 20.0)))
                self.stats.samples += 1
            raise ConnectionError("connection lost")

    node_map = default_node_map(THERMOMETERS)
    client = LostAfterTwoSamples("opc.tcp://127.0.0.1:4840/", node_map, DriftObserver(rom, THERMOMETERS),
                                 tmp_path / "drift.csv", backoff_s=0.01)
    stats = asyncio.run(client.run(max_wall_s=0.05))
    assert not stats.ended_connected
    assert not (tmp_path / "drift.csv").exists() and (tmp_path / "drift.csv.part").exists()
    assert stats.log == tmp_path / "drift.csv.part"


def test_the_reconnect_backoff_never_outlasts_the_duration(tmp_path, rom):
    node_map = default_node_map(THERMOMETERS)
    client = LiveClient(f"opc.tcp://127.0.0.1:{free_port()}/x/", node_map, DriftObserver(rom, THERMOMETERS),
                        backoff_s=60.0, max_backoff_s=60.0)
    stats = asyncio.run(client.run(max_wall_s=0.5))
    assert stats.failed_attempts >= 1 and stats.wall_s < 30.0     # not the 60 s backoff


# ----------------------------------------------------------------------------- D5: output nodes
@pytest.mark.parametrize("kind", ["read-only", "string", "float", "input"])
def test_output_nodes_are_checked_at_the_start_and_a_float_one_gets_floats(rom, tmp_path, kind):
    from asyncua import ua

    async def main():
        async with ReplayServer(CHANNELS, port=free_port()) as server:
            node_map = default_node_map(THERMOMETERS, "T15", index=server.index)
            node_map.source = str(tmp_path / "machine.toml")
            machine = await server.server.nodes.objects.add_object(server.index, "Cnc")
            variant = {"string": ua.VariantType.String, "float": ua.VariantType.Float}.get(kind, ua.VariantType.Double)
            if kind == "input":
                node_map.outputs["Z"] = f"ns={server.index};s=T15"          # the room air's node
            else:
                value = "0" if kind == "string" else 0.0
                var = await machine.add_variable(ua.NodeId("Z_out", server.index), "Z_out", value, variant)
                if kind != "read-only":
                    await var.set_writable()
                node_map.outputs["Z"] = f"ns={server.index};s=Z_out"
            client = LiveClient(server.endpoint, node_map, DriftObserver(rom, THERMOMETERS))
            task = asyncio.create_task(client.run(until_time_s=20.0, max_wall_s=15))
            await _until_subscribed(client, task)
            for k in range(3):
                await server.publish(10.0 * k, _sample(10.0 * k, rpm=9000.0))
            stats = await task
            return stats, await server.server.get_node(node_map.outputs["Z"]).read_value()

    if kind == "float":
        stats, written = asyncio.run(main())
        assert written == pytest.approx(stats.last.drift_um[2], rel=1e-6)
        return
    expected = {"read-only": r"machine.toml: \[outputs\] Z = 'ns=2;s=Z_out': not writable on opc.tcp://127.0.0.1",
                "input": r"machine.toml: \[outputs\] Z = 'ns=2;s=T15': the node of \[inputs\] room_air too",
                "string": r"machine.toml: \[outputs\] Z = 'ns=2;s=Z_out': data type String on opc.tcp://127.0.0.1"}
    with pytest.raises(TwinInputError, match=expected[kind]):
        asyncio.run(main())


# ----------------------------------------------------------------------------- D6, D7: clocks and stale nodes
def _twenty_samples(rom, sample_of, *, late_after_s):
    """The stats of a client while the server publishes 20 samples: ``sample_of(k)`` gives sample k's source
    timestamp (s), its values and the channels they are for."""
    async def main():
        async with ReplayServer(CHANNELS, port=free_port()) as server:
            client = _client(server, rom, late_after_s=late_after_s)
            task = asyncio.create_task(client.run(until_time_s=190.0, max_wall_s=60))
            await _until_subscribed(client, task)
            for k in range(20):
                await server.publish(*sample_of(k))
                await asyncio.sleep(0.01)
            return await task

    return asyncio.run(main())


def test_a_source_clock_that_jumps_back_is_said_once_and_re_anchored(rom, caplog):
    def sample_of(k):
        stamp = 10.0 * k - (3600.0 if k >= 10 else 0.0)                  # the controller's clock set back 1 h
        return stamp, _sample(10.0 * k, rpm=9000.0), CHANNELS

    caplog.set_level(logging.INFO, logger="thermal_twin")
    # every sample waits for all its readings (a loaded machine must not fuse one early and count the rest
    # late): what is late here is late for the clock alone
    stats = _twenty_samples(rom, sample_of, late_after_s=30.0)
    assert [h[0] for h in stats.history][-20:] == [10.0 * k for k in range(20)]
    assert stats.late == 0
    jumps = _warnings(caplog, "the timestamps jumped back 3590 s")
    assert len(jumps) == 1 and "2025-12-31T23:01:40+00:00" in jumps[0] and "t = 100 s" in jumps[0]


def test_a_thermometer_that_stops_updating_is_named_once(rom, caplog):
    def sample_of(k):
        names = CHANNELS if k <= 5 else [c for c in CHANNELS if c != THERMOMETERS[0]]
        values = dict(zip(CHANNELS, _sample(10.0 * k)))
        return 10.0 * k, [values[n] for n in names], names

    caplog.set_level(logging.INFO, logger="thermal_twin")
    stats = _twenty_samples(rom, sample_of, late_after_s=0.1)
    assert stats.samples >= 20
    stale = _warnings(caplog, "has not updated since")
    assert len(stale) == 1 and f"[thermometers] {THERMOMETERS[0]} = " in stale[0] and "since t = 50 s" in stale[0]
