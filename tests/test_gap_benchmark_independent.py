"""The independent gap benchmark's cases, goal metrics and report (no FE run: the cases' records are tested in
test_gap_benchmark_truth.py and the discovery in test_gap_discovery.py)."""
import numpy as np
import pytest

from twin.core.dataset import ChannelInfo, Dataset
from twin.core.machine_definition import load_machine, room_zone
from twin.core.scenario import load_scenario
from twin.errors import TwinInputError
from twin.gap.benchmark import (
    format_benchmark,
    format_independent,
    in_wrong_unit,
    independent_cases,
    independent_metrics,
)
from twin.gap.sensor_errors import apply_sensor_errors
from twin.gap.truth import changed_definition


def test_case_set_meets_the_issue_and_every_change_applies():
    cases = independent_cases()
    kinds = [c.kind for c in cases]
    assert kinds.count("library") >= 8 and kinds.count("outside") >= 4
    assert kinds.count("pair") == 3 and kinds.count("control") >= 3
    assert {"45s", "irregular", "clock_offset"} <= {c.sampling for c in cases}
    definition = load_machine("vmc_ram")
    for c in cases:
        changed = changed_definition(definition, c.change)     # unknown groups/joints/sources would raise
        assert (changed != definition) or c.sensors or c.sampling or c.corrupt or c.kind == "control", c.name
    assert kinds.count("sensor") >= 1 and {c.corrupt for c in cases} >= {"kelvin", "mm"}
    with pytest.raises(TwinInputError, match="unknown independent case"):
        independent_cases("column_source,teleport")


def _result(case, kind, outcome, correct, drift=0.9, source=None, params=()):
    return {"case": case, "kind": kind, "outcome": outcome, "correct": correct, "top": case if correct else "none",
            "drift_reduction": drift, "drift_gap": 10.0, "explained_with_gap": outcome == "explained" and drift < 0.7,
            "source": source, "truth_fit": {"params": list(params)}, "truth_seconds": 1, "diagnosis_seconds": 2}


def test_metrics_and_report():
    results = [
        _result("joint_ram_guides", "library", "explained", True, 0.9,
                params=[{"truth": 0.2, "fitted": 0.21, "sd": 0.01, "interval": [0.19, 0.23]},
                        {"truth": 1.0, "fitted": 1.2, "sd": 0.01, "interval": [1.18, 1.22]}]),
        _result("belt_drive", "library", "partly_explained", False, 0.5),
        _result("column_source", "outside", "explained", False, 0.4,
                source={"distance_m": 0.05, "power_W": 41.0, "truth_W": 40.0, "ok": True}),
        _result("missing_joint", "outside", "not_explained", False, 0.1),
        _result("control: 45 s sampling", "control", "no_significant_gap", True),
        {**_result("loose_thermometer", "sensor", "not_explained", False),
         "sensor": {"broken": "T11", "flagged": ["T11", "T12"], "found": True, "located": True}},
        {**_result("kelvin_in_degC", "units", "refused", False), "message": "record: column 'T01_degC' has value 293"},
        {**_result("mm_in_um", "units", "no_significant_gap", False), "message": ""},
    ]
    m = independent_metrics(results)
    assert m["library_top1"] == (1, 2)
    assert m["outside_never_explained_with_gap"] == (1, 2)     # column_source "explained" with 60 % left
    assert m["sources_found"] == (1, 1)
    assert m["controls_no_gap"] == (1, 1)
    assert m["interval_coverage"] == (1, 2)                    # 0.2 in 0.21 ± 0.016; 1.0 not in 1.2 ± 0.016
    assert m["median_drift_reduction"] == pytest.approx(0.9)
    md = format_independent(results, m, 60.0, {"scenario": "gap_independent_24h", "scheduler": "local"})
    assert "| library effects made independently: top-1 | ≥ 90 % | 1/2 (50%) |" in md
    assert "0.05 m, 41 W for 40 W" in md
    assert m["single_sensor"] == (1, 1) and m["wrong_units_refused"] == (1, 2)
    assert "| a gap at a single sensor: found, and that sensor flagged worst | all | 1/1 (100%) |" in md
    assert "flagged T11, T12" in md and "column 'T01_degC' has value 293" in md and "not refused" in md


def test_blind_benchmark_report_tables():
    single = {"case": "belt_drive", "kind": "single", "truth": "belt_drive", "top": "belt_drive", "correct": True,
              "partially": True, "ranking": [("belt_drive", 8804.2)], "runner_up": "air_pocket",
              "evidence_ratio": float("inf"), "drift_gap": 9.3, "verdict": "gap explained by belt_drive",
              "truth_fit": {"params": [{"param": "belt_drive.power_W", "truth": 60.0, "fitted": 60.5, "sd": 0.086,
                                        "unit": "W", "error": 0.5, "relative": 0.5 / 60}]},
              "shrink_top": {"drift_before_rms": 0.93, "drift_after_rms": 0.11, "drift_before_max": 2.29,
                             "drift_after_max": 0.34, "drift_reduction": 0.88, "temperature_before_rms": 0.565,
                             "temperature_after_rms": 0.078, "temperature_reduction": 0.86},
              "truth_seconds": 70, "diagnosis_seconds": 93}
    none = {"case": "none", "kind": "none", "truth": "none", "top": "air_pocket", "correct": False,
            "partially": False, "ranking": [], "runner_up": None, "evidence_ratio": float("nan"), "drift_gap": 1.2,
            "verdict": "gap explained by air_pocket"}
    metrics = {"top1_rate": 1.0, "top1_correct": 1, "singles": 1, "drift_shrink_median": 0.88,
               "drift_shrink_min": 0.88, "drift_shrink_cases": 1, "drift_shrink_goal_met": 1, "none_correct": 0,
               "none": 1, "pairs_both": 0, "pairs_one": 0, "pairs": 0}
    settings = {"scenario": "gap_blind_24h", "truth_mesh_size_m": 0.035, "nominal_mesh_size_m": None,
                "holdout_fraction": 0.3, "scheduler": "local"}
    md = format_benchmark([single, none], metrics, 120.0, settings)
    assert "| belt_drive | belt_drive | ✓ | 8804 | air_pocket | – | 9.3 |" in md
    assert "| belt_drive | belt_drive.power_W | 60 W | 60.5 ± 0.086 | +0.5 (+1%) |" in md
    assert "| belt_drive | 0.93 → 0.11 | 2.29 → 0.34 | −88% | 0.565 → 0.078 | −86% |" in md
    assert "- **none** → air_pocket: gap explained by air_pocket" in md
    assert "| none | 0 | 0 |" in md


def test_cli_runs_the_independent_benchmark_and_refuses_an_unknown_case_before_any_work(tmp_path, capsys):
    from twin.cli import main

    out = tmp_path / "independent"
    assert main(["gap", "benchmark", "--independent", "column_source,teleport", "--out", str(out)]) == 2
    assert "unknown independent case 'teleport'" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("flag, value", [("--holdout", "0.5"), ("--truth-mesh-size", "0.045")])
def test_cli_refuses_blind_benchmark_settings_the_independent_cases_fix_themselves(tmp_path, capsys, flag, value):
    """Each independent case has its own truth mesh and hold-out: a flag that would be ignored is an error."""
    from twin.cli import main

    out = tmp_path / "independent"
    assert main(["gap", "benchmark", "--independent", "column_source", flag, value, "--out", str(out)]) == 2
    assert f"{flag} do(es) not apply" in capsys.readouterr().err
    assert not out.exists()


def test_wrong_unit_records_and_a_loose_thermometer_are_written_apart_from_the_diagnosis():
    t = np.arange(0.0, 3600.0, 60.0)
    channels = [ChannelInfo("T11", "degC", "temperature"), ChannelInfo("T12", "degC", "temperature"),
                ChannelInfo("Z", "um", "displacement")]
    data = Dataset(t, np.column_stack([25.0 + 0 * t, 26.0 + 0 * t, 10.0 + 0 * t]), channels, {})
    kelvin, mm = in_wrong_unit(data, "kelvin"), in_wrong_unit(data, "mm")
    np.testing.assert_allclose(kelvin.values[:, :2], data.values[:, :2] + 273.15)
    np.testing.assert_allclose(mm.values[:, 2], data.values[:, 2] / 1e3)
    sc = load_scenario("gap_independent_24h")
    room = apply_sensor_errors(data, [("thermometer_in_air", "T11", 0.4)], sc)
    room_air = room_zone(load_machine(sc.machine).zones)
    air = sc.zone_ambient(t, [room_air])[room_air]
    np.testing.assert_allclose(room.values[:, 0], 0.6 * 25.0 + 0.4 * air)
    np.testing.assert_array_equal(room.values[:, 1:], data.values[:, 1:])
    with pytest.raises(TwinInputError, match="'Z' is not a thermometer"):
        apply_sensor_errors(data, [("thermometer_in_air", "Z", 0.4)], sc)


def test_the_confusion_table_prints_log10_evidence_not_an_overflowing_ratio():
    from twin.gap.benchmark import _confusion_table

    row = {"truth": "belt_drive", "top": "belt_drive", "correct": True, "partially": True,
           "ranking": [("belt_drive", 141.2)], "runner_up": "fixture_drift", "evidence_ratio": 2.04e31,
           "log10_evidence_ratio": 31.3, "drift_gap": 9.3}
    table = _confusion_table([row])
    assert "log10 evidence ratio" in table and "| 31.3 |" in table and "e+31" not in table
