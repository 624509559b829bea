"""models.kalman.discretize over any step: a stiff model over a long gap keeps finite, exact step matrices.

Before, the Van Loan block exponential held e^{−A dt}: with a mode of 0.34 /s (the vmc_ram ROM's fastest) it
overflowed beyond dt ≈ 2000 s and the observer went NaN for ever.
"""
import numpy as np
import pytest
from scipy.linalg import expm, solve_continuous_lyapunov

from models.kalman import discretize


def van_loan(A, Qc, dt):
    """The textbook Van Loan form in one block exponential (exact, as long as e^{−A dt} stays representable)."""
    n = len(A)
    C = np.zeros((2 * n, 2 * n))
    C[:n, :n], C[:n, n:], C[n:, n:] = -A, Qc, A.T
    E = expm(C * dt)
    return E[n:, n:].T @ E[:n, n:]


def stiff_chain(n=5):
    """A coupled chain (not diagonal, not normal) with rates from 1e-4 to 0.5 /s and noise on two states."""
    A = np.diag(-np.geomspace(1e-4, 0.5, n))
    A += np.diag(np.full(n - 1, 2e-3), 1)
    Qc = np.zeros((n, n))
    Qc[0, 0], Qc[-1, -1], Qc[0, -1], Qc[-1, 0] = 2e-6, 3e-4, 1e-6, 1e-6
    return A, np.ones((n, 1)), Qc


@pytest.mark.parametrize("dt", [1e-6, 0.5, 2.0])
def test_short_steps_equal_the_one_block_van_loan(dt):
    A, B, Qc = stiff_chain()
    np.testing.assert_allclose(discretize(A, B, dt, Qc)[2], van_loan(A, Qc, dt), rtol=1e-11, atol=1e-22)


@pytest.mark.parametrize("dt", [2400.0, 3600.0, 1e5])
def test_diagonal_stiff_model_over_a_long_gap_matches_the_closed_form(dt):
    """For diagonal A, Q_ij = Qc_ij (1 − e^{−(λi+λj)dt}) / (λi+λj) and G = (1 − e^{−λ dt}) / λ · B."""
    lam = np.array([1e-5, 7e-5, 3e-3, 0.34, 1.0])
    rng = np.random.default_rng(1)
    L = rng.normal(size=(5, 5)) * 1e-3
    Qc = L @ L.T
    B = rng.normal(size=(5, 2))
    F, G, Q = discretize(np.diag(-lam), B, dt, Qc)
    s = lam[:, None] + lam[None, :]
    np.testing.assert_allclose(Q, Qc * -np.expm1(-s * dt) / s, rtol=1e-10, atol=1e-22)
    np.testing.assert_allclose(G, (-np.expm1(-lam * dt) / lam)[:, None] * B, rtol=1e-10, atol=1e-22)
    np.testing.assert_allclose(F, np.diag(np.exp(-lam * dt)), rtol=1e-10, atol=1e-12)


def test_coupled_stiff_model_over_a_long_gap_matches_fine_sub_steps():
    """3600 s composed of 36 000 steps of 0.1 s, each the one-block Van Loan (safe at 0.1 s)."""
    A, B, Qc = stiff_chain()
    dt, steps = 3600.0, 36000
    h = dt / steps
    Fh, Qh = expm(A * h), van_loan(A, Qc, h)
    Q = np.zeros_like(Qc)
    for _ in range(steps):
        Q = Fh @ Q @ Fh.T + Qh
    F, _, Q_long = discretize(A, B, dt, Qc)
    assert np.all(np.isfinite(Q_long))
    np.testing.assert_allclose(Q_long, Q, rtol=1e-8, atol=1e-14 * np.abs(Q).max())
    np.testing.assert_allclose(F, expm(A * dt), rtol=1e-10, atol=1e-12)


def test_a_step_much_longer_than_every_time_constant_reaches_the_stationary_covariance():
    """Q(dt → ∞) solves A Q + Q Aᵀ + Qc = 0."""
    A, B, Qc = stiff_chain()
    _, _, Q = discretize(A, B, 1e7, Qc)
    np.testing.assert_allclose(Q, solve_continuous_lyapunov(A, -Qc), rtol=1e-8, atol=1e-14)


@pytest.mark.parametrize("dt", [-1.0, np.inf, np.nan])
def test_a_step_that_is_no_duration_is_refused(dt):
    A, B, Qc = stiff_chain()
    with pytest.raises(ValueError, match="finite number of seconds"):
        discretize(A, B, dt, Qc)
