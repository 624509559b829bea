"""The prewhitened sandwich of ``models.robust_covariance``: unread entries are left out, not taken as residuals of 0,
and the gap diagnosis uses the same Bartlett estimator."""

import numpy as np
import pytest
from scipy.linalg import solve_toeplitz
from scipy.signal import lfilter
from test_models_greybox import record

import models.greybox
from models.greybox import GreyBoxRegressor
from models.robust_covariance import (
    andrews_bandwidth,
    bartlett_long_run,
    consecutive_runs,
    sandwich_covariance,
)
from twin.gap.fit import parameter_sd

N_ROWS, BLOCK = 600, slice(250, 330)


def _fit_arrays(seed=0, n_outputs=2, k=3):
    """``(J (n, o, k), r (n, o))``: a smooth Jacobian and AR(1) residuals of 10-row correlation."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, N_ROWS)
    J = np.stack([np.column_stack([np.ones_like(t), t, np.sin(3.0 * t + o)]) for o in range(n_outputs)], axis=1)
    r = lfilter([1.0], [1.0, -0.9], rng.normal(size=(N_ROWS, n_outputs)), axis=0)
    return J[:, :, :k], r


def test_a_block_no_output_read_gives_the_covariance_of_the_record_cut_there_into_two_segments():
    J, r = _fit_arrays()
    read = np.ones(r.shape, bool)
    read[BLOCK] = False
    J[BLOCK], r[BLOCK] = 0.0, 0.0            # the fit weighs those entries 0
    left_out = sandwich_covariance(J, r, [(0, N_ROWS)], 3, read)
    keep = np.all(read, axis=1)
    cut = sandwich_covariance(J[keep], r[keep], [(0, BLOCK.start), (BLOCK.start, int(keep.sum()))], 3)
    np.testing.assert_allclose(left_out[0], cut[0], rtol=1e-12)
    assert left_out[1] == pytest.approx(cut[1], rel=1e-12)
    # as residuals of 0 the block reads as a stretch the model fitted exactly, and counts 16 % more rows as
    # independent
    assert np.all(sandwich_covariance(J, r, [(0, N_ROWS)], 3)[1] > 1.1 * cut[1])


def test_each_output_counts_the_independent_rows_of_its_readings_against_the_parameters_it_sets():
    """Output 0 sets parameters 0 and 1, output 1 parameter 2, and output 1 is unread on a block: each parameter's
    degrees of freedom are those of the output that sets it, n_eff of its readings less its share of the parameters
    (was: one count pooled over the outputs, n_eff_0 + n_eff_1 − 3, for every parameter)."""
    J, r = _fit_arrays(seed=1)
    J[:, 0, 2] = J[:, 1, :2] = 0.0
    read = np.ones(r.shape, bool)
    read[BLOCK, 1] = False
    J[BLOCK, 1], r[BLOCK, 1] = 0.0, np.nan   # what an unread entry holds does not matter
    _, dof = sandwich_covariance(J, r, [(0, N_ROWS)], 3, read)
    n_eff_first = sandwich_covariance(J[:, [0]][:, :, :2], r[:, [0]], [(0, N_ROWS)], 0)[1][0]
    n_eff_second = sandwich_covariance(J[read[:, 1]][:, [1]][:, :, [2]], r[read[:, 1]][:, [1]],
                                       consecutive_runs(read[:, 1], [(0, N_ROWS)]), 0)[1][0]
    np.testing.assert_allclose(dof, [n_eff_first - 2, n_eff_first - 2, n_eff_second - 1], rtol=1e-12)


def test_one_output_takes_n_eff_less_the_parameters_fitted_for_every_parameter():
    J, r = _fit_arrays(seed=5, n_outputs=1)
    n_eff = sandwich_covariance(J, r, [(0, N_ROWS)], 0)[1]
    np.testing.assert_allclose(sandwich_covariance(J, r, [(0, N_ROWS)], 7)[1], n_eff - 7, rtol=1e-12)


def test_consecutive_runs_break_at_rows_left_out_and_at_segment_starts():
    kept = np.ones(12, bool)
    kept[[3, 4]] = False
    assert consecutive_runs(kept, [(0, 8), (8, 12)]) == [(0, 3), (3, 6), (6, 10)]
    assert consecutive_runs(np.zeros(4, bool), [(0, 4)]) == []


def test_a_grey_box_fit_leaves_an_observed_thermometers_missing_readings_out_of_its_intervals(monkeypatch):
    """An observed thermometer out for 200 min: the residuals' autoregression and effective row count are those of
    its readings, the block cut out, not of readings of 0 there."""
    calls = []

    def recorded(*args, **kwargs):
        calls.append((args, sandwich_covariance(*args, **kwargs)))
        return calls[-1][1]

    monkeypatch.setattr(models.greybox, "sandwich_covariance", recorded)
    X, drift = record(np.arange(0.0, 30 * 3600.0, 60.0), [1500.0, 3000.0, 4500.0])
    X[300:500, 3] = np.nan
    noise = lfilter([1.0], [1.0, -0.95], np.random.default_rng(2).normal(0.0, 0.3, len(drift)))
    GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), observed=(3,)).fit(X, drift + noise)
    (J, r, segments, n_fitted, read), (_, dof) = calls[0]
    measured = np.isfinite(X[:, 3])   # used: every row has weight 1
    np.testing.assert_array_equal(read, np.column_stack([np.ones_like(measured), measured]))
    n_eff_drift = sandwich_covariance(J[:, [0]], r[:, [0]], segments, 0)[1][0]
    n_eff_thermometer = sandwich_covariance(J[measured][:, [1]], r[measured][:, [1]],
                                            consecutive_runs(measured, segments), 0)[1][0]
    # each parameter's degrees of freedom lie between the two outputs' own (n_eff_o less its share of the fit)
    assert np.all((min(n_eff_drift, n_eff_thermometer) - n_fitted <= dof)
                  & (dof < n_eff_drift + n_eff_thermometer - n_fitted))


def test_the_gap_diagnosis_takes_the_grey_box_models_bartlett_estimator():
    """``parameter_sd`` without the tolerance term is the sandwich around ``bartlett_long_run`` of the scores
    summed per time row; its bandwidth is Andrews' of those scores, between 1 and half the rows."""
    J, r = _fit_arrays(seed=3, n_outputs=1)
    J, r = np.repeat(J[:, 0], 2, axis=0), np.repeat(r[:, 0], 2)   # two channels per time row
    rows = np.repeat(np.arange(N_ROWS), 2)
    scores = (J * r[:, None]).reshape(N_ROWS, 2, -1).sum(axis=1)
    bread = np.linalg.pinv(J.T @ J)
    expected = np.sqrt(np.diag(bread @ bartlett_long_run(scores, [(0, N_ROWS)]) @ bread))
    np.testing.assert_allclose(parameter_sd(J, r, rows, tolerance=False), expected, rtol=1e-10)
    assert 1 <= andrews_bandwidth(scores, [(0, N_ROWS)]) <= N_ROWS // 2
    assert andrews_bandwidth(np.ones((N_ROWS, 2)), [(0, N_ROWS)]) == 1   # no variation: no correlation


def test_the_bandwidth_does_not_depend_on_the_parameters_units():
    """τ in s or in h, the same lags: the score components weigh equally, whatever their size."""
    J, r = _fit_arrays(seed=4, n_outputs=1)
    scores = J[:, 0] * r
    scores[:, 2] = lfilter([1.0], [1.0, -0.99], scores[:, 2])   # one persistent component
    in_other_units = scores * np.array([1.0, 1.0, 1e-3])
    assert andrews_bandwidth(in_other_units, [(0, N_ROWS)]) == andrews_bandwidth(scores, [(0, N_ROWS)])


def _white_rows(seed=6, n_rows=400):
    """``(J (n, 2, 3), r (n, 2), segments)``: two outputs sharing all three parameters, white residuals of different
    sizes, every row its own segment (so no autoregression and no lag enters: n_eff is the row count)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n_rows)
    J = np.stack([np.column_stack([np.ones_like(t), t, np.cos(2.0 * t + o)]) for o in range(2)], axis=1)
    return J, rng.normal(size=(n_rows, 2)) * [1.0, 3.0], [(row, row + 1) for row in range(n_rows)]


def test_two_outputs_sharing_the_parameters_take_welch_satterthwaites_degrees_of_freedom_and_scaled_scores():
    """Worked by hand: bread (JᵀJ)⁻¹, each output's leverage plus half the 8 profiled parameters as its share k_o,
    its scores J_o r_o scaled by n / (n − k_o), V_o = diag(bread S_o bread), dof = (Σ V_o)² / Σ V_o² / (n − k_o).
    Fails with dof = Σ V_o / Σ (V_o / dof_o), and with the scaling left out."""
    J, r, segments = _white_rows()
    n_rows, n_fitted = len(r), 3 + 8
    bread = np.linalg.inv(sum(J[:, o].T @ J[:, o] for o in range(2)))
    shares = [np.trace(J[:, o] @ bread @ J[:, o].T) + 8 / 2 for o in range(2)]
    scores = [J[:, o] * r[:, [o]] * n_rows / (n_rows - shares[o]) for o in range(2)]
    parts = np.array([np.diag(bread @ (s.T @ s) @ bread) for s in scores])
    expected_dof = parts.sum(axis=0) ** 2 / np.sum(parts ** 2 / (n_rows - np.array(shares))[:, None], axis=0)
    total = scores[0] + scores[1]
    covariance, dof = sandwich_covariance(J, r, segments, n_fitted)
    np.testing.assert_allclose(dof, expected_dof, rtol=1e-10)
    np.testing.assert_allclose(covariance, bread @ (total.T @ total) @ bread, rtol=1e-10)


def _yule_walker_whitened(r, J):
    """Independent of the module: the Yule–Walker AR (order 0 … 12 (n/100)^¼ by AIC) of ``r``, solved as a Toeplitz
    system for each order; ``(v, W, n_eff)`` with ``W`` the Jacobian filtered by it backwards in time."""
    n_rows = len(r)
    gamma = np.array([r[: n_rows - lag] @ r[lag:] for lag in range(int(12.0 * (n_rows / 100.0) ** 0.25) + 1)]) / n_rows
    fits = [(n_rows * np.log(gamma[0]), np.zeros(0))]
    for order in range(1, len(gamma)):
        phi = solve_toeplitz(gamma[:order], gamma[1: order + 1])
        fits.append((n_rows * np.log(gamma[0] - phi @ gamma[1: order + 1]) + 2 * order, phi))
    phi = min(fits, key=lambda fit: fit[0])[1]
    a = np.r_[1.0, -phi]
    innovation = gamma[0] - phi @ gamma[1: len(phi) + 1]
    return lfilter(a, [1.0], r), lfilter([1.0], a, J[::-1], axis=0)[::-1], n_rows * gamma[0] * a.sum() ** 2 / innovation


def _lag_sums(scores, lags):
    """``Σ_|l|≤L (1 − |l|/(L+1)) Γ_l`` with ``Γ_l = Σ_t s_t s_(t+l)ᵀ``, ``Γ_−l = Γ_lᵀ``: written out, one segment."""
    total = scores.T @ scores
    for lag in range(1, lags + 1):
        gamma = scores[:-lag].T @ scores[lag:]
        total += (1.0 - lag / (lags + 1)) * (gamma + gamma.T)
    return total


def test_the_covariance_of_two_autocorrelated_outputs_is_the_formula_written_out():
    """AR(1) residuals, outputs sharing parameters 0 and 2: whitened by an independent Yule–Walker fit, scores
    scaled by n_eff / (n_eff − k_o), the Bartlett sum over lags. Fails with the scaling left out."""
    J, r = _fit_arrays(seed=7)
    J[:, 1, 1] = 0.0   # parameter 1 is output 0's alone
    n_fitted = 3 + 2 * 5
    bread = np.linalg.inv(sum(J[:, o].T @ J[:, o] for o in range(2)))
    scores = []
    for o in range(2):
        v, W, n_eff = _yule_walker_whitened(r[:, o], J[:, o])
        share = np.trace(J[:, o] @ bread @ J[:, o].T) + 5
        scores.append(W * v[:, None] * n_eff / (n_eff - share))
    total = scores[0] + scores[1]
    expected = bread @ _lag_sums(total, andrews_bandwidth(total, [(0, N_ROWS)])) @ bread
    np.testing.assert_allclose(sandwich_covariance(J, r, [(0, N_ROWS)], n_fitted)[0], expected, rtol=1e-8)


def test_bartletts_long_run_covariance_is_its_weighted_lag_sum_in_each_segment():
    """A 3-row segment takes at most 2 lags, whatever the bandwidth of the others."""
    J, r = _fit_arrays(seed=8, n_outputs=1)
    scores = J[:, 0] * r
    segments = [(0, 400), (400, 597), (597, 600)]
    lags = andrews_bandwidth(scores, segments)
    assert lags > 2
    expected = sum(_lag_sums(scores[start:stop], min(lags, stop - start - 1)) for start, stop in segments)
    np.testing.assert_allclose(bartlett_long_run(scores, segments), expected, rtol=1e-10)


def test_an_output_whose_scale_cannot_be_estimated_leaves_undetermined_only_what_it_sets():
    """Output 1 alone sets parameter 2 and its residual is a swing over the whole record (n_eff below its share
    of the 3 + 2 × 4 parameters): parameter 2 is undetermined, parameters 0 and 1, which output 0 sets, keep the
    degrees of freedom of output 0 alone and a finite variance (was: all three undetermined)."""
    J, r = _fit_arrays(seed=9)
    J[:, 0, 2] = J[:, 1, :2] = 0.0
    r[:, 1] = np.sin(np.linspace(0.0, 3.0, N_ROWS))
    covariance, dof = sandwich_covariance(J, r, [(0, N_ROWS)], 3 + 2 * 4)
    assert np.all(np.isinf(covariance[2])) and np.all(np.isinf(covariance[:, 2])) and dof[2] == 1.0
    assert np.all(np.isfinite(covariance[:2, :2])) and np.all(np.diag(covariance)[:2] > 0)
    alone = sandwich_covariance(J[:, [0]][:, :, :2], r[:, [0]], [(0, N_ROWS)], 2 + 4)
    np.testing.assert_allclose(dof[:2], alone[1], rtol=1e-10)


def test_a_nearly_singular_jacobian_gives_undetermined_rather_than_huge_variances():
    """Two columns equal to 1e-7 (condition of JᵀJ ~1e15): the inverse does not raise, but its leverage traces sum to
    3.05, not 3 (was: variances of ~1e14 read as an interval)."""
    t = np.linspace(0.0, 1.0, N_ROWS)
    J = np.column_stack([np.ones_like(t), t, t + 1e-7 * np.sin(7.0 * t)])[:, None, :]
    r = np.random.default_rng(10).normal(size=(N_ROWS, 1))
    covariance, dof = sandwich_covariance(J, r, [(0, N_ROWS)], 3)
    assert np.all(np.isinf(covariance)) and np.all(dof == 1.0)
    J[:, 0, 2] = t ** 2   # well posed: finite
    assert np.all(np.isfinite(sandwich_covariance(J, r, [(0, N_ROWS)], 3)[0]))
