"""Inputs that were taken silently: a scenario's ambient CSV timed in hours or minutes under a header that says so,
an operating input of ``twin gap`` unread at the record's start or end (held, with no word), and ``twin train
--machine`` building the machine once per scenario dataset."""
import numpy as np
import pytest

from meshes.tomlspec import DefinitionError, Table
from twin.core.scenario import HOUR, load_scenario


@pytest.mark.parametrize("header, factor", [("time_h", "3600"), ("t [min]", "60"), ("elapsed_min", "60")])
def test_an_ambient_csv_whose_time_header_names_another_unit_is_refused(tmp_path, header, factor):
    """The file's times span the scenario read in s (0 … 7200), so the span check passes them: the header alone
    says they are not in s.  They had been read as seconds."""
    times = np.arange(0.0, 2 * HOUR + 1, 600.0)
    rows = "".join(f"{t:g},{20.0 + 0.1 * k:g}\n" for k, t in enumerate(times))
    (tmp_path / "air.csv").write_text(f"{header},ambient_degC\n{rows}")
    path = tmp_path / "day.toml"
    path.write_text(f'[scenario]\nduration_h = 2\nsample_interval_s = 600.0\n[ambient]\nkind = "csv"\n'
                    f'file = "air.csv"\ntime_column = "{header}"\n')
    with pytest.raises(DefinitionError) as err:
        load_scenario(path)
    message = str(err.value)
    assert message.startswith(f"{path}: ambient.time_column names a column whose header says ") and message.endswith(
        f"{header!r}")
    assert f"write the column in s (× {factor}) as time_s" in message


@pytest.mark.parametrize("header", ["time_h", "t [min]", "elapsed_min", "time_s", "t"])
def test_a_scenario_and_a_measured_csv_give_one_reason_for_a_time_header(header):
    """Both refusals had their own wording (and code); they give the dataset's one text now."""
    from twin.core.dataset import _refuse_other_time_unit, other_time_unit_text
    from twin.core.scenario import _refuse_other_time_unit as refuse_in_scenario
    from twin.errors import TwinInputError

    text = other_time_unit_text(header)
    refusals = []
    for refuse, where in ((_refuse_other_time_unit, ("air.csv", header, False)),
                          (refuse_in_scenario, (Table({"time_column": header}, "day.toml", "ambient"), header))):
        try:
            refuse(*where)
        except (TwinInputError, DefinitionError) as err:
            refusals.append(str(err))
    assert len(refusals) == (0 if text is None else 2)
    assert all(text in r for r in refusals)


@pytest.fixture(scope="module")
def quick_truth():
    """The gap tests' quick record (gap_quick_8h, 8 h every 2 min, no effect) and its machine."""
    from twin.gap.diagnose import _machine
    from twin.gap.truth import truth_dataset

    machine = _machine("vmc_ram")
    return machine, truth_dataset("gap_quick_8h", machine, [])


def _unread(data, channel, rows, source):
    """``data`` with ``channel`` left empty on ``rows`` (bool), as ``source``."""
    from twin.core.dataset import Dataset

    values = data.values.copy()
    values[rows, data.names.index(channel)] = np.nan
    return Dataset(data.time_s, values, data.channels, {"source": source})


def test_a_spindle_unread_for_the_first_half_hour_is_said_to_be_held(quick_truth):
    """Unread from the record's start, the spindle is held at its first reading and no outage is judged: that had
    been said nowhere.  The record's warnings are the first of the diagnosis's notes (diagnosis.json, the report)
    and are printed by ``twin gap diagnose``; a full diagnosis would add the engine's 6–20 s."""
    from twin.gap.measured import match_record

    machine, data = quick_truth
    record = match_record(_unread(data, "spindle", data.time_s < 1800.0, "late.csv"), machine)
    assert record.report["warnings"] == [(
        "column 'spindle_rpm' is not read from 0 s to 1800 s into the record (0.00–0.50 h, from the record's start "
        "to its first reading): the twin holds that reading (0) there, and judges no outage without a reading on "
        "both sides")]


def test_the_note_quotes_the_spindle_speed_held_not_its_signed_reading(quick_truth):
    """A spindle logged with its sign (reverse rotation): the twin runs on the magnitude, and holds 9000 rpm before
    the first reading of −9000; the note had quoted −9000."""
    from twin.gap.measured import match_record

    machine, data = quick_truth
    reversed_ = _unread(data, "spindle", data.time_s < 1900.0, "reversed.csv")
    reversed_.values[:, data.names.index("spindle")] *= -1.0               # first reading at 1920 s: −9000 rpm
    warnings = match_record(reversed_, machine).report["warnings"]
    assert ("column 'spindle_rpm' is not read from 0 s to 1920 s into the record (0.00–0.53 h, from the record's "
            "start to its first reading): the twin holds that reading (9000) there, and judges no outage without a "
            "reading on both sides") in warnings, warnings


def test_a_record_read_from_start_to_end_has_no_held_note(quick_truth):
    from twin.gap.measured import match_record

    machine, data = quick_truth
    inside = (data.time_s > HOUR) & (data.time_s < 2 * HOUR)         # unread between readings: not an end
    assert match_record(_unread(data, "feed_x", inside, "inside.csv"), machine).report["warnings"] == []


def test_the_last_reading_is_held_to_the_end():
    from twin.gap.measured import _held_at_ends

    t = np.arange(241) * 120.0                       # 8 h every 2 min
    feed = np.where(t < 7 * HOUR, 1500.0, np.nan)
    assert _held_at_ends(t, feed, "Feed X") == [(
        "column 'Feed X' is not read from 25080 s to 28800 s into the record (6.97–8.00 h, from its last reading to "
        "the record's end): the twin holds that reading (1500) there, and judges no outage without a reading on "
        "both sides")]


@pytest.mark.parametrize("start_s", [1.7e9, 2.5e6])
def test_the_held_note_gives_times_from_the_record_start(start_s):
    """A record timed in epoch seconds (or one past 1e6 s): the note had said "from 1.7e+09 s to 1.7e+09 s"."""
    from twin.gap.measured import _held_at_ends

    t = start_s + np.arange(241) * 120.0
    feed = np.where(t - start_s < 7 * HOUR, 1500.0, np.nan)
    notes = _held_at_ends(t, feed, "Feed X")
    assert notes == _held_at_ends(t - start_s, feed, "Feed X") and "from 25080 s to 28800 s into the record" in notes[0]


@pytest.mark.parametrize("unread_rows, noted", [(1, False), (5, False), (6, True)])
def test_an_unread_end_is_noted_only_as_long_as_an_outage(unread_rows, noted):
    """Every 2 min, an outage is more than 5 intervals and at least 600 s (twin.gap.outages): one trailing empty
    cell, or 5 rows (600 s, not more than 5 intervals), are a sampling irregularity and had each been noted; 6 rows
    (720 s) are noted, at the start as at the end."""
    from twin.gap.measured import _held_at_ends

    t = np.arange(241) * 120.0
    feed = np.full(len(t), 1500.0)
    feed[:unread_rows] = feed[len(t) - unread_rows:] = np.nan
    assert len(_held_at_ends(t, feed, "Feed X")) == (2 if noted else 0)


def _two_short_scenarios(tmp_path, monkeypatch):
    """Two 30 min scenarios at two speeds, sampled every 2 min (each runs in under a second), as the shipped ones,
    and a list that :func:`~twin.compensation.train.build_machine` appends to at each build."""
    from twin.compensation import train as training
    from twin.core import scenario

    for name, rpm in (("short_a", 6000), ("short_b", 3000)):
        (tmp_path / f"{name}.toml").write_text(
            f'[scenario]\nname = "{name}"\nmachine = "vmc_ram"\nduration_min = 30\nsample_interval_s = 120.0\n'
            f'time_step_s = 120.0\nseed = 1\n[[segments]]\nduration_min = 30\nspindle_rpm = {rpm}\n')
    monkeypatch.setattr(scenario, "SCENARIOS_DIR", tmp_path)      # train runs shipped scenarios only
    built = []
    real = training.build_machine

    def counted(*args, **kwargs):
        built.append(kwargs.get("definition"))
        return real(*args, **kwargs)
    monkeypatch.setattr(training, "build_machine", counted)
    return built


def test_training_on_two_scenarios_builds_the_machine_once(tmp_path, monkeypatch):
    """``twin train --machine M`` with two scenario datasets had built M (mesh, thermal system, output operator)
    once per dataset."""
    from twin.compensation import train as training

    built = _two_short_scenarios(tmp_path, monkeypatch)
    training.train(["short_a", "short_b"], "T01,T02", "Z", model="mlr", machine="vmc_ram")
    assert len(built) == 1


def test_evaluating_a_scenario_with_a_scenario_history_builds_the_machine_once(tmp_path, monkeypatch):
    """``twin evaluate --machine M --history``: the history record runs on the same build as the datasets."""
    from twin.compensation import train as training

    built = _two_short_scenarios(tmp_path, monkeypatch)
    model = training.train(["short_a"], "T01,T02", "Z", model="mlr", machine="vmc_ram")
    built.clear()
    training.evaluate(model, ["short_a"], machine="vmc_ram", history="short_b", reference="train")
    assert len(built) == 1


def test_a_malformed_csv_listed_after_a_scenario_is_refused_before_the_machine_is_built(tmp_path, monkeypatch):
    """The machine had been built before any dataset was read: a CSV error came only after the build (minutes on
    a cold cache)."""
    from twin.compensation import train as training
    from twin.errors import TwinInputError

    built = _two_short_scenarios(tmp_path, monkeypatch)
    (tmp_path / "bad.csv").write_text("time_s,T01_degC,T02_degC,Z_um\n0,20,20,0\n60,abc,20,0\n")
    with pytest.raises(TwinInputError, match="bad.csv"):
        training.train(["short_a", str(tmp_path / "bad.csv")], "T01,T02", "Z", model="mlr", machine="vmc_ram")
    assert built == []
