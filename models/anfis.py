"""First-order Takagi–Sugeno ANFIS with Gaussian membership functions (Jang 1993; thesis §3.3).

Layers, for inputs x ∈ R^d and rules r = 1..R:

1. ``μ_{r,d}(x_d) = exp(-(x_d - c_{r,d})² / (2 σ_{r,d}²))``
2. firing strength ``w_r = Π_d μ_{r,d}(x_d)``
3. normalisation ``w̄_r = w_r / Σ_s w_s``
4. consequents ``f_r = p_r · x + q_r``
5. output ``F = Σ_r w̄_r f_r``

Structure: ``init="grid"`` gives ``n_mfs`` MFs per input and one rule per
combination (R = n_mfs^d); ``init="fcm"`` gives genfis3-style multivariate
rules, one per fuzzy c-means cluster of the joint input–output data, each
with its own MF per input (the thesis's ANFIS-FCM).

Training is Jang's hybrid rule: the consequents are always the least-squares
solution for the current premises, and the premises (centres and widths)
move by one of two documented updates (``premise_update``):

* ``"jang"`` (default, as MATLAB ``anfis``): a normalised steepest-descent
  step, the premise vector moves by κ along ``-∇E/‖∇E‖``. κ starts at
  ``step_size`` (0.01), grows ×``step_increase`` (1.1) after four
  consecutive error decreases and shrinks ×``step_decrease`` (0.9) after two
  consecutive increase–decrease oscillations.
* ``"levenberg-marquardt"``: a damped Gauss–Newton step on the
  variable-projection (Kaufman) Jacobian of the premises, i.e. with the
  consequents' own dependence on the premises projected out. A step is kept
  when the error falls by a fair share (gain ratio > 1e-3) of the predicted
  decrease; the damping follows Nielsen's rule; the first step is no longer
  than ``step_size`` (Jang's κ₀), so the premises leave the initial guess
  gradually; training stops once a step is predicted to lower the squared
  error by less than 1e-12 of it. Jang's first-order rule stalls on some
  problems with Gaussian MFs (on the two-input sinc at RMSE ≈ 0.03); this
  update converges in tens of epochs.

**Reproducibility.** ``random_state`` seeds the FCM initialisation and, for
``init="grid"``, an offset of every grid centre by up to ±1.5 % of the MF
spacing. A grid on symmetric data (Jang's sinc is even in x and y and
symmetric under x ↔ y) starts on a saddle of the training error: without the
offset the premises leave it in a direction that rounding decides, which
differs between CPUs and BLAS builds, and training then ends in a different
minimum (RMSE 0.0085–0.015 on the sinc for inputs changed by 1e-14). ``fit``
runs with one BLAS thread (:mod:`models._threads`), so a seed gives the same
model whatever ``OPENBLAS_NUM_THREADS`` is.

Every premise step is followed by a least-squares solve, so training ends
with a final LSE after the last premise step and the consequents are never
one step stale. With a checking set, the parameters of the epoch with the
lowest checking RMSE are kept.

Conventions:

* Inputs are standardised internally, ``z = (x - x_mean_) / x_scale_``; the
  premise parameters ``mf_centers_``, ``mf_sigmas_`` and consequents
  ``consequents_`` live in z units, so the step size is scale-free.
  :meth:`ANFISRegressor.membership_parameters` returns them in input units.
* The least-squares solve adds a Tikhonov term ``ridge × mean(diag ΦᵀΦ) × I``
  (default 1e-8): it only guards against singular normal equations when rules
  barely fire or inputs are collinear.
* **Outside the training range** the firing strengths are normalised in
  log-space with a max-shift, ``w̄ = exp(log w - max log w) / Σ …``, so w̄
  never becomes 0/0: far from the data the rule whose MFs are nearest (in
  σ-scaled distance) dominates and the output is that rule's linear
  consequent, a linear extrapolation, never a silent 0.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Literal, NamedTuple

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted

from ._threads import one_blas_thread
from ._validation import (
    check_n_features,
    check_positive_int,
    require_parameters,
    validate_x,
    validate_xy,
)
from .fcm import FuzzyCMeans
from .registry import register_model

_SIGMA_FLOOR = 1e-3  # z units; keeps a Gaussian MF from collapsing to a spike
_GRID_JITTER = 3e-2  # seeded offset of the grid centres, as a fraction of the MF spacing (module doc)
_MAX_GRID_RULES = 4096  # the firing strengths alone take n_samples × rules × inputs floats
_LM_DAMPING0 = 1e-3  # initial LM damping, relative to the Marquardt scaling diag(JᵀJ)
_LM_RTOL = 1e-12  # LM has converged once a step is predicted to lower the squared error by less
_LM_MAX_REJECTIONS = 30


def _standardise(X):
    mean = X.mean(axis=0)
    scale = X.std(axis=0)
    scale[scale == 0.0] = 1.0
    return mean, scale


def _log_firing(Z, centers, sigmas, rule_mfs):
    """log w_r for every sample, (n_samples, n_rules); centres/σ are (d, n_mfs)."""
    cols = np.arange(Z.shape[1])
    c = centers[cols, rule_mfs]  # (R, d)
    s = sigmas[cols, rule_mfs]
    u = (Z[:, None, :] - c[None]) / s[None]
    return -0.5 * np.einsum("nrd,nrd->nr", u, u)


def _normalised_firing(Z, centers, sigmas, rule_mfs):
    """w̄ via a max-shift in log space, so the nearest rule dominates far outside the data."""
    log_w = _log_firing(Z, centers, sigmas, rule_mfs)
    log_w -= log_w.max(axis=1, keepdims=True)
    w = np.exp(log_w)
    return w / w.sum(axis=1, keepdims=True)


def _with_bias(Z):
    return np.hstack([Z, np.ones((Z.shape[0], 1))])


def _output(wbar, Z1, consequents):
    f = Z1 @ consequents.T  # (n, R)
    return np.einsum("nr,nr->n", wbar, f), f


def _design(wbar, Z1):
    """Consequent design matrix Φ, (n_samples, n_rules·(d+1)): column (r, j) is w̄_r·[z, 1]_j."""
    n, R = wbar.shape
    return (wbar[:, :, None] * Z1[:, None, :]).reshape(n, -1)


class _LeastSquares(NamedTuple):
    """The consequent least squares for fixed premises, and what the premise steps reuse."""

    wbar: np.ndarray  # (n, R) normalised firing strengths
    phi: np.ndarray  # (n, R·(d+1)) design matrix Φ
    factor: tuple  # Cholesky factor of ΦᵀΦ + ridge·mean(diag ΦᵀΦ) I
    theta: np.ndarray  # (R, d+1) consequents
    F: np.ndarray  # (n,) output
    f: np.ndarray  # (n, R) rule outputs
    sse: float  # Σ (F - y)²


def _solve_consequents(wbar, Z1, y, ridge):
    """Consequents minimising ‖Φθ - y‖² + ridge·mean(diag ΦᵀΦ)‖θ‖², as a :class:`_LeastSquares`."""
    phi = _design(wbar, Z1)
    gram = phi.T @ phi
    gram[np.diag_indices_from(gram)] += ridge * max(np.trace(gram) / gram.shape[0], 1e-300)
    factor = scipy.linalg.cho_factor(gram)
    theta = scipy.linalg.cho_solve(factor, phi.T @ y).reshape(wbar.shape[1], Z1.shape[1])
    F, f = _output(wbar, Z1, theta)
    return _LeastSquares(wbar, phi, factor, theta, F, f, float((F - y) @ (F - y)))


def _least_squares(wbar, Z1, y, ridge):
    """Consequents (R, d+1) minimising ‖Φθ - y‖² + ridge·mean(diag ΦᵀΦ)‖θ‖²."""
    return _solve_consequents(wbar, Z1, y, ridge).theta


def _premise_jacobian(Z, wbar, f, F, centers, sigmas, rule_mfs):
    """∂F_n/∂[centres, σ] with the consequents held fixed, shape (n_samples, 2·d·n_mfs).

    Uses ∂F/∂log w_r = w̄_r (f_r - F) and, for a Gaussian MF,
    ∂log w_r/∂c = (z - c)/σ², ∂log w_r/∂σ = (z - c)²/σ³. Rules that share an
    MF (grid partition) add their contributions to the same column.
    """
    n, d = Z.shape
    cols = np.arange(d)
    c = centers[cols, rule_mfs]  # (R, d)
    s = sigmas[cols, rule_mfs]
    a = wbar * (f - F[:, None])  # (n, R)
    u = Z[:, None, :] - c[None]  # (n, R, d)
    share = np.zeros((d,) + rule_mfs.shape[:1] + (centers.shape[1],))  # input d: rule r uses MF m
    share[cols[None, :], np.arange(rule_mfs.shape[0])[:, None], rule_mfs] = 1.0
    g_c = a[:, :, None] * u / s**2  # ∂F/∂c_{r,d} per rule, (n, R, d)
    g_s = g_c * u / s  # ∂F/∂σ_{r,d}
    # sum the rules sharing each MF: one (n, R) @ (R, n_mfs) product per input
    j_c = np.matmul(g_c.transpose(2, 0, 1), share).transpose(1, 0, 2)
    j_s = np.matmul(g_s.transpose(2, 0, 1), share).transpose(1, 0, 2)
    return np.hstack([j_c.reshape(n, -1), j_s.reshape(n, -1)])


def _projected_normal_equations(J, residual, ls):
    """``(J_Kᵀ J_K, J_Kᵀ r)`` for Kaufman's variable-projection Jacobian ``J_K = (I - Φ(ΦᵀΦ)⁻¹Φᵀ) J``.

    The consequents are the least-squares solution for the premises, so the
    residual depends on the premises also through them; Kaufman's
    approximation of that dependence projects the premise Jacobian onto the
    complement of the consequent basis Φ. The gradient barely changes (the
    residual is already orthogonal to Φ, up to the ridge), but the
    Gauss–Newton model no longer proposes premise moves that the next
    least-squares solve undoes, so LM converges in tens of steps.
    """
    J = J - ls.phi @ scipy.linalg.cho_solve(ls.factor, ls.phi.T @ J)
    return J.T @ J, J.T @ residual


def _adapt_step(step, errors, increase, decrease):
    """Jang's step-size rule on the last five training errors."""
    if len(errors) < 5:
        return step
    e = errors[-5:]
    d = np.diff(e)
    if np.all(d < 0):
        return step * increase
    if d[0] > 0 and d[1] < 0 and d[2] > 0 and d[3] < 0:
        return step * decrease
    return step


@register_model({"anfis": {"init": "fcm", "n_rules": 3, "epochs": 50, "random_state": 0},
                 "anfis-fcm": {"init": "fcm", "n_rules": 3, "epochs": 50, "random_state": 0},
                 "anfis-grid": {"init": "grid", "n_mfs": 2, "epochs": 50, "random_state": 0}})
class ANFISRegressor(RegressorMixin, BaseEstimator):
    """First-order Sugeno ANFIS with Gaussian MFs and hybrid learning.

    Parameters
    ----------
    init : {"fcm", "grid"}, default "fcm"
        Rule-base construction: multivariate FCM (one rule per cluster) or
        grid partition (``n_mfs`` per input, ``n_mfs**n_features`` rules).
    n_rules : int, default 3
        Number of FCM clusters/rules (``init="fcm"``; thesis Machine B: 3).
    n_mfs : int, default 2
        MFs per input (``init="grid"``).
    epochs : int, default 100
        Premise steps; each is followed by a least-squares solve.
    step_size, step_increase, step_decrease : float
        ``"jang"`` only: initial normalised step κ (z units) and its
        ×1.1 / ×0.9 adaptation.
    ridge : float, default 1e-8
        Relative Tikhonov term of the consequent least squares.
    validation_fraction : float or None
        If no checking set is passed to ``fit``, hold out this final
        (chronologically last) fraction of the training rows as one.
    n_iter_no_change : int or None
        Stop when the checking error has not improved for this many epochs.
    error_goal : float, default 0.0
        Stop once the training RMSE is at or below this value.
    fcm_m : float, default 2.0
        FCM fuzziness for ``init="fcm"``.
    premise_update : {"jang", "levenberg-marquardt"}, default "jang"
        Premise learning rule (see the module docstring).
    random_state : int, RandomState or None
        Seeds the FCM initialisation and the offset of the grid centres;
        an int gives the same model on every run and BLAS thread count.

    Attributes
    ----------
    x_mean_, x_scale_ : (n_features,) input standardisation
    mf_centers_, mf_sigmas_ : (n_features, n_mfs) Gaussian MF parameters in z units
    rule_mfs_ : (n_rules, n_features) int, which MF of each input a rule uses
    consequents_ : (n_rules, n_features + 1) ``[p_r, q_r]`` in z units
    training_rmse_, checking_rmse_ : (n_epochs,) history (checking is empty without a set)
    best_epoch_ : epoch whose parameters were kept
    n_iter_ : premise steps taken
    """

    def __init__(
        self,
        init: Literal["fcm", "grid"] = "fcm",
        n_rules: int = 3,
        n_mfs: int = 2,
        epochs: int = 100,
        step_size: float = 0.01,
        step_increase: float = 1.1,
        step_decrease: float = 0.9,
        ridge: float = 1e-8,
        validation_fraction: float | None = None,
        n_iter_no_change: int | None = None,
        error_goal: float = 0.0,
        fcm_m: float = 2.0,
        premise_update: Literal["jang", "levenberg-marquardt"] = "jang",
        random_state: int | np.random.RandomState | None = None,
    ):
        self.init = init
        self.n_rules = n_rules
        self.n_mfs = n_mfs
        self.epochs = epochs
        self.step_size = step_size
        self.step_increase = step_increase
        self.step_decrease = step_decrease
        self.ridge = ridge
        self.validation_fraction = validation_fraction
        self.n_iter_no_change = n_iter_no_change
        self.error_goal = error_goal
        self.fcm_m = fcm_m
        self.premise_update = premise_update
        self.random_state = random_state

    # ----------------------------------------------------------------- init
    def _initial_premises(self, Z, y, rng):
        d = Z.shape[1]
        if self.init == "grid":
            n_mfs = check_positive_int(self.n_mfs, "n_mfs")
            lo, hi = Z.min(axis=0), Z.max(axis=0)
            if n_mfs == 1:
                centers = ((lo + hi) / 2.0)[:, None]
                sigmas = np.maximum(hi - lo, 1.0)[:, None]
            else:
                centers = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, n_mfs)[None]
                # neighbouring MFs cross at μ = 0.5
                spacing = (hi - lo) / (n_mfs - 1)
                sigmas = np.repeat((spacing / (2.0 * np.sqrt(2.0 * np.log(2.0))))[:, None], n_mfs, 1)
                centers += _GRID_JITTER * spacing[:, None] * rng.uniform(-0.5, 0.5, centers.shape)
            rule_mfs = np.array(list(itertools.product(range(n_mfs), repeat=d)), dtype=np.intp)
        elif self.init == "fcm":
            n_rules = check_positive_int(self.n_rules, "n_rules")
            y_mean, y_scale = _standardise(y[:, None])
            data = np.hstack([Z, (y[:, None] - y_mean) / y_scale])
            fcm = FuzzyCMeans(n_clusters=n_rules, m=self.fcm_m, random_state=rng).fit(data)
            centers = fcm.cluster_centers_[:, :d].T.copy()  # (d, R)
            um = fcm.membership_**self.fcm_m  # (n, R)
            spread = np.einsum("nr,nrd->rd", um, (Z[:, None, :] - centers.T[None]) ** 2)
            sigmas = np.sqrt(spread / um.sum(axis=0)[:, None]).T
            rule_mfs = np.repeat(np.arange(n_rules, dtype=np.intp)[:, None], d, axis=1)
        else:
            raise ValueError(f"init must be 'fcm' or 'grid', got {self.init!r}.")
        return centers, np.maximum(sigmas, _SIGMA_FLOOR), rule_mfs

    def _n_rules_for(self, d):
        if self.init == "grid":
            return check_positive_int(self.n_mfs, "n_mfs") ** d
        return check_positive_int(self.n_rules, "n_rules")

    def n_parameters(self, n_features: int) -> int:
        """Free parameters for ``n_features`` inputs: consequents plus MF centres and widths.

        Parameters
        ----------
        n_features : int
            Number of inputs.

        Returns
        -------
        int
            ``n_rules·(n_features + 1) + 2·n_features·n_mfs`` (FCM: one MF per rule and input).
        """
        n_rules = self._n_rules_for(n_features)
        n_mfs = check_positive_int(self.n_mfs, "n_mfs") if self.init == "grid" else n_rules
        return n_rules * (n_features + 1) + 2 * n_features * n_mfs

    # ------------------------------------------------------------------ fit
    @one_blas_thread
    def fit(self, X: ArrayLike, y: ArrayLike, X_check: ArrayLike | None = None,
            y_check: ArrayLike | None = None) -> ANFISRegressor:
        """Train on ``X`` (n_samples, n_features), ``y`` (n_samples,).

        ``X_check``/``y_check`` form the checking set for early stopping
        (best-on-checking parameters are kept); see ``validation_fraction``.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Inputs, in any units (standardised internally).
        y : array_like, shape (n_samples,)
            Target, in its own unit (the prediction has the same unit).
        X_check : array_like, shape (n_check, n_features), optional
            Checking inputs (same units as ``X``).
        y_check : array_like, shape (n_check,), optional
            Checking target.

        Returns
        -------
        ANFISRegressor
            ``self``, fitted.

        Raises
        ------
        ValueError
            Bad hyperparameters, NaN/inf, or no more samples than parameters.
        """
        X, y = validate_xy(X, y, what="ANFISRegressor")
        if X_check is None and y_check is None and self.validation_fraction:
            n_check = int(round(X.shape[0] * self.validation_fraction))
            if not 0 < n_check < X.shape[0]:
                raise ValueError(f"validation_fraction={self.validation_fraction!r} leaves no data.")
            X, X_check, y, y_check = X[:-n_check], X[-n_check:], y[:-n_check], y[-n_check:]
        if self.init not in ("fcm", "grid"):
            raise ValueError(f"init must be 'fcm' or 'grid', got {self.init!r}.")
        hint = ""
        if self.init == "grid":
            n_rules = self._n_rules_for(X.shape[1])
            hint = (
                f" init='grid' makes n_mfs**n_features = {self.n_mfs}**{X.shape[1]} = {n_rules:,} rules: use "
                "FCM initialisation (init='fcm', one rule per cluster) or a selected subset of the inputs."
            )
            if n_rules > _MAX_GRID_RULES:
                raise ValueError(f"ANFISRegressor allows at most {_MAX_GRID_RULES:,} rules.{hint}")
        require_parameters(X.shape[0], self.n_parameters(X.shape[1]), "ANFISRegressor", hint=hint)
        has_check = X_check is not None or y_check is not None
        if has_check:
            X_check, y_check = validate_xy(X_check, y_check, what="the ANFIS checking set")
            if X_check.shape[1] != X.shape[1]:
                raise ValueError(f"X_check has {X_check.shape[1]} features but X has {X.shape[1]}.")
        if self.premise_update not in ("jang", "levenberg-marquardt"):
            raise ValueError(
                f"premise_update must be 'jang' or 'levenberg-marquardt', got {self.premise_update!r}."
            )
        epochs = check_positive_int(self.epochs, "epochs", minimum=0)

        self.x_mean_, self.x_scale_ = _standardise(X)
        Z = (X - self.x_mean_) / self.x_scale_
        check = ((X_check - self.x_mean_) / self.x_scale_, y_check) if has_check else None
        self._train(Z, y, check, epochs, *self._initial_premises(Z, y, check_random_state(self.random_state)))
        self.n_features_in_ = X.shape[1]
        return self

    def _train(self, Z, y, check, epochs, centers, sigmas, rule_mfs):
        """Hybrid training from the initial premises; sets the fitted premises, consequents and histories."""
        Z1 = _with_bias(Z)

        def evaluate(centers, sigmas):
            return _solve_consequents(_normalised_firing(Z, centers, sigmas, rule_mfs), Z1, y, self.ridge)

        if check is not None:
            Zc, y_check = check
            Zc1 = _with_bias(Zc)

        ls = evaluate(centers, sigmas)
        train_hist, check_hist = [np.sqrt(ls.sse / y.size)], []
        step, damping = float(self.step_size), _LM_DAMPING0
        best = None
        epoch = 0
        while True:
            score = train_hist[-1]
            if check is not None:
                wc = _normalised_firing(Zc, centers, sigmas, rule_mfs)
                check_hist.append(float(np.sqrt(np.mean((_output(wc, Zc1, ls.theta)[0] - y_check) ** 2))))
                score = check_hist[-1]
            if best is None or score <= best[0] or check is None:
                best = (score, epoch, centers, sigmas, ls.theta)
            stalled = (
                check is not None
                and self.n_iter_no_change is not None
                and epoch - best[1] >= self.n_iter_no_change
            )
            if epoch == epochs or train_hist[-1] <= self.error_goal or stalled:
                break
            moved = self._premise_step(Z, y, ls, centers, sigmas, rule_mfs, step, damping, train_hist, evaluate,
                                       first=epoch == 0)
            if moved is None:
                break
            centers, sigmas, ls, step, damping = moved
            train_hist.append(np.sqrt(ls.sse / y.size))
            epoch += 1
        _, self.best_epoch_, self.mf_centers_, self.mf_sigmas_, self.consequents_ = best
        self.rule_mfs_ = rule_mfs
        self.training_rmse_ = np.asarray(train_hist)
        self.checking_rmse_ = np.asarray(check_hist)
        self.n_iter_ = epoch

    def _premise_step(self, Z, y, ls, centers, sigmas, rule_mfs, step, damping, train_hist, evaluate, first):
        """One premise update (Jang's normalised gradient step, or Levenberg–Marquardt on the projected problem).

        Returns ``(centers, sigmas, consequent fit, step, damping)``, or None when no step improves (a zero
        gradient, or no damping gives a lower error).
        """
        J = _premise_jacobian(Z, ls.wbar, ls.f, ls.F, centers, sigmas, rule_mfs)
        if self.premise_update == "jang":
            step = _adapt_step(step, train_hist, self.step_increase, self.step_decrease)
            gradient = J.T @ (ls.F - y)
            norm = np.linalg.norm(gradient)
            if norm == 0.0:
                return None
            centers, sigmas = self._moved(centers, sigmas, -step * gradient / norm)
            return centers, sigmas, evaluate(centers, sigmas), step, damping
        H, g = _projected_normal_equations(J, ls.F - y, ls)
        # the first step is no longer than Jang's initial step κ₀ (step_size)
        moved = self._levenberg_marquardt_step(H, g, ls.sse, centers, sigmas, damping, evaluate,
                                               float(self.step_size) if first else None)
        if moved is None:
            return None
        centers, sigmas, ls, damping = moved
        return centers, sigmas, ls, step, damping

    @staticmethod
    def _moved(centers, sigmas, delta):
        """Premises shifted by ``delta`` = [Δcentres, Δσ] (flat), σ kept above the floor."""
        k = centers.size
        return (
            centers + delta[:k].reshape(centers.shape),
            np.maximum(sigmas + delta[k:].reshape(sigmas.shape), _SIGMA_FLOOR),
        )

    def _levenberg_marquardt_step(self, H, g, sse, centers, sigmas, damping, evaluate, max_step=None):
        """One accepted LM step ``(centres, σ, least squares, damping)``, or None once converged.

        ``H``, ``g`` are the Gauss–Newton matrix and gradient of the squared
        error ``sse`` (see :func:`_projected_normal_equations`). A trial step
        is kept when the actual decrease of the squared error is a fair share
        (gain ratio ρ > 1e-3) of the decrease the Gauss–Newton model predicts;
        the damping then follows Nielsen's rule, ``×max(1/3, 1 - (2ρ - 1)³)``,
        and doubles its growth factor on every rejection. Training has
        converged when the predicted decrease is below ``_LM_RTOL`` of the
        squared error: from there on, accepting or rejecting a step would be
        decided by rounding. With ``max_step``, the damping is first raised
        ×10 until the step is no longer than that (z units).
        """
        # Marquardt scaling with a floor, so MFs that barely fire still get damped
        scale = np.diag(H) + 1e-3 * max(np.trace(H) / H.shape[0], 1e-300)

        def solve(damping):
            return scipy.linalg.solve(H + damping * np.diag(scale), -g, assume_a="pos")

        while max_step is not None and np.linalg.norm(solve(damping)) > max_step:
            damping *= 10.0
        growth = 2.0
        for _ in range(_LM_MAX_REJECTIONS):
            delta = solve(damping)
            predicted = float(delta @ (damping * scale * delta - g))
            if not predicted > _LM_RTOL * sse:
                return None
            trial = self._moved(centers, sigmas, delta)
            ls = evaluate(*trial)
            gain = (sse - ls.sse) / predicted
            if gain > 1e-3:
                return trial[0], trial[1], ls, max(damping * max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3), 1e-12)
            damping *= growth
            growth *= 2.0
        return None

    # -------------------------------------------------------------- predict
    def _z(self, X):
        check_is_fitted(self, "consequents_")
        X = validate_x(X, what="ANFISRegressor")
        check_n_features(self, X)
        return (X - self.x_mean_) / self.x_scale_

    def normalised_firing_strengths(self, X: ArrayLike) -> NDArray[np.float64]:
        """w̄ (n_samples, n_rules) for ``X``; rows sum to 1 everywhere (see module doc).

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Inputs, in the units of the training inputs.

        Returns
        -------
        ndarray, shape (n_samples, n_rules)
            Normalised firing strengths (dimensionless).
        """
        return _normalised_firing(self._z(X), self.mf_centers_, self.mf_sigmas_, self.rule_mfs_)

    def predict(self, X: ArrayLike) -> NDArray[np.float64]:
        """Sugeno output ``Σ w̄_r f_r`` for each row of ``X``.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Inputs, in the units of the training inputs.

        Returns
        -------
        ndarray, shape (n_samples,)
            Prediction, in the unit of the training target.
        """
        Z = self._z(X)
        wbar = _normalised_firing(Z, self.mf_centers_, self.mf_sigmas_, self.rule_mfs_)
        return _output(wbar, _with_bias(Z), self.consequents_)[0]

    # ------------------------------------------------------------ listing
    def membership_parameters(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Gaussian MF centres and σ in input units, each (n_features, n_mfs).

        Returns
        -------
        centers : ndarray, shape (n_features, n_mfs)
            MF centres, in each input's unit.
        sigmas : ndarray, shape (n_features, n_mfs)
            MF widths σ, in each input's unit.
        """
        check_is_fitted(self, "consequents_")
        centers = self.x_mean_[:, None] + self.x_scale_[:, None] * self.mf_centers_
        return centers, self.x_scale_[:, None] * self.mf_sigmas_

    def rules_text(self, feature_names: Sequence[str] | None = None, output_name: str = "out1") -> list[str]:
        """Linguistic rules as in thesis Table 5-6, one string per rule.

        FCM rules read ``If (T05 is T05cluster1) and … then (out1 is out1cluster1)``;
        grid rules name MFs ``<input>mf<k>`` as MATLAB does.

        Parameters
        ----------
        feature_names : sequence of str, optional
            One name per input (default ``in1``, ``in2``, …).
        output_name : str, default "out1"
            Name of the output in the rules.

        Returns
        -------
        list of str
            ``"<r>. If (<input> is <input><term><k>) and … then (<output> is <output><term><r>)"``.
        """
        check_is_fitted(self, "consequents_")
        names = (
            [f"in{j + 1}" for j in range(self.n_features_in_)]
            if feature_names is None
            else [str(n) for n in feature_names]
        )
        if len(names) != self.n_features_in_:
            raise ValueError(f"expected {self.n_features_in_} feature names, got {len(names)}.")
        term = "cluster" if self.init == "fcm" else "mf"
        lines = []
        for r, mfs in enumerate(self.rule_mfs_, start=1):
            premise = " and ".join(f"({n} is {n}{term}{k + 1})" for n, k in zip(names, mfs))
            lines.append(f"{r}. If {premise} then ({output_name} is {output_name}{term}{r})")
        return lines
