"""Blocked cross-validation across operating regimes (models.selection_cv)."""

import numpy as np
import pytest
from test_models_greybox import _day

from models import GM0NRegressor, MLRRegressor
from models.greybox import GreyBoxRegressor
from models.selection_cv import (
    blocked_folds,
    fold_prediction,
    geometric_mean_rmse,
    margin,
    model_kind,
    nested_lower_orders,
    parsimonious_choice,
    rank_agreement,
    record_blocks,
    regime_blocks,
    select_by_blocked_cv,
    within_one_standard_error,
)


def test_regime_blocks_start_at_runs_and_keep_the_stop_after_them():
    speed = np.r_[np.zeros(3), np.full(5, 1000.0), np.zeros(4), np.full(5, 2000.0), np.full(2, 3000.0), np.zeros(3)]
    assert regime_blocks(speed) == [(0, 12), (12, 17), (17, 22)]
    assert regime_blocks(speed, min_rows=6) == [(0, 12), (12, 22)]  # the 2-row 3000 rpm run merges back
    assert regime_blocks(np.r_[np.full(4, 500.0), np.zeros(4), np.full(4, 900.0)]) == [(0, 8), (8, 12)]
    with pytest.raises(ValueError, match="finite 1-D"):
        regime_blocks([0.0, np.nan, 1.0])


def test_regime_blocks_of_a_measured_speed_are_those_of_its_set_points():
    """Noise, a standstill that reads a few rpm, and ramps after a start or a step are no regimes."""
    set_points = np.r_[np.zeros(20), np.full(40, 2000.0), np.zeros(30), np.full(40, 4000.0), np.full(40, 6000.0),
                       np.zeros(30)]
    rng = np.random.default_rng(0)
    measured = np.where(set_points > 0, set_points + rng.normal(0.0, 5.0, len(set_points)),
                        np.abs(rng.normal(0.0, 2.0, len(set_points))))
    for k in (20, 90):                        # runs that ramp up over three rows
        measured[k: k + 3] = set_points[k] * np.array([0.3, 0.7, 0.9])
    measured[130: 133] = [4600.0, 5200.0, 5800.0]   # and a step that ramps
    expected = [(0, 90), (90, 130), (130, 200)]
    assert regime_blocks(set_points) == expected
    assert regime_blocks(measured) == expected
    assert regime_blocks(set_points, tolerance=0.6) == [(0, 90), (90, 200)]   # 6000 is within 60 % of 4000


def test_a_run_that_restarts_at_the_same_speed_continues_its_block():
    """A duty cycle at one speed is one regime; a restart at another speed is a new one."""
    cycles = np.tile(np.r_[np.full(5, 3000.0), np.zeros(5)], 4)
    speed = np.r_[np.zeros(3), cycles, np.full(6, 5000.0), np.zeros(4), np.full(6, 3000.0)]
    assert regime_blocks(speed) == [(0, 43), (43, 53), (53, 59)]


def test_folds_of_both_schemes():
    blocks = [(0, 10), (10, 25), (25, 30)]
    folds = blocked_folds(blocks)
    # rolling origin into the last block is leaving it out: one fold, counted once
    assert [f.name for f in folds] == [
        "leave-one-block-out block 1", "leave-one-block-out block 2", "leave-one-block-out block 3",
        "rolling-origin block 2",
    ]
    lobo2, lobo3, rolling2 = folds[1], folds[2], folds[3]
    assert lobo2.test == (10, 25) and lobo2.train.sum() == 15 and not lobo2.train[10:25].any()
    assert rolling2.test == (10, 25) and rolling2.train[:10].all() and not rolling2.train[10:].any()
    assert lobo3.test == (25, 30) and lobo3.train[:25].all() and not lobo3.train[25:].any()
    rolling = blocked_folds(blocks, schemes=("rolling-origin",))
    assert [f.name for f in rolling] == ["rolling-origin block 2", "rolling-origin block 3"]
    assert np.array_equal(rolling[1].train, lobo3.train)
    # two records: the last block of the first record is a middle block, and both of its folds are kept
    two = blocked_folds([(0, 10), (10, 25), (25, 30), (30, 40)], record_starts=[25])
    assert [f.name for f in two][-2:] == ["rolling-origin block 2", "rolling-origin block 3"]
    assert len({(f.test, f.train.tobytes()) for f in two}) == len(two) == 4 + 2
    with pytest.raises(ValueError, match="at least 2 operating-regime blocks"):
        blocked_folds([(0, 10)])
    with pytest.raises(ValueError, match="unknown scheme 'random'"):
        blocked_folds(blocks, schemes=("random",))


def _record(seed=0, slow_share=0.0):
    """Runs at four speeds with stops; a drift that lags the spindle heat (τ = 40 min) plus the ambient, and
    ``slow_share`` of the heat's drift again through a slow mode (τ = 8 h)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 32 * 3600.0, 120.0)
    slot = (t // (4 * 3600.0)).astype(int)
    speed = np.where(slot % 2 == 1, np.array([1000.0, 2000.0, 3000.0, 4000.0])[(slot // 2) % 4], 0.0)
    ambient = 20 + np.sin(2 * np.pi * t / 86400.0)
    heat, drift = (speed / 1000.0) ** 1.5, np.zeros_like(t)
    for k in range(1, len(t)):
        a = np.exp(-120.0 / 2400.0)
        drift[k] = a * drift[k - 1] + (1 - a) * 4.0 * heat[k - 1]
    slow = np.zeros_like(t)
    for k in range(1, len(t)):
        a = np.exp(-120.0 / (8 * 3600.0))
        slow[k] = a * slow[k - 1] + (1 - a) * slow_share * 4.0 * heat[k - 1]
    y = drift + slow + 3.0 * (ambient - ambient[0]) + 0.05 * rng.standard_normal(len(t))
    X = np.column_stack([t, speed, ambient, rng.standard_normal(len(t))])  # column 3: an irrelevant sensor
    return X, y, speed


def test_held_out_targets_never_reach_the_fit():
    X, y, speed = _record()
    fold = blocked_folds(regime_blocks(speed))[1]  # leave out the second block, in the middle
    start, stop = fold.test
    spoiled = y.copy()
    spoiled[start:stop] += 1e3
    for model, cols in ((GreyBoxRegressor(n_poles=1, temperature_inputs=(2,)), [0, 1, 2]),
                        (MLRRegressor(), [2, 3]), (GM0NRegressor(), [2, 3])):
        clean = fold_prediction(model, X[:, cols], y, fold)
        np.testing.assert_allclose(fold_prediction(model, X[:, cols], spoiled, fold), clean, atol=1e-9)
    assert [model_kind(m) for m in (GreyBoxRegressor(), GM0NRegressor(), MLRRegressor())] == [
        "weighted", "series", "static"]


def test_a_series_model_left_without_the_first_block_predicts_from_the_runs_start():
    """A target that is a fixed mix of the inputs, 7 µm off zero: GM(0,N) trained on blocks 2-4 predicts the
    change since row 0 added to the target there, not to block 2's start (1.6 µm away)."""
    X, _, speed = _record()
    y = 3.0 * (X[:, 2] - X[0, 2]) + 0.5 * X[:, 3] + 7.0
    first = blocked_folds(regime_blocks(speed))[0]
    assert first.name == "leave-one-block-out block 1" and abs(y[first.test[1]] - y[0]) > 1.0
    start, stop = first.test
    assert np.max(np.abs(fold_prediction(GM0NRegressor(), X[:, [2, 3]], y, first) - y[start:stop])) < 0.1


def test_selection_prefers_the_model_of_the_right_structure_and_says_why():
    X, y, speed = _record()
    candidates = {
        "grey-box": (GreyBoxRegressor(n_poles=1, temperature_inputs=(2,)), [0, 1, 2]),
        "MLR on ambient": (MLRRegressor(), [2]),
        "MLR on noise": (MLRRegressor(), [3]),
        "too big": (GreyBoxRegressor(n_poles=1), [0, 1] + [3] * 1),  # fine: fits, but the sensor is noise
    }
    chosen = select_by_blocked_cv(candidates, X, y, speed)
    assert chosen.chosen == "grey-box"
    # every held-out block at the noise level (0.05), except rolling origin from the 1000 rpm block
    # alone: one speed cannot identify the exponent of P ∝ n^b, so 2000 rpm is extrapolated blind
    scores = dict(zip(chosen.folds, chosen.fold_rmse["grey-box"]))
    assert max(v for k, v in scores.items() if k != "rolling-origin block 2") < 0.07
    assert scores["rolling-origin block 2"] > 0.5
    assert len(chosen.folds) == 4 + 2
    assert chosen.reason.startswith("chose grey-box: lowest geometric-mean RMSE on operating-regime blocks it did not see")
    assert ("6 folds (4 leave-one-block-out, 2 more rolling-origin; the last block's fold is rolling-origin too)"
            in chosen.reason)
    rival = chosen.ranking[1]
    ahead = sum(a < b for a, b in zip(chosen.fold_rmse["grey-box"], chosen.fold_rmse[rival]))
    assert chosen.reason.endswith(f". It beats {rival} on {ahead} of 6 folds.")
    assert chosen.ranking == sorted(chosen.score, key=chosen.score.get)
    for name, folds in chosen.fold_rmse.items():
        assert chosen.score[name] == pytest.approx(np.exp(np.mean(np.log(folds))))


def test_the_reason_counts_each_fold_once_and_names_its_schemes():
    X, y, speed = _record()
    candidates = {"MLR on ambient": (MLRRegressor(), [2]), "MLR on noise": (MLRRegressor(), [3])}
    counts = {("leave-one-block-out",): "over 4 folds (4 leave-one-block-out), worst",
              ("rolling-origin",): "over 3 folds (3 rolling-origin), worst"}
    for schemes, text in counts.items():
        assert text in select_by_blocked_cv(candidates, X, y, speed, schemes=schemes).reason
    two = regime_blocks(speed)[2][0]   # the first two regime blocks only
    reason = select_by_blocked_cv(candidates, X[:two], y[:two], speed[:two]).reason
    assert "over 2 folds (2 leave-one-block-out; the last block's fold is rolling-origin too), worst" in reason


def test_record_blocks_never_span_two_records():
    speed = np.r_[np.zeros(3), np.full(5, 1000.0), np.zeros(2), np.full(4, 1000.0), np.full(4, 2000.0)]
    assert record_blocks(speed) == regime_blocks(speed) == [(0, 14), (14, 18)]
    # the same speeds as two records: the second's 1000 rpm run is a block of its own
    assert record_blocks(speed, [10]) == [(0, 10), (10, 14), (14, 18)]
    folds = blocked_folds(record_blocks(speed, [10]), record_starts=[10])
    assert [f.record_start for f in folds] == [0, 10, 10, 10]
    with pytest.raises(ValueError, match="at least 2 rows per record"):
        record_blocks(speed, [17])


def test_several_records_are_scored_each_run_from_its_own_start():
    """Three test days apart, one speed each (the RC network of test_models_greybox, solved by solve_ivp):
    a held-out day is predicted from its own start at rest, so the right structure scores at the noise-free
    level; run on from the first day's start over the nights, it would be off by several µm."""
    days = [_day(start, level) for start, level in ((0, 1500.0), (30, 3000.0), (60, 4500.0))]
    X = np.vstack([x for x, _ in days])
    y = np.concatenate([d for _, d in days])
    starts = np.cumsum([len(x) for x, _ in days])[:-1].tolist()
    candidates = {"grey-box": (GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)), [0, 1, 2]),
                  "MLR": (MLRRegressor(), [2, 3]), "GM(0,N)": (GM0NRegressor(), [2, 3])}
    chosen = select_by_blocked_cv(candidates, X, y, X[:, 1], record_starts=starts)
    assert chosen.chosen == "grey-box" and len(chosen.folds) == 3 + 1
    scores = dict(zip(chosen.folds, chosen.fold_rmse["grey-box"]))
    # rolling origin from the first day alone extrapolates the exponent blind (one speed); every other is exact
    assert max(v for k, v in scores.items() if k != "rolling-origin block 2") < 1e-3 * np.ptp(y)
    assert chosen.score["GM(0,N)"] == np.inf   # a series model trains on one record
    assert "failed or diverged on some block: GM(0,N)" in chosen.reason


def test_the_score_is_the_geometric_mean_so_no_one_regime_rules_it():
    # ten times worse on one regime, ten times better on two: as good as 1 on all three (the mean says 3.4)
    assert geometric_mean_rmse([0.1, 0.1, 10.0], floor=1e-9) == pytest.approx(10 ** (-1 / 3))
    assert geometric_mean_rmse([1.0, np.inf], floor=1e-9) == np.inf
    assert geometric_mean_rmse([0.0, 1.0], floor=1e-2) == pytest.approx(0.1)


def _orders(columns=(0, 1, 2)):
    return {f"{n} poles": (GreyBoxRegressor(n_poles=n, temperature_inputs=(2,)), list(columns)) for n in (1, 2, 3)}


def test_nested_orders_are_the_same_model_columns_and_parameters_at_a_lower_order():
    candidates = {
        **_orders(),
        "2 poles, other columns": (GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)), [0, 1, 3]),
        "1 pole, other parameters": (GreyBoxRegressor(n_poles=1, temperature_inputs=(2,), exponent=1.5), [0, 1, 2]),
        "MLR": (MLRRegressor(), [2]),
    }
    assert nested_lower_orders(candidates, "3 poles") == ["1 poles", "2 poles"]
    assert nested_lower_orders(candidates, "1 poles") == []
    assert nested_lower_orders(candidates, "2 poles, other columns") == []
    assert nested_lower_orders(candidates, "MLR") == []


def test_one_standard_error_on_paired_folds():
    best = [1.0, 2.0, 0.5, 4.0]
    # the folds differ twentyfold, but the simpler model tracks the best one: within its scatter
    assert within_one_standard_error([1.05, 1.9, 0.55, 4.1], best, floor=1e-9)
    # consistently 10 % worse on every fold: the paired difference has no scatter to hide in
    assert not within_one_standard_error([1.1, 2.2, 0.55, 4.4], best, floor=1e-9)
    assert not within_one_standard_error([1.0, np.inf, 0.5, 4.0], best, floor=1e-9)
    assert within_one_standard_error([1.0], [1.0], floor=1e-9)


def test_parsimony_takes_the_lowest_order_within_one_standard_error():
    candidates = _orders()
    folds = {"3 poles": [1.0, 2.0, 0.5, 4.0], "2 poles": [1.05, 1.9, 0.55, 4.1], "1 poles": [1.5, 3.0, 0.75, 6.0]}
    assert parsimonious_choice(candidates, folds, "3 poles", floor=1e-9) == "2 poles"
    folds["1 poles"] = [0.9, 2.2, 0.52, 4.2]
    assert parsimonious_choice(candidates, folds, "3 poles", floor=1e-9) == "1 poles"
    folds["3 poles"] = [1.0, np.inf, 0.5, 4.0]  # a best that diverged somewhere is left alone
    assert parsimonious_choice(candidates, folds, "3 poles", floor=1e-9) == "3 poles"


def test_a_second_pole_must_earn_more_than_the_folds_scatter():
    # a 5 % slow mode: two poles score best, but one pole is within one standard error of them
    faint = select_by_blocked_cv(_orders(), *_record(seed=0, slow_share=0.05))
    assert faint.ranking[0] == "2 poles" and faint.chosen == "1 poles"
    assert faint.reason.startswith("chose 1 poles: the lowest order within one standard error of 2 poles, whose "
                                   "geometric-mean RMSE on operating-regime blocks it did not see is the lowest")
    assert faint.reason.endswith("folds, and the two are within one standard error: these folds do not tell them "
                                 "apart.")
    assert " It beats 2 poles on " in faint.reason
    # each worst fold is its own model's, and RMSEs under 1 keep three significant digits
    def rmse(value):
        return f"{value:.2f}" if value >= 1 else f"{value:.3g}"
    assert (f"({rmse(faint.score['2 poles'])} against {rmse(faint.score['1 poles'])} " in faint.reason)
    assert (f"; worst fold {rmse(faint.worst_rmse['2 poles'])} against {rmse(faint.worst_rmse['1 poles'])} "
            in faint.reason)
    # a 30 % slow mode: two poles win by far more than the scatter and are kept
    clear = select_by_blocked_cv(_orders(), *_record(seed=0, slow_share=0.3))
    assert clear.ranking[0] == clear.chosen == "2 poles"
    assert clear.reason.startswith("chose 2 poles: lowest geometric-mean RMSE")
    assert clear.reason.endswith(f" It beats {clear.ranking[1]} on 6 of 6 folds.")


def test_a_candidate_that_cannot_be_fitted_ranks_last():
    X, y, speed = _record()
    candidates = {
        "MLR": (MLRRegressor(), [2]),
        "MLR 2": (MLRRegressor(), [2, 3]),
        "grey-box 4 poles on 300 columns": (GreyBoxRegressor(n_poles=4), [0, 1] + [2] * 300),
    }
    chosen = select_by_blocked_cv(candidates, X, y, speed)
    assert chosen.ranking[-1] == "grey-box 4 poles on 300 columns"
    assert "failed or diverged on some block: grey-box 4 poles on 300 columns" in chosen.reason


def test_rank_agreement():
    a = {"x": 1.0, "y": 2.0, "z": 3.0, "w": np.inf}
    assert rank_agreement(a, a) == pytest.approx(1.0)
    assert rank_agreement(a, {"x": 4.0, "y": 3.0, "z": 2.0, "w": 1.0}) == pytest.approx(-1.0)
    with pytest.raises(ValueError, match="at least 3 common"):
        rank_agreement({"x": 1.0, "y": 2.0}, {"x": 1.0, "y": 2.0})


def test_the_margin_names_the_next_best_and_whether_the_folds_separate_them():
    folds = {"a": [1.0, 1.0, 1.0, 1.0], "b": [2.0, 2.0, 2.0, 2.1], "c": [1.05, 0.95, 1.1, 0.9],
             "d": [0.5, np.inf, 0.5, 0.5]}
    assert margin(["a", "c", "b", "d"], "a", folds, floor=1e-9) == ("c", 2, True)    # within the scatter
    assert margin(["a", "b", "d"], "a", folds, floor=1e-9) == ("b", 4, False)        # clear on every fold
    assert margin(["d", "a"], "d", folds, floor=1e-9) is None                       # the choice failed on a fold
    assert margin(["a", "d"], "a", folds, floor=1e-9) is None                       # no rival left
