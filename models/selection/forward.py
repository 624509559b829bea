"""Greedy forward sensor selection on the leave-one-block-out error of the compensation model itself.

A physics-free but model-aware method: blocks are independent records (e.g.
one per training scenario); a sensor is worth adding if the MLR fitted on the
other blocks predicts the held-out block better with it.
"""
from __future__ import annotations

import numpy as np


def greedy_loso(blocks_X, blocks_y, k_max, ridge=1e-4, exclude=(), normalise="none", criterion="max"):
    """Greedy forward selection on the leave-one-block-out error of an MLR (with intercept).

    ``blocks_X`` : list of (n_f, p) zero-referenced candidate series, one per training scenario;
    ``blocks_y`` : matching drift changes.  Each block is predicted by the model fitted on the
    others (ridge ``ridge`` × mean Gram diagonal on the slopes).  Objective over the blocks f:
    ``criterion="max"`` (default) Σ_f max|e_f| — the held-out peak residual, the quantity
    compensation is judged by — or ``"sse"`` Σ_f ‖e_f‖²; each term weighted by
    ``normalise``: ``"none"`` (µm as they are, default), ``"rows"`` (1/n_f) or ``"peak"``
    (1/max|y_f|, squared for SSE; makes small-drift records count as much as large ones —
    which over-weights the nearly drift-free ETVE and transferred worse in our tests).
    All candidates are scored at once per step from Gram matrices and Schur complements
    (the max criterion also needs one residual matrix per block), never by refitting.
    Returns the chosen columns in order, the objective after each step, and every
    candidate's objective when used alone.
    """
    F = len(blocks_X)
    if F < 2:
        raise ValueError("greedy leave-one-block-out selection needs at least two blocks (training scenarios)")
    p = blocks_X[0].shape[1]
    # Augment with the intercept column (index 0); Grams per block.
    Xa = [np.column_stack([np.ones(len(X)), X]) for X in blocks_X]
    G = [X.T @ X for X in Xa]
    b = [X.T @ y for X, y in zip(Xa, blocks_y)]
    yy = [float(y @ y) for y in blocks_y]
    if normalise == "peak":
        w = [1.0 / (len(y) * max(float(np.max(np.abs(y))), 1e-12) ** 2) for y in blocks_y]
    elif normalise == "rows":
        w = [1.0 / len(y) for y in blocks_y]
    else:
        w = [1.0 for y in blocks_y]
    G_all, b_all = sum(G), sum(b)
    diag_scale = np.mean(np.diag(G_all)[1:]) if p else 1.0
    lam = ridge * diag_scale
    selected = [0]
    blocked = np.zeros(p + 1, bool)
    blocked[0] = True
    for e in exclude:
        blocked[e + 1] = True
    history, alone = [], None
    for _step in range(k_max):
        objective = np.zeros(p + 1)
        S = np.array(selected)
        for f in range(F):
            Gt = G_all - G[f]
            bt = b_all - b[f]
            A = Gt[np.ix_(S, S)] + lam * np.diag((S != 0).astype(float))
            A_inv = np.linalg.inv(A)
            GS = Gt[S]                                      # (s, p+1)
            V = A_inv @ GS                                  # v_c columns
            d = np.diag(Gt) + lam - np.einsum("ij,ij->j", GS, V)
            beta_S0 = A_inv @ bt[S]
            beta_c = (bt - V.T @ bt[S]) / np.maximum(d, 1e-300)
            # validation block f
            Gv, bv = G[f], b[f]
            e0e0 = yy[f] - 2 * beta_S0 @ bv[S] + beta_S0 @ Gv[np.ix_(S, S)] @ beta_S0
            # e0ᵀ x_c and e0ᵀ X_S
            e0x = bv - Gv[S].T @ beta_S0                    # (p+1,)  = X_vᵀ(y − X_S β)
            e0r = e0x - V.T @ e0x[S]
            GvS = Gv[S]                                     # (s, p+1)
            rr = np.diag(Gv) - 2 * np.einsum("ij,ij->j", V, GvS) + np.einsum("ij,ij->j", V, Gv[np.ix_(S, S)] @ V)
            if criterion == "sse":
                objective += w[f] * (e0e0 - 2 * beta_c * e0r + beta_c ** 2 * rr)
            else:                                           # max |residual| over the block, exactly
                e0 = blocks_y[f] - Xa[f][:, S] @ beta_S0
                R = Xa[f] - Xa[f][:, S] @ V
                worst = np.abs(e0[:, None] - R * beta_c).max(axis=0)
                objective += worst * (np.sqrt(w[f] * len(blocks_y[f])) if normalise != "none" else 1.0)
        objective[blocked] = np.inf
        if alone is None:
            alone = objective[1:].copy()
        best = int(np.argmin(objective))
        selected.append(best)
        blocked[best] = True
        history.append(float(objective[best]))
    return np.array(selected[1:]) - 1, np.array(history), alone
