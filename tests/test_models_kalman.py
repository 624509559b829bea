"""models.kalman: discretisation against scipy, the filter against the batch Gaussian posterior, band coverage."""
import numpy as np
import pytest
from scipy.integrate import quad_vec
from scipy.linalg import expm
from scipy.signal import cont2discrete

from models.kalman import KalmanFilter, discretize


def thermal_rc(n=3, seed=0):
    """A stable RC chain: n lumped temperatures, heat into the first, loss to ambient from the last."""
    rng = np.random.default_rng(seed)
    A = np.zeros((n, n))
    for i in range(n - 1):
        g = rng.uniform(0.5, 2.0) * 1e-3
        A[i, i] -= g
        A[i + 1, i + 1] -= g
        A[i, i + 1] += g
        A[i + 1, i] += g
    A[-1, -1] -= 1e-3
    B = np.zeros((n, 2))
    B[0, 0], B[-1, 1] = 1e-3, 1e-3          # power (scaled) into node 0, ambient into the last node
    return A, B


def test_discretize_matches_scipy_zoh_and_van_loan_matches_the_integral():
    A, B = thermal_rc()
    Qc = np.diag([1e-4, 2e-4, 5e-5])
    F, G, Q = discretize(A, B, 60.0, Qc)
    Fs, Gs, *_ = cont2discrete((A, B, np.eye(3), np.zeros((3, 2))), 60.0, method="zoh")
    np.testing.assert_allclose(F, Fs, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(G, Gs, rtol=1e-12, atol=1e-14)
    Q_quad, _ = quad_vec(lambda s: expm(A * s) @ Qc @ expm(A.T * s), 0.0, 60.0, epsabs=1e-14)
    np.testing.assert_allclose(Q, Q_quad, rtol=1e-8)


def batch_posterior(F, G, H, Q, R, x0, P0, U, Y):
    """Posterior mean and covariance of the last state from the joint Gaussian of all states (no recursion)."""
    n, N = len(x0), len(U)
    # states as x_k = Φ_k x0 + Σ_j Ψ_kj w_j + known input terms; unknowns z = [x0, w_0 .. w_{N-2}]
    dim = n * N
    T = np.zeros((N, n, dim))           # x_k = T_k z + c_k
    c = np.zeros((N, n))
    T[0][:, :n] = np.eye(n)
    c[0] = 0.0
    for k in range(1, N):
        T[k] = F @ T[k - 1]
        T[k][:, n * k:n * (k + 1)] += np.eye(n)
        c[k] = F @ c[k - 1] + G @ U[k - 1]
    prior_mean = np.zeros(dim)
    prior_mean[:n] = x0
    prior_cov = np.zeros((dim, dim))
    prior_cov[:n, :n] = P0
    for k in range(1, N):
        prior_cov[n * k:n * (k + 1), n * k:n * (k + 1)] = Q
    rows, obs, noise = [], [], []
    for k in range(N):
        for i in range(H.shape[0]):
            if np.isfinite(Y[k, i]):
                rows.append(H[i] @ T[k])
                obs.append(Y[k, i] - H[i] @ c[k])
                noise.append(R[i, i])
    Hb, yb, Rb = np.array(rows), np.array(obs), np.diag(noise)
    S = Hb @ prior_cov @ Hb.T + Rb
    K = prior_cov @ Hb.T @ np.linalg.inv(S)
    post_mean = prior_mean + K @ (yb - Hb @ prior_mean)
    post_cov = prior_cov - K @ Hb @ prior_cov
    last = T[-1]
    return last @ post_mean + c[-1], last @ post_cov @ last.T


def test_filter_equals_the_batch_posterior_with_missing_measurements():
    rng = np.random.default_rng(1)
    A, B = thermal_rc()
    F, G, Q = discretize(A, B, 60.0, np.diag([1e-4, 2e-4, 5e-5]))
    H = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    R = np.diag([0.01, 0.04])
    N = 12
    U = np.column_stack([rng.uniform(0, 5, N), 20 + rng.normal(0, 0.5, N)])
    Y = rng.normal(0.0, 1.0, (N, 2)) + 20.0
    Y[3, 0] = Y[5, :] = Y[8, 1] = np.nan
    x0, P0 = np.full(3, 20.0), np.diag([1.0, 2.0, 0.5])
    kf = KalmanFilter(F, G, H, None, Q, R).reset(x0, P0)
    result = kf.filter(U, Y)
    mean, cov = batch_posterior(F, G, H, Q, R, x0, P0, U, Y)
    np.testing.assert_allclose(result.state[-1], mean, rtol=1e-9)
    np.testing.assert_allclose(kf.P, cov, rtol=1e-7, atol=1e-12)
    assert list(result.measured) == [2, 2, 2, 1, 2, 0, 2, 2, 1, 2, 2, 2]
    assert np.isnan(result.normalised_innovation[5])


def test_the_95_percent_band_of_an_unmeasured_output_covers_the_truth():
    # Monte Carlo truths drawn from the model itself: the band is a claim about exactly this
    rng = np.random.default_rng(7)
    A, B = thermal_rc()
    F, G, Q = discretize(A, B, 60.0, np.diag([2e-4, 2e-4, 2e-4]))
    H, R = np.array([[0.0, 0.0, 1.0]]), np.array([0.02])
    L = np.array([[1.0, 0.0, 0.0]])          # the hot node nobody measures
    N, runs, inside = 200, 60, 0
    U = np.column_stack([np.where(np.arange(N) < 100, 3.0, 0.0), np.full(N, 20.0)])
    chol_Q = np.linalg.cholesky(Q)
    for _ in range(runs):
        x = 20.0 + rng.normal(0.0, 1.0, 3)
        truth, Y = np.empty(N), np.empty((N, 1))
        for k in range(N):
            truth[k] = x[0]
            Y[k] = H @ x + rng.normal(0.0, np.sqrt(R[0]))
            x = F @ x + G @ U[k] + chol_Q @ rng.normal(size=3)
        kf = KalmanFilter(F, G, H, None, Q, R).reset(np.full(3, 20.0), np.eye(3))
        result = kf.filter(U, Y, L=L)
        inside += np.sum(np.abs(truth - result.output[:, 0]) <= 1.96 * result.output_std[:, 0])
    coverage = inside / (N * runs)
    assert coverage == pytest.approx(0.95, abs=0.02)


def test_bad_noise_covariances_are_refused():
    with pytest.raises(ValueError, match="Q and R must be finite"):
        KalmanFilter(np.eye(1), np.eye(1), np.eye(1), None, [[np.nan]], [1.0])
