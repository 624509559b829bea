"""ANFIS: Jang's sinc, gradient correctness, hybrid bookkeeping, fallback, rule listing."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from models import anfis as A
from models.anfis import ANFISRegressor


def sinc_grid(n=11):
    g = np.linspace(-10.0, 10.0, n)
    xx, yy = np.meshgrid(g, g)
    X = np.column_stack([xx.ravel(), yy.ravel()])
    return X, np.sinc(X[:, 0] / np.pi) * np.sinc(X[:, 1] / np.pi)  # sin(x)/x · sin(y)/y


def rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


def sinc_model(random_state=0):
    return ANFISRegressor(
        init="grid", n_mfs=4, epochs=100, premise_update="levenberg-marquardt", random_state=random_state
    )


@pytest.mark.parametrize("seed", range(3))
def test_jang_sinc_16_rules_training_rmse_below_001(seed):
    X, y = sinc_grid()
    assert X.shape == (121, 2)
    model = sinc_model(seed).fit(X, y)
    assert model.rule_mfs_.shape == (16, 2)
    assert model.training_rmse_[0] > 0.05  # the LSE on the initial grid alone is far off (0.098)
    # Jang's target; seeds 0-29 all reach < 1e-4 except seed 25 (0.013, a local minimum)
    assert rmse(model.predict(X), y) < 0.01
    # between the training points it is still sinc, not an interpolant with spikes (seeds 0-9: 0.003-0.021)
    X_between, y_between = sinc_grid(201)
    assert rmse(model.predict(X_between), y_between) < 0.05


def test_levenberg_marquardt_does_not_amplify_rounding():
    # Jang's grid on the symmetric sinc starts on a saddle. Before the seeded offset of the grid
    # centres, rounding decided which way training left it: inputs changed by 1e-14 (another CPU's
    # rounding) gave training RMSE 0.0085-0.015 and predictions 0.15-0.34 apart.
    X, y = sinc_grid()
    X_rounded = X * (1.0 + 1e-14 * np.random.default_rng(1).standard_normal(X.shape))
    a, b = sinc_model().fit(X, y), sinc_model().fit(X_rounded, y)
    assert abs(a.training_rmse_[-1] - b.training_rmse_[-1]) < 1e-8  # measured 3e-10
    X_between, _ = sinc_grid(41)
    assert np.max(np.abs(a.predict(X_between) - b.predict(X_between))) < 1e-4  # measured 4e-6


TRAIN_IN_SUBPROCESS = """
import sys
import numpy as np
from models import ANFISRegressor
rng = np.random.default_rng(0)
X = rng.standard_normal((20000, 8)).cumsum(axis=0) * 0.01
y = X @ rng.standard_normal(8) + np.sin(3 * X[:, 0]) + 0.1 * rng.standard_normal(20000)
m = ANFISRegressor(n_rules=3, epochs=20, premise_update="levenberg-marquardt", random_state=0).fit(X, y)
np.save(sys.argv[1], np.concatenate([m.mf_centers_.ravel(), m.mf_sigmas_.ravel(), m.consequents_.ravel()]))
"""


def test_same_seed_same_model_whatever_the_blas_thread_count(tmp_path):
    # With two OpenBLAS threads the long products Jᵀr, ΦᵀJ sum in another order; unpinned, the
    # fitted parameters differed by 2.4e-7 before this change, 1.7e-8 with the new LM (and the fit took
    # 10x longer on a loaded 2-core machine).
    runs = {}
    for threads in (1, 2):
        env = {**os.environ, "OPENBLAS_NUM_THREADS": str(threads), "OMP_NUM_THREADS": str(threads)}
        out = tmp_path / f"threads{threads}.npy"
        runs[threads] = (out, subprocess.Popen([sys.executable, "-c", TRAIN_IN_SUBPROCESS, str(out)], env=env,
                                               cwd=Path(__file__).resolve().parents[1], stderr=subprocess.PIPE))
    for out, process in runs.values():
        _, err = process.communicate()
        assert process.returncode == 0, err.decode()
    one, two = (np.load(out) for out, _ in runs.values())
    assert np.max(np.abs(one - two)) <= 1e-12


def test_jang_rule_lowers_training_error():
    X, y = sinc_grid()
    model = ANFISRegressor(init="grid", n_mfs=4, epochs=60, random_state=0).fit(X, y)
    assert model.training_rmse_[-1] < 0.5 * model.training_rmse_[0]  # 0.31 (seeds 0-4: 0.31-0.44)


def test_premise_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    Z = rng.standard_normal((40, 2))
    y = np.sin(Z[:, 0]) * Z[:, 1]
    initial = ANFISRegressor(init="grid", n_mfs=3)._initial_premises(Z, y, np.random.RandomState(0))
    centers, sigmas, rule_mfs = initial
    Z1 = A._with_bias(Z)
    theta = A._least_squares(A._normalised_firing(Z, centers, sigmas, rule_mfs), Z1, y, 0.0)

    def output(c, s):
        return A._output(A._normalised_firing(Z, c, s, rule_mfs), Z1, theta)[0]

    wbar = A._normalised_firing(Z, centers, sigmas, rule_mfs)
    F, f = A._output(wbar, Z1, theta)
    J = A._premise_jacobian(Z, wbar, f, F, centers, sigmas, rule_mfs)
    p = np.concatenate([centers.ravel(), sigmas.ravel()])
    h = 1e-6
    numeric = np.empty_like(J)
    for i in range(p.size):
        plus, minus = p.copy(), p.copy()
        plus[i] += h
        minus[i] -= h
        split = lambda q: (q[: centers.size].reshape(centers.shape), q[centers.size :].reshape(sigmas.shape))
        numeric[:, i] = (output(*split(plus)) - output(*split(minus))) / (2 * h)
    assert np.allclose(J, numeric, atol=1e-7)


def test_adaptive_step_rule():
    assert A._adapt_step(1.0, [5, 4, 3, 2, 1], 1.1, 0.9) == pytest.approx(1.1)  # four decreases
    assert A._adapt_step(1.0, [1, 2, 1, 2, 1], 1.1, 0.9) == pytest.approx(0.9)  # up-down twice
    assert A._adapt_step(1.0, [1, 2, 3, 2, 1], 1.1, 0.9) == 1.0
    assert A._adapt_step(1.0, [3, 2, 1], 1.1, 0.9) == 1.0


def test_final_least_squares_follows_last_premise_step():
    X, y = sinc_grid()
    model = ANFISRegressor(init="grid", n_mfs=3, epochs=5, random_state=0).fit(X, y)
    Z = (X - model.x_mean_) / model.x_scale_
    wbar = A._normalised_firing(Z, model.mf_centers_, model.mf_sigmas_, model.rule_mfs_)
    fresh = A._least_squares(wbar, A._with_bias(Z), y, model.ridge)
    assert np.allclose(model.consequents_, fresh)


def test_checking_set_keeps_best_epoch():
    rng = np.random.default_rng(1)
    X = rng.uniform(-2, 2, (300, 2))
    y = np.sin(X[:, 0]) + 0.5 * X[:, 1] ** 2 + 0.3 * rng.standard_normal(300)
    Xc = rng.uniform(-2, 2, (100, 2))
    yc = np.sin(Xc[:, 0]) + 0.5 * Xc[:, 1] ** 2
    model = ANFISRegressor(n_rules=6, epochs=40, random_state=0).fit(X, y, Xc, yc)
    assert model.best_epoch_ == int(np.argmin(model.checking_rmse_))
    achieved = np.sqrt(np.mean((model.predict(Xc) - yc) ** 2))
    assert achieved == pytest.approx(model.checking_rmse_.min(), rel=1e-9)


def test_validation_fraction_and_patience():
    rng = np.random.default_rng(2)
    X = rng.uniform(-2, 2, (200, 2))
    y = X[:, 0] * X[:, 1]
    model = ANFISRegressor(n_rules=4, epochs=300, validation_fraction=0.25, n_iter_no_change=5, random_state=0)
    model.fit(X, y)
    assert model.checking_rmse_.size == model.n_iter_ + 1
    assert model.n_iter_ - model.best_epoch_ <= 5


def test_outside_training_range_uses_nearest_rule_not_zero():
    # linear data: every rule's consequent is the same plane, so extrapolation is exact
    rng = np.random.default_rng(3)
    X = rng.uniform(0, 1, (80, 2))
    y = 2.0 * X[:, 0] - X[:, 1] + 3.0
    model = ANFISRegressor(n_rules=3, epochs=10, random_state=0).fit(X, y)
    far = np.array([[50.0, -40.0], [-1e3, 1e3]])
    assert np.allclose(model.predict(far), 2.0 * far[:, 0] - far[:, 1] + 3.0, rtol=1e-6)
    wbar = model.normalised_firing_strengths(far)
    assert np.allclose(wbar.sum(axis=1), 1.0) and np.all(np.isfinite(wbar))
    assert np.allclose(wbar.max(axis=1), 1.0)  # one rule (the nearest) carries the output


def test_fcm_rules_and_linguistic_listing():
    rng = np.random.default_rng(4)
    X = rng.uniform(0, 1, (90, 5))
    y = X @ np.arange(1.0, 6.0)
    model = ANFISRegressor(init="fcm", n_rules=3, epochs=3, random_state=0).fit(X, y)
    assert model.rule_mfs_.shape == (3, 5) and model.mf_centers_.shape == (5, 3)
    names = ["T05", "T11", "T40", "T65", "T75"]
    rules = model.rules_text(names)
    assert rules[0] == (
        "1. If (T05 is T05cluster1) and (T11 is T11cluster1) and (T40 is T40cluster1) "
        "and (T65 is T65cluster1) and (T75 is T75cluster1) then (out1 is out1cluster1)"
    )
    assert len(rules) == 3
    grid = ANFISRegressor(init="grid", n_mfs=2, epochs=0, random_state=0).fit(X[:, :2], y)
    assert grid.rules_text()[1] == "2. If (in1 is in1mf1) and (in2 is in2mf2) then (out1 is out1mf2)"
    centres, sigmas = grid.membership_parameters()
    # the first centres sit at the lower end of each input, up to the seeded offset: by construction at
    # most 1.5 % of the spacing (here the whole range), and not zero, else the grid stays symmetric
    offset = np.abs(centres[:, 0] - X[:, :2].min(axis=0)) / np.ptp(X[:, :2], axis=0)
    assert np.all(offset <= 0.015) and np.all(offset > 0)


def test_seeded_fcm_init_is_reproducible():
    rng = np.random.default_rng(5)
    X = rng.uniform(0, 1, (60, 3))
    y = np.sin(3 * X[:, 0]) + X[:, 1]
    a = ANFISRegressor(n_rules=4, epochs=5, random_state=9).fit(X, y).predict(X)
    b = ANFISRegressor(n_rules=4, epochs=5, random_state=9).fit(X, y).predict(X)
    assert np.array_equal(a, b)


def test_anfis_errors():
    X, y = sinc_grid()
    # 16 rules × 3 consequents + 2 inputs × 4 MFs × (centre, σ) = 64 parameters
    with pytest.raises(ValueError, match="64 parameters to fit and needs at least 65 samples, got 40"):
        ANFISRegressor(init="grid", n_mfs=4).fit(X[:40], y[:40])
    wide = np.random.default_rng(0).uniform(0, 1, (5000, 16))
    with pytest.raises(ValueError, match=r"2\*\*16 = 65,536 rules: use FCM initialisation .* or a selected subset"):
        ANFISRegressor(init="grid", n_mfs=2).fit(wide, wide.sum(axis=1))
    with pytest.raises(ValueError, match="init must be"):
        ANFISRegressor(init="bogus").fit(X, y)
    with pytest.raises(ValueError, match="premise_update"):
        ANFISRegressor(premise_update="adam").fit(X, y)
    with pytest.raises(ValueError, match="X_check has 1 features"):
        ANFISRegressor().fit(X, y, X[:, :1], y)
    with pytest.raises(NotFittedError):
        ANFISRegressor().predict(X)
