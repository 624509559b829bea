"""Rules of the placement study's result: independent of the order of its lists, refusals before any simulation
(a scenario of another machine, records too coarse for the fits), no singular fit as a traceback, verdicts per
test scenario, the chosen sets with the noise drawn again."""
from types import SimpleNamespace

import numpy as np
import pytest
from test_cli_outdir import one_error_line
from test_placement import HEAT, short_scenarios

from twin.cli import main
from twin.errors import TwinInputError
from twin.placement.records import Record
from twin.placement.report import placement_summary, verdicts
from twin.placement.selection import METHODS, select_sets
from twin.placement.study import placement_study

SMALL = {"parts": ("ram", "carrier", "column", "spindle_motor"), "n_candidates": 120, "k_max": 3, "axes": ("Z", "Y"),
         "record_interval_s": 60.0, "scheduler": "serial", "use_cache": False, "anfis_check": False,
         "write_datasets": False, "log": None}


def _scores(result):
    """The study's table and test rows, every number exact (the table's row order follows --methods)."""
    table = sorted((r["axis"], r["method"], r["K"], tuple(r["sensors"]), r["max_residual"], r["rmse"])
                   for r in result.table)
    tested = {(key, axis): (r["method"], r["K"], tuple(r["sensors"]), r["max_residual"], r["per_scenario"])
              for key, rows in result.test.items() for axis, r in rows.items()}
    return table, tested


def test_the_order_of_the_lists_changes_nothing(tmp_path):
    """The training records were stacked in the order given, and GM(0,N)'s accumulated series ran over that
    stack: `gm-influence+fcm` chose other sensors when `--train` was given in another order."""
    sc = short_scenarios(tmp_path)
    runs = [placement_study(train=train, validation=(sc["p_val"],), test=(sc["p_test"],), methods=methods, **SMALL)
            for train, methods in (((sc["p_heat"], sc["p_steps"], sc["p_room"]), ("gm-influence+fcm", "greedy-loso")),
                                   ((sc["p_room"], sc["p_heat"], sc["p_steps"]), ("greedy-loso", "gm-influence+fcm")))]
    assert _scores(runs[0]) == _scores(runs[1])
    assert runs[0].best == runs[1].best and runs[0].redraw == runs[1].redraw
    assert runs[0].config["train"] == runs[1].config["train"] == ["p_heat", "p_room", "p_steps"]
    assert "the order given does not matter" in runs[0].summary


def _synthetic_records(n_records=4, n=80, p=25, seed=3):
    """Records of ``p`` candidates (°C) driven by two modes, and a Z and Y drift (µm) of those modes."""
    rng = np.random.default_rng(seed)
    out = []
    for f in range(n_records):
        t = np.arange(n) * 60.0
        modes = np.column_stack([1 - np.exp(-t / (1800 + 600 * f)), np.sin(t / (900 + 100 * f))])
        temps = 20 + modes @ rng.standard_normal((2, p)) + 0.02 * rng.standard_normal((n, p))
        out.append(Record(f"r{f}", t, temps, {"Z": 8 * modes[:, 0] - 3 * modes[:, 1], "Y": 2 * modes[:, 1]}))
    return out


@pytest.mark.parametrize("method", METHODS)
def test_one_set_is_what_the_full_selection_chooses(method):
    """The noise-redraw check chooses one K again with `select_one`: it must be the selection's own choice."""
    from twin.placement.selection import select_one

    records, responses = _synthetic_records(), _synthetic_records(2, seed=5)
    full = select_sets(records, responses, [method], ("Z", "Y"), 4, log=None)
    for axis in ("Z", "Y"):
        assert select_one(records, responses, method, axis, ("Z", "Y"), 3) == [int(i) for i in
                                                                                full.sets[(method, axis)][2]]


def test_the_chosen_sets_are_chosen_again_with_the_noise_redrawn(tmp_path):
    sc = short_scenarios(tmp_path)
    res = placement_study(train=(sc["p_heat"], sc["p_steps"], sc["p_room"]), validation=(sc["p_val"],),
                          test=(sc["p_test"],), methods=("greedy-loso", "qr-drift"), **SMALL)
    for axis, (method, k, idx) in res.best.items():
        r = res.redraw[axis]
        assert (r["method"], r["K"], len(r["sensors"])) == (method, k, k)
        shared = len(set(r["sensors"]) & {res.candidates.names[i] for i in idx})
        assert r["shared"] == shared and len(r["others_distance_m"]) == k - shared
        assert all(d > 0 for d in r["others_distance_m"]) and 0 <= r["others_same_part"] <= k - shared
        assert r["test_max_residual_chosen"] > 0 and r["test_max_residual_again"] > 0
        assert f"- {axis} ({method} K = {k}): {shared} of the {k} chosen sensors picked again" in res.summary
    quiet = placement_study(train=(sc["p_heat"], sc["p_steps"], sc["p_room"]), validation=(sc["p_val"],),
                            test=(sc["p_test"],), methods=("greedy-loso",), noise=False, **SMALL)
    assert quiet.redraw == {} and "noise drawn again" not in quiet.summary


@pytest.fixture
def refused(tmp_path, monkeypatch, capsys):
    """``refused(*arguments)``: ``twin place`` with these arguments exits 2 without simulating or writing; its one
    error line."""
    from twin.placement import study

    def simulate(*args, **kwargs):
        raise AssertionError("simulated although the options are bad")

    monkeypatch.setattr(study, "_simulate", simulate)
    out = tmp_path / "place"

    def run(*arguments):
        assert main(["place", *arguments, "--methods", "greedy-loso", "--axes", "Z", "--scheduler", "serial",
                     "--out", str(out)]) == 2
        assert not out.exists()
        return one_error_line(capsys)
    return run


@pytest.mark.parametrize("role", ["--train", "--validation", "--test"])
def test_a_scenario_of_another_machine_is_refused(refused, role):
    """`machine_a_heat_cool` ran silently on vmc_ram: its loads and limits are machine A's."""
    given = {"--train": "heat_cool_9000,thesis_test_4", "--validation": "thesis_test_2", "--test": "step_speed"}
    given[role] += ",machine_a_heat_cool"
    err = refused(*[a for option, value in given.items() for a in (option, value)], "--k-max", "5")
    assert (f"{role} machine_a_heat_cool: the scenario is written for machine 'machine_a', not for 'vmc_ram' "
            "(--machine)") in err


ROLES = ["--train", "heat_cool_9000,thesis_test_4", "--validation", "thesis_test_2", "--test", "step_speed"]


@pytest.mark.parametrize(("interval", "message"), [
    ("100000", ("--train heat_cool_9000: 11400 s recorded every 100000 s (--record-interval) gives 1 row; a "
                "training record needs at least --k-max + 2 = 6")),
    ("5000", ("--train heat_cool_9000: 11400 s recorded every 5000 s (--record-interval) gives 3 rows; a training "
              "record needs at least --k-max + 2 = 6: the MLR with K sensors has K + 1 coefficients")),
])
def test_a_record_interval_too_coarse_for_the_fits_is_refused(refused, interval, message):
    """100000 s gave a singular matrix in greedy-loso (a traceback); 5000 s fitted 9 rows and reported 95 %."""
    err = refused(*ROLES, "--record-interval", interval, "--k-max", "4")
    assert message in err and err.endswith("; lower --record-interval or --k-max")


def test_a_scenario_sampled_too_coarsely_is_refused_naming_its_own_sampling(refused, tmp_path):
    """A finer --record-interval cannot help: the message says the sampling is the scenario's own."""
    path = tmp_path / "p_coarse.toml"
    path.write_text(HEAT.format(name="p_coarse", ambient_kind="constant", ambient="temperature_C = 20.0", h1=2,
                                rpm1=9000, h2=1, rpm2=0).replace("sample_interval_s = 300.0",
                                                                 "sample_interval_s = 3600.0"))
    err = refused("--train", f"heat_cool_9000,{path}", "--validation", "thesis_test_2", "--test", "step_speed",
                  "--k-max", "4")
    assert err.endswith("--train p_coarse: 14400 s recorded every 3600 s (its own sampling) gives 5 rows; a training "
                        "record needs at least --k-max + 2 = 6: the MLR with K sensors has K + 1 coefficients and "
                        "greedy-loso fits it on the training scenarios but one (with two, on one alone)")


def test_the_rows_a_record_needs_follow_k_max_and_its_role():
    """A training record needs --k-max + 2 rows; a validation or test record, which is only predicted, 2."""
    from twin.core.variants import as_scenario
    from twin.placement.study import _check_record_rows

    roles = {"training": [as_scenario("etve_5K"), as_scenario("thesis_test_4")],
             "validation": [as_scenario("thesis_test_2")], "test": [as_scenario("step_speed")]}
    _check_record_rows(roles, 10000.0, 1)                   # thesis_test_4: 3 rows; the others 2 or more
    with pytest.raises(TwinInputError, match="--train thesis_test_4: .* gives 3 rows; .* --k-max \\+ 2 = 4"):
        _check_record_rows(roles, 10000.0, 2)
    roles["test"].append(as_scenario("cutting_soft"))       # 7200 s, every 10000 s: its start only
    with pytest.raises(TwinInputError, match="--test cutting_soft: .* gives 1 row; a validation or test record "
                                             "needs at least 2"):
        _check_record_rows(roles, 10000.0, 1)


def test_a_singular_fit_is_one_line_not_a_traceback(tmp_path, monkeypatch):
    """Records that do not change at all (noise-free, nothing moving) leave greedy-loso's Gram singular: the study
    says so in one line naming the training scenarios, not with numpy's traceback."""
    from twin.placement import study

    def constant_records(machine, spec, cspec, scenarios, axes, *args):
        n = len(cspec.build(machine))
        records = [Record(study.as_scenario(s).name, np.arange(30) * 60.0, np.full((30, n), 20.0),
                          {a: np.zeros(30) for a in axes}) for s in scenarios]
        return records, [], {"simulation_s": 0.0, "simulated": 0, "from_cache": 0, "responses": 0}

    monkeypatch.setattr(study, "_simulate", constant_records)
    with pytest.raises(TwinInputError) as info:
        placement_study(train=("thesis_test_4", "heat_cool_9000"), validation=("thesis_test_2",),
                        test=("step_speed",), methods=("greedy-loso",), n_candidates=30, k_max=2, axes=("Z",),
                        noise=False, log=None, out_dir=tmp_path / "place")
    message = str(info.value)
    assert message.startswith("a fit on the training records (heat_cool_9000, thesis_test_4) failed: Singular "
                              "matrix — ") and "\n" not in message
    assert not (tmp_path / "place").exists()


def _row(method, k, per):
    """A test row: ``per`` scenario → (max residual, uncompensated max), µm."""
    per_scenario = {sc: {"max_residual": r, "uncompensated_max": u, "rmse": r / 3, "rows": 100}
                    for sc, (r, u) in per.items()}
    peak = max(u for _r, u in per.values())
    worst = max(r for r, _u in per.values())
    return {"method": method, "K": k, "axis": "Z", "max_residual": worst, "rmse": worst / 3,
            "reduction_percent": 100 * (1 - worst / peak), "sensors": ["s1"] * k, "per_scenario": per_scenario}


def test_the_verdict_counts_the_test_scenarios_that_meet_the_goal():
    """Pooled, 1.0 µm of 20 µm is 95 %; but on `summer` (2 µm of drift) it is 50 %, and the seed set makes `summer`
    worse than no compensation: each test scenario is in the report, and the verdict counts them."""
    best = _row("greedy-loso", 4, {"hard": (1.0, 20.0), "summer": (1.0, 2.0)})
    seed = _row("gra+fcm", 5, {"hard": (0.5, 20.0), "summer": (4.7, 2.0)})
    table = [dict(r, per_scenario={}) for r in (best, seed)]
    result = SimpleNamespace(
        config={"axes": ["Z"], "methods": ["gra+fcm", "greedy-loso"], "k_max": 5, "machine": "vmc_ram",
                "n_candidates": 1, "n_surface": 1, "n_camera": 0, "parts": ["ram"], "train": ["a", "b"],
                "validation": ["v"], "test": ["hard", "summer"], "noise": True, "record_intervals_s": {"a": 60.0}},
        table=table + [dict(r, K=k) for r in table for k in (1, 2, 3, 4, 5) if k != r["K"]],
        test={"best": {"Z": best}, "own": {"Z": best}, "seed": {"Z": seed}},
        uncompensated={"Z": (20.0, 5.0)}, uncompensated_test={"Z": (20.0, 5.0)}, anfis=[], redraw={},
        timings={"simulation_s": 1.0, "simulated": 1, "from_cache": 0, "selection_s": 1.0, "scoring_s": 1.0,
                 "total_s": 3.0}, candidates=SimpleNamespace(names=["s1"], kinds=["surface"], parts=["ram"],
                                                             points=np.zeros((1, 3))), best={})
    v = verdicts(result)["Z"]
    assert v["goal_80_percent_pooled"] and v["goal_80_percent_scenarios"] == 1 and not v["goal_80_percent"]
    assert v["reduction_percent_per_scenario"]["summer"] == pytest.approx(50.0)
    assert v["own_beats_seed_scenarios"] == 1
    text = placement_summary(result)
    assert ("80 % goal met on 1 of 2 test scenarios (not on summer: 50.0 %); pooled (the largest residual on any "
            "test scenario over the largest drift on any): 1.00 µm, 95.0 % below 20.00 µm — met") in text
    assert "| chosen = best own: greedy-loso K = 4 | summer | 100 | 2.00 | 1.00 | 0.33 | 50.0 | NOT met |" in text
    assert "| best seed: gra+fcm K = 5 | summer | 100 | 2.00 | 4.70 | 1.57 | -135.0 | NOT met |" in text
