"""Greedy forward sensor selection on the leave-one-block-out error of the compensation model itself.

A model-aware method: blocks are independent records (e.g. one per training
scenario, or one per elementary step response of a physical model); a sensor
is worth adding if the MLR fitted on the other blocks predicts the held-out
block better with it.  Several targets (drift axes) can share one sensor set.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class _Grams:
    """Per block: the intercept-augmented candidates, targets, Grams XᵀX, XᵀY and yᵀy; weights of the objective."""

    Xa: list
    Ys: list
    G: list
    b: list
    yy: list
    w: list                 #: per block, per target: the ``normalise`` weight
    tw: np.ndarray          #: per target: ``target_weights``
    normalise: str
    G_all: np.ndarray       #: Σ of the blocks' XᵀX
    b_all: np.ndarray       #: Σ of the blocks' XᵀY


def _checked_blocks(blocks_X, blocks_y, target_weights, folds):
    """``(targets (n_f, a) per block, target weights (a,), held-out fold indices)``, each checked."""
    if len(blocks_X) < 2:
        raise ValueError("greedy leave-one-block-out selection needs at least two blocks (training scenarios)")
    Ys = [np.asarray(y, float).reshape(len(y), -1) for y in blocks_y]
    n_t = Ys[0].shape[1]
    if any(Y.shape[1] != n_t for Y in Ys):
        raise ValueError("every block needs the same number of targets")
    tw = np.ones(n_t) if target_weights is None else np.asarray(target_weights, float).ravel()
    if tw.shape != (n_t,):
        raise ValueError(f"target_weights has {tw.size} values for {n_t} targets")
    folds = list(range(len(blocks_X))) if folds is None else [int(f) for f in folds]
    if not folds:
        raise ValueError("no block is held out: give at least one fold")
    return Ys, tw, folds


def _block_weights(Ys, normalise):
    """Per block, per target: 1 (``"none"``), 1/n_f (``"rows"``) or 1/(n_f max|y|²) (``"peak"``)."""
    n_t = Ys[0].shape[1]
    if normalise == "peak":
        return [1.0 / (len(Y) * np.maximum(np.abs(Y).max(axis=0), 1e-12) ** 2) for Y in Ys]
    if normalise == "rows":
        return [np.full(n_t, 1.0 / len(Y)) for Y in Ys]
    return [np.ones(n_t) for _Y in Ys]


def _add_fold_objective(objective, g, f, S, lam, criterion):
    """Add to ``objective`` (p+1,) the objective on held-out block ``f`` of adding each candidate to the columns
    ``S``, summed over the targets (in place, in the order of the targets).

    The fit on the other blocks with S plus candidate c comes from the Schur complement of the Gram on S
    (``V`` = A⁻¹ G_S, ``d`` the complement), never by refitting.
    """
    Gt = g.G_all - g.G[f]
    A_inv = np.linalg.inv(Gt[np.ix_(S, S)] + lam * np.diag((S != 0).astype(float)))
    GS = Gt[S]                                      # (s, p+1)
    V = A_inv @ GS                                  # v_c columns
    d = np.diag(Gt) + lam - np.einsum("ij,ij->j", GS, V)
    Gv = g.G[f]
    if criterion == "sse":
        GvS, Gv_SS = Gv[S], Gv[np.ix_(S, S)]
        rr = np.diag(Gv) - 2 * np.einsum("ij,ij->j", V, GvS) + np.einsum("ij,ij->j", V, Gv_SS @ V)
    else:
        XS = g.Xa[f][:, S]
        R = g.Xa[f] - XS @ V                        # residual of every candidate on X_S (block f)
    for a in range(len(g.tw)):
        bt = g.b_all[:, a] - g.b[f][:, a]
        beta_S0 = A_inv @ bt[S]
        beta_c = (bt - V.T @ bt[S]) / np.maximum(d, 1e-300)
        if criterion == "sse":
            bv = g.b[f][:, a]
            e0e0 = g.yy[f][a] - 2 * beta_S0 @ bv[S] + beta_S0 @ Gv_SS @ beta_S0
            e0x = bv - GvS.T @ beta_S0              # X_vᵀ(y − X_S β)
            e0r = e0x - V.T @ e0x[S]
            objective += g.tw[a] * g.w[f][a] * (e0e0 - 2 * beta_c * e0r + beta_c ** 2 * rr)
        else:                                       # max |residual| over the block, exactly
            e0 = g.Ys[f][:, a] - XS @ beta_S0
            worst = np.abs(e0[:, None] - R * beta_c).max(axis=0)
            scale = np.sqrt(g.w[f][a] * len(g.Ys[f])) if g.normalise != "none" else 1.0
            objective += g.tw[a] * worst * scale


def greedy_loso(blocks_X: Sequence[NDArray[np.float64]], blocks_y: Sequence[ArrayLike], k_max: int,
                ridge: float = 1e-4, normalise: Literal["none", "rows", "peak"] = "none",
                criterion: Literal["max", "sse"] = "max", target_weights: ArrayLike | None = None,
                folds: Sequence[int] | None = None
                ) -> tuple[NDArray[np.int_], NDArray[np.float64], NDArray[np.float64]]:
    """Greedy forward selection on the leave-one-block-out error of an MLR (with intercept).

    ``blocks_X`` : list of (n_f, p) zero-referenced candidate series, one per block (record);
    ``blocks_y`` : matching targets, each (n_f,) or (n_f, a) for ``a`` targets (e.g. the drift
    axes Z and Y) that share one sensor set — each target has its own MLR.  Each block is
    predicted by the model fitted on the others (ridge ``ridge`` × mean Gram diagonal on the
    slopes).  Objective over the held-out blocks f (``folds``: indices of the blocks that are
    held out in turn, default all; the others only ever train) and targets a:
    ``criterion="max"`` (default) Σ_a w_a Σ_f max|e_fa| — the held-out peak residual, the
    quantity compensation is judged by — or ``"sse"`` Σ_a w_a Σ_f ‖e_fa‖²; ``w_a`` =
    ``target_weights`` (default 1; e.g. 1 / the target's training peak to put axes of
    different size on one scale), each term also weighted by ``normalise``: ``"none"``
    (µm as they are, default), ``"rows"`` (1/n_f) or ``"peak"`` (1/max|y_fa|, squared for
    SSE; makes small-drift records count as much as large ones — which over-weights the
    nearly drift-free ETVE and transferred worse in our tests).
    All candidates are scored at once per step from Gram matrices and Schur complements
    (the max criterion also needs one residual matrix per block), never by refitting.
    Returns the chosen columns in order, the objective after each step, and every
    candidate's objective when used alone.

    Parameters
    ----------
    blocks_X : sequence of ndarray, each (n_f, p)
        Zero-referenced candidate series (e.g. °C), one per block; at least two blocks.
    blocks_y : sequence of array_like, each (n_f,) or (n_f, a)
        Matching targets (e.g. µm).
    k_max : int
        Sensors to choose.
    ridge : float, default 1e-4
        Ridge on the slopes, relative to the mean Gram diagonal.
    normalise : {"none", "rows", "peak"}, default "none"
        Weight of each block's term (above).
    criterion : {"max", "sse"}, default "max"
        Held-out peak residual or sum of squares.
    target_weights : array_like, shape (a,), optional
        Weight of each target (default 1).
    folds : sequence of int, optional
        Blocks held out in turn (default all).

    Returns
    -------
    chosen : ndarray of int, shape (k_max,)
        Candidate columns in the order chosen.
    history : ndarray, shape (k_max,)
        Objective after each step (µm with ``criterion="max"`` and ``normalise="none"``, µm² with "sse").
    alone : ndarray, shape (p,)
        Each candidate's objective as the only sensor.
    """
    Ys, tw, folds = _checked_blocks(blocks_X, blocks_y, target_weights, folds)
    p = blocks_X[0].shape[1]
    # Augment with the intercept column (index 0); Grams per block.
    Xa = [np.column_stack([np.ones(len(X)), X]) for X in blocks_X]
    G = [X.T @ X for X in Xa]
    b = [X.T @ Y for X, Y in zip(Xa, Ys)]                       # (p+1, a)
    grams = _Grams(Xa, Ys, G, b, [np.einsum("ia,ia->a", Y, Y) for Y in Ys], _block_weights(Ys, normalise), tw,
                   normalise, sum(G), sum(b))
    diag_scale = np.mean(np.diag(grams.G_all)[1:]) if p else 1.0
    lam = ridge * diag_scale
    selected = [0]
    blocked = np.zeros(p + 1, bool)
    blocked[0] = True
    history, alone = [], None
    for _step in range(k_max):
        S = np.array(selected)
        objective = np.zeros(p + 1)
        for f in folds:
            _add_fold_objective(objective, grams, f, S, lam, criterion)
        objective[blocked] = np.inf
        if alone is None:
            alone = objective[1:].copy()
        best = int(np.argmin(objective))
        selected.append(best)
        blocked[best] = True
        history.append(float(objective[best]))
    return np.array(selected[1:]) - 1, np.array(history), alone
