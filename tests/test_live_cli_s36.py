"""``twin live`` options an exploratory tester got wrong answers from (2026-11-28, s36): a thermometer named twice, a
channel two options name, a thermometer given as the spindle speed, ``--duration`` with ``--replay``, and a log in
a folder not made yet."""
from __future__ import annotations

import time

import numpy as np
import pytest

from twin.cli import main as twin_main
from twin.live.cli import DEFAULT_THERMOMETERS, free_port
from twin.live.replay import default_node_map

THERMOMETERS = list(DEFAULT_THERMOMETERS)


def _record(path, samples=3, step_s=10.0):
    """A replayable record at ``path``: spindle (rpm), room air T15 and the default thermometers (°C), every
    ``step_s`` s."""
    from twin.core.dataset import ChannelInfo, Dataset

    channels = [ChannelInfo("spindle", "rpm", "spindle_speed"), ChannelInfo("T15", "degC", "air"),
                *(ChannelInfo(t, "degC", "temperature") for t in THERMOMETERS)]
    t = np.arange(samples) * step_s
    values = np.full((samples, len(channels)), 20.0)
    values[:, 0] = 6000.0
    Dataset(t, values, channels).write(path)
    return path


@pytest.fixture
def no_server(monkeypatch):
    """Fail a test whose command starts the replay server."""
    async def refused(self):
        raise AssertionError("the replay server was started")

    monkeypatch.setattr("twin.live.replay.ReplayServer.__aenter__", refused)


@pytest.mark.parametrize("mode", ["replay", "endpoint"])
def test_a_thermometer_named_twice_is_refused_before_anything_starts(tmp_path, capsys, no_server, mode):
    """It crashed the replay server (BadNodeIdExists, exit 1); on a machine it would fuse one reading as two."""
    node_map = tmp_path / "machine.toml"
    node_map.write_text(default_node_map(THERMOMETERS).to_toml())
    where = {"replay": ["--replay", str(_record(tmp_path / "rec.csv"))],
             "endpoint": ["--endpoint", f"opc.tcp://127.0.0.1:{free_port()}/", "--node-map", str(node_map),
                          "--duration", "0.5"]}[mode]
    assert twin_main(["live", *where, "--thermometers", "T18,T26,T18"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "twin live: error: --thermometers names thermometer 'T18' more than once"


def test_a_channel_two_options_name_is_refused_before_the_server_starts(tmp_path, capsys, no_server):
    """T18, a default thermometer, as the room air too: one replay node made twice (BadNodeIdExists, exit 1)."""
    record = _record(tmp_path / "rec.csv")
    assert twin_main(["live", "--replay", str(record), "--room-air", "T18"]) == 2
    err = capsys.readouterr().err
    assert "thermometer 'T18': the channel of --room-air too" in err and "Traceback" not in err


def test_a_thermometer_as_the_spindle_speed_is_refused(tmp_path, capsys, no_server):
    """The record says T18 is a temperature (°C): taken as rpm it ran with exit 0 and no word."""
    record = _record(tmp_path / "rec.csv")
    assert twin_main(["live", "--replay", str(record), "--spindle", "T18"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"twin live: error: --spindle 'T18': a temperature channel (degC) in {record}; its spindle_speed "
                   "channels: spindle")


def test_duration_stops_a_replay_before_its_end(tmp_path, capsys):
    """A 2000 s record at 100× takes 20 wall s; ``--duration 1.5`` stops it after 1.5 s (it used to replay every
    sample), and the log of the session that ended as asked is complete."""
    record, log = _record(tmp_path / "rec.csv", samples=201), tmp_path / "drift.csv"
    start = time.monotonic()
    assert twin_main(["live", "--replay", str(record), "--speed", "100", "--duration", "1.5", "--log", str(log)]) == 0
    took = time.monotonic() - start
    out = capsys.readouterr().out
    rows = len(log.read_text().splitlines()) - 1
    assert took < 12.0 and 0 < rows < 201
    assert "replay of rec.csv at 100× stopped after " in out and "(--duration 1.5 s), at machine time " in out
    assert f"of 2000 s ({rows} of 201 samples)" in out


def test_a_log_in_a_folder_not_made_yet_is_written_there(tmp_path, capsys):
    """Like every twin output: the folder is made (it was an error about ``drift.csv.part``, after the server had
    started)."""
    log = tmp_path / "new" / "sub" / "drift.csv"
    assert twin_main(["live", "--replay", str(_record(tmp_path / "rec.csv")), "--speed", "100", "--log", str(log)]) == 0
    assert f"log written to {log}" in capsys.readouterr().out
    assert len(log.read_text().splitlines()) == 4


def test_a_log_whose_folder_cannot_be_made_is_refused_before_anything_starts(tmp_path, capsys, no_server):
    (tmp_path / "notes.txt").write_text("a file\n")
    log = tmp_path / "notes.txt" / "drift.csv"
    assert twin_main(["live", "--replay", str(_record(tmp_path / "rec.csv")), "--log", str(log)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"twin live: error: {log}: cannot be created: {tmp_path / 'notes.txt'} is a file, not a folder"
