"""The gap diagnosis: a small blind case, no-effect data, bad channels, robustness of the measured-data path."""
import json

import numpy as np
import pytest

from twin.core.dataset import ChannelInfo, Dataset
from twin.errors import TwinInputError
from twin.gap.benchmark import DRIFT_GAP, GOAL_DRIFT_SHRINK, TRUTH_HIDDEN, TRUTH_VALUES, BenchmarkTask, cases
from twin.gap.effects import default_library
from twin.gap.measured import match_record
from twin.infra.sweep import cached, run_tasks

QUICK = "gap_quick_8h"
LIB = {e.name: e for e in default_library()}


@pytest.fixture(scope="module")
def machine():
    from twin.gap.diagnose import _machine

    return _machine("vmc_ram")


def truth(machine, name=None, seed=None):
    """A quick truth record (nominal mesh, backward Euler 20 s, noise, truth variants), cached per process."""
    from twin.gap.truth import truth_dataset

    def make():
        active = [] if name is None else [(LIB[name].variant(**TRUTH_HIDDEN.get(name, {})),
                                           np.array(TRUTH_VALUES[name], float))]
        return truth_dataset(QUICK, machine, active, seed=seed)

    return cached(("gap-test-truth", name, seed), make)


@pytest.fixture(scope="module")
def blind(machine):
    """The small blind case of the default suite: three effects and no effect, serial sweep, nominal mesh truth."""
    todo = [c for c in cases("belt_drive,convection_enclosure,fixture_drift,none")]
    tasks = [BenchmarkTask(c, scenario=QUICK, truth_mesh_size_m=None) for c in todo]
    return run_tasks(tasks, scheduler="serial")


def test_small_blind_case_names_the_hidden_effect(blind):
    singles = [r for r in blind if r["kind"] == "single"]
    for r in singles:
        assert r["correct"], f"{r['case']}: named {r['top']} ({r['verdict']})"
        fit = r["truth_fit"]["params"]
        for p in fit:
            assert abs(p["relative"]) < 0.15, p
        if (r["drift_gap"] or 0) > DRIFT_GAP:
            assert r["shrink_top"]["drift_reduction"] >= GOAL_DRIFT_SHRINK, r["shrink_top"]


def test_no_effect_data_gives_no_significant_gap(blind):
    none = [r for r in blind if r["kind"] == "none"]
    assert none and all(r["top"] == "none" and not r["significant"] for r in none)
    assert all(r["verdict"].startswith("no significant gap") for r in none)


def test_bad_channel_gives_a_clear_error_listing_valid_names(machine):
    data = truth(machine)
    bad = Dataset(data.time_s, np.column_stack([data.values, data["T01"]]),
                  data.channels + [ChannelInfo("T99", "degC", "temperature")])
    with pytest.raises(TwinInputError, match=r"T99.*valid names.*T01.*spindle"):
        match_record(bad, machine)
    wrong_unit = Dataset(data.time_s, data.values[:, :5],
                         data.channels[:4] + [ChannelInfo("T01", "um", "displacement")])
    with pytest.raises(TwinInputError, match="T01.*degC"):
        match_record(wrong_unit, machine)


def _with(data, name, values):
    """``data`` with channel ``name``'s values replaced, or added as the room's ambient column (a unit error
    written by hand, not by the twin)."""
    if name not in data.names:
        data = Dataset(data.time_s, np.column_stack([data.values, values]),
                       data.channels + [ChannelInfo(name, "degC", "ambient")], data.metadata)
    changed = data.values.copy()
    changed[:, data.names.index(name)] = values
    return Dataset(data.time_s, changed, data.channels, {**data.metadata, "source": "rig.csv"})


@pytest.mark.parametrize(("name", "convert", "message"), [
    ("ambient_room", lambda v: np.full(len(v), 293.15),
     ("column 'ambient_room_degC' has value 293.15 at t = 0 s, outside the plausible -40 … 80 degC of an air "
      "sensor; it looks like kelvin")),
    ("spindle", lambda v: v * 2.0, r"column 'spindle_rpm' has value 18000 at t = .* beyond the ±12600 spindle "),
    ("feed_x", lambda v: v + 130000.0, r"column 'feed_x_mm_min' has value 130000 .* beyond the ±120000 feed"),
])
def test_operating_conditions_in_another_unit_are_refused_by_column(machine, name, convert, message):
    """A spindle column in Hz had become a 7.7 kW "discovered" source; an ambient in kelvin was averaged into the
    room's air and its 270 K offsets called thermometer accuracy."""
    data = truth(machine)
    with pytest.raises(TwinInputError, match="rig.csv: " + message):
        match_record(_with(data, name, convert(data[name] if name in data.names else data.time_s)), machine)


def test_a_spindle_speed_is_its_magnitude_and_one_that_reads_like_hz_is_warned_about(machine):
    """Reverse rotation and a tachometer's noise at rest are logged negative: the heat is that of |n|, and
    refusing them refused real logs. A column that peaks at 200 "rpm" on a 12000 rpm machine reads like Hz
    (it became a 7.7 kW "discovered" source), but a slow warm-up can be true: warned, in words."""
    data = truth(machine)
    noise = np.random.default_rng(0).uniform(-3.0, 3.0, len(data))     # a tachometer at standstill
    record = match_record(_with(data, "spindle", noise), machine)
    np.testing.assert_allclose(record.spindle, np.abs(noise))
    assert record.report["warnings"] == [
        (f"column 'spindle_rpm' reads down to {noise.min():g} rpm: its magnitude is the spindle speed (reverse "
         "rotation, a tachometer's noise at rest)")]
    reverse = match_record(_with(data, "spindle", -data["spindle"]), machine)
    np.testing.assert_array_equal(reverse.spindle, data["spindle"])
    in_hz = match_record(_with(data, "spindle", data["spindle"] / 60.0), machine)
    assert in_hz.report["warnings"][0].startswith(
        "column 'spindle_rpm' peaks at about 200 rpm (99th percentile), 1.7 % of the 12000 rpm top speed of machine "
        "'vmc_ram': if it is in Hz (rev/s), the speed is 12000 rpm")
    assert match_record(data, machine).report["warnings"] == []


def test_an_empty_spindle_column_is_named_as_empty_not_missing(machine):
    from twin.gap.drive import measured_drive

    data = truth(machine)
    record = match_record(_with(data, "spindle", np.full(len(data), np.nan)), machine)
    with pytest.raises(TwinInputError, match="rig.csv: column 'spindle_rpm' holds no value; give the spindle speed"):
        measured_drive(machine, data.time_s, record)


@pytest.mark.parametrize(("step", "message"), [
    (0.0, "step_s .--step. must be a positive number of seconds, got 0"),
    (-60.0, "got -60"), (float("nan"), "got nan"),
    (7200.0, r"step_s \(--step\) 7200 s is longer than a tenth of the held-out"),
])
def test_a_time_step_the_twin_cannot_take_is_refused(machine, step, message):
    """--step 0 and a negative step had ended in an OverflowError and an IndexError from numpy."""
    from twin.gap.diagnose import diagnose

    with pytest.raises(TwinInputError, match=message):
        diagnose(truth(machine), machine, step_s=step)


def test_nan_gaps_offsets_missing_channels_and_other_sampling(machine, tmp_path):
    """Every third row with jitter (another sampling), NaN gaps, constant offsets, a missing sensor: still named."""
    from twin.gap.diagnose import diagnose
    from twin.gap.report import write_report

    data = truth(machine, "belt_drive")
    rng = np.random.default_rng(0)
    keep = np.arange(0, len(data), 3)
    t = data.time_s[keep] + np.r_[0.0, rng.uniform(-20, 20, len(keep) - 2), 0.0]
    names = [c.name for c in data.channels if c.name != "T05"]            # T05 missing
    values = data.matrix(names)[keep].copy()
    j = names.index
    values[40:55, j("T12")] = np.nan                                       # a 1.5 h gap
    values[60:63, j("Z")] = np.nan
    infos = [data.info(n) for n in names]
    without_offsets = diagnose(Dataset(t, values.copy(), infos, {"source": "resampled"}), machine, n_pairs=0)
    values[:, j("T20")] += 1.5                                             # constant offsets
    values[:, j("Y")] += 4.0
    d = diagnose(Dataset(t, values, infos, {"source": "perturbed"}), machine, n_pairs=0)
    assert d.winner is not None and d.winner.name == "belt_drive"
    rep = d.record.report
    assert rep["nan_counts"] == {"T12": 15, "Z": 3} and "T05" in rep["sensors_missing"]
    assert not rep["sampling_regular"] and rep["sampling_interval_s"] == pytest.approx(360, abs=30)
    off = dict(zip(d.names, d.nominal.residual.offsets))
    off0 = dict(zip(without_offsets.names, without_offsets.nominal.residual.offsets))
    assert off["T20"] - off0["T20"] == pytest.approx(1.5, abs=1e-6)    # taken by the offsets, exactly
    assert off["Y"] - off0["Y"] == pytest.approx(4.0, abs=1e-6)
    assert d.winner.values == pytest.approx(without_offsets.winner.values, rel=1e-6)
    assert np.isnan(d.winner.residual.R[40:55, d.names.index("T12")]).all()
    out = write_report(d, tmp_path / "report", render=False)
    text = (out / "report.md").read_text()
    assert "T12 15" in text and "T05" in text and "belt_drive" in text
    assert json.loads((out / "diagnosis.json").read_text())["winner"]["name"] == "belt_drive"


def test_cli_diagnose_with_column_map(machine, tmp_path):
    """A measured CSV with its own column names, read through a column map, diagnosed from the command line."""
    from twin.cli import main

    data = truth(machine, "convection_enclosure")
    cols = {"time": data.time_s, "rpm": data["spindle"]}
    mapping = {"rpm": "spindle_rpm"}
    for c in data.channels:
        if c.kind in ("temperature", "air", "displacement", "strain"):
            cols[f"ch_{c.name.lower()}"] = data[c.name]
            mapping[f"ch_{c.name.lower()}"] = f"{c.name}_{c.unit}"
    import pandas as pd

    csv = tmp_path / "measured.csv"
    frame = pd.DataFrame(cols).rename(columns={"time": "time_s"})
    frame.loc[10:12, "ch_t03"] = np.nan
    frame.to_csv(csv, index=False)
    (tmp_path / "map.json").write_text(json.dumps(mapping))
    out = tmp_path / "diag"
    code = main(["gap", "diagnose", "--measured", str(csv), "--column-map", str(tmp_path / "map.json"),
                 "--no-render", "--pairs", "0", "--out", str(out)])
    assert code == 0
    report = json.loads((out / "diagnosis.json").read_text())
    assert report["winner"]["name"] == "convection_enclosure"
    assert report["data"]["nan_counts"] == {"T03": 3}
    assert (out / "report.md").exists() and (out / "residuals.png").exists()
    # an unmapped, unknown column: one clear line and exit code 2
    frame.rename(columns={"ch_t03": "mystery"}).to_csv(tmp_path / "bad.csv", index=False)
    mapping.pop("ch_t03")
    mapping["mystery"] = "T77_degC"
    (tmp_path / "bad.json").write_text(json.dumps(mapping))
    assert main(["gap", "diagnose", "--measured", str(tmp_path / "bad.csv"), "--column-map",
                 str(tmp_path / "bad.json"), "--out", str(tmp_path / "x")]) == 2


def test_fl_thermal_import_path(machine, fl_thermal_csv):
    """The real recording has no twin: only the import path is exercised (map, NaN-free, 15 s sampling)."""
    from twin.gap.measured import read_measured

    mapping = {"spindle_rpm": "spindle_rpm", "ch3_um": "Z_um", "ch4_um": "Y_um", "t1_degC": "T01_degC",
               "t2_degC": "T02_degC", "t4_degC": "T15_degC"}
    import pandas as pd

    header = list(pd.read_csv(fl_thermal_csv, nrows=0).columns)
    with pytest.raises(TwinInputError, match="ch1.*valid names"):
        match_record(read_measured(fl_thermal_csv, {}), machine)
    drop = {c: f"x{i}_s" for i, c in enumerate(header) if c not in mapping and c != "time_s"}
    ds = read_measured(fl_thermal_csv, {**mapping, **drop})
    ds = ds.select([n for n in ds.names if not n.startswith("x")])
    rec = match_record(ds, machine)
    assert rec.report["sampling_interval_s"] == 15.0 and rec.report["rows"] > 7000
    assert rec.spindle is not None and [a[0] for a in rec.air] == ["T15"]
    assert set(rec.names) == {"Z", "Y", "T01", "T02", "T15"}


def test_cli_truth_writes_a_blind_record(tmp_path):
    """``twin gap truth``: the measured CSV without a sidecar (the diagnosis must not see the truth), the truth beside."""
    from twin.cli import main
    from twin.core.dataset import Dataset, sidecar_path

    csv = tmp_path / "new" / "measured.csv"                                 # the folder is created
    assert main(["gap", "truth", "--effect", "belt_drive", "--scenario", QUICK, "--truth-mesh-size", "0",
                 "--out", str(csv)]) == 0
    assert not sidecar_path(csv).exists()
    truth = json.loads((csv.parent / "measured.truth.json").read_text())
    assert truth["metadata"]["effects"][0]["name"] == "belt_drive"
    assert truth["metadata"]["effects"][0]["params"] == list(TRUTH_VALUES["belt_drive"])
    data = Dataset.read(csv)
    assert "spindle" in data.names and "T01" in data.names
    assert not [n for n in data.names if n.startswith(("P_", "ambient"))]
    assert main(["gap", "truth", "--effect", "belt_drive,door_draft", "--out", str(tmp_path / "x.csv")]) == 2


def test_a_logging_outage_across_a_spindle_change_is_named_and_its_rows_left_out(machine):
    """The spindle ran 12000, then 4500 rpm while the logger was off (3-5 h): when is unknown, so the rows after
    the outage cannot judge the twin.  Before, the outage swamped the timing floor (0.05 -> 0.4 K), and a clear
    enclosure-convection gap read "no significant gap"."""
    import re

    from twin.gap.diagnose import diagnose

    data = truth(machine, "convection_enclosure")
    keep = (data.time_s < 3 * 3600) | (data.time_s > 5 * 3600)
    cut = Dataset(data.time_s[keep], data.values[keep], data.channels, {"source": "outage.csv"})
    with pytest.raises(TwinInputError, match=r"outage.csv: .*logging outages \(2\.97–5\.03 h \(spindle_rpm 0 → 10000"
                                             r".*0 held-out rows.*--holdout") as err:
        diagnose(cut, machine, n_pairs=0, discovery=False)
    holdout = float(re.search(r"--holdout ([0-9.]+)", str(err.value)).group(1))
    few = {"n_pairs": 0, "discovery": False, "effects": ["convection_enclosure"]}
    d = diagnose(cut, machine, holdout_fraction=holdout, **few)
    left = d.unknown_inputs.rows
    assert d.verdict.startswith("INPUTS UNKNOWN: ") and left.sum() > 0
    assert d.record.time_s[left].min() > 5 * 3600 and not (d.evaluator.hold_rows & left).any()
    unread = data.values.copy()
    unread[(data.time_s >= 3 * 3600) & (data.time_s <= 5 * 3600), :4] = np.nan   # spindle and feeds, rows logged
    with pytest.raises(TwinInputError, match=r"unread.csv: .*logging outages \(2\.97–5\.03 h \(spindle_rpm 0 → 10000"):
        diagnose(Dataset(data.time_s, unread, data.channels, {"source": "unread.csv"}), machine, **few)
    steady = (data.time_s < 0.7 * 3600) | (data.time_s > 1.7 * 3600)     # an hour off while it ran at 9000 rpm
    d = diagnose(Dataset(data.time_s[steady], data.values[steady], data.channels, {"source": "steady.csv"}),
                 machine, **few)
    assert not d.unknown_inputs.outages and "INPUTS UNKNOWN" not in d.verdict
