"""Sensor-set selection of the placement study: seed pipelines and our own methods, per axis, K = 1 … K_max.

Selection sees the training records only (the step responses too, for
``greedy-physics``); rows are thinned evenly within each training record.

``greedy-loso``
    greedy forward selection that adds, at each step, the candidate that
    most lowers the *leave-one-scenario-out* peak error of the compensation
    model itself (MLR with intercept, light ridge): each training scenario is
    predicted by a model fitted on the others, and the objective is the sum
    over scenarios of the max |residual|.  Exact and fast through Gram
    matrices and Schur complements (no refit per candidate).
``qr-drift``
    QR with column pivoting (Q-DEIM) on the drift-relevant POD modes of the
    training snapshot matrix of candidate temperatures: the K modes that
    carry most of the drift signal (largest |uᵢᵀy|); the pivots are the
    points that best pin down those temperature-field components.
``greedy-physics``
    one sensor set for every drift axis, chosen like ``greedy-loso`` (Σ over
    axes, each weighted by 1 / its training peak) but with more blocks: the
    twin's step response to every thermal input alone (see
    :class:`~twin.placement.records.ResponseTask`).  A sensor set passes only
    if one linear model explains the drift across the training scenarios *and*
    every elementary response.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from models.selection import (
    SEED_METHODS,
    SeedSelector,
    greedy_loso,
    pod_modes,
    qr_drift,
    seed_scores,
)

from ..core.variants import zero_referenced
from .records import Record

OWN_METHODS = ("greedy-loso", "qr-drift", "greedy-physics")
METHODS = SEED_METHODS + OWN_METHODS


@dataclass
class Selection:
    """Sensor sets of every method and axis, and the per-candidate scores the methods computed.

    Attributes
    ----------
    sets : dict
        ``(method, axis)`` → list over K = 1 … K_max of candidate index lists.
    scores : dict
        Score name (``grade_Z``, ``greedy_alone_Y``, ``physics_alone``, …) → one value per candidate.
    rows : int
        Training rows the selection used.
    """

    sets: dict = field(default_factory=dict)
    scores: dict = field(default_factory=dict)
    rows: int = 0


def thin(n: int, max_rows: int) -> np.ndarray:
    """At most ``max_rows`` row indices spread evenly over ``n`` rows (all of them if ``n <= max_rows``).

    Parameters
    ----------
    n : int
        Rows available.
    max_rows : int
        Most rows kept.

    Returns
    -------
    ndarray of int
        Increasing row indices, the first and the last included.
    """
    if n <= max_rows:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_rows).round().astype(int))


def select_sets(records: list[Record], responses: list[Record], methods: list[str], axes: tuple, k_max: int,
                max_rows: int = 2000, log: Callable[[str], object] | None = print) -> Selection:
    """Choose the sensor sets of ``methods`` for every axis and K = 1 … ``k_max`` on ``records``.

    Parameters
    ----------
    records : list of Record
        The training records (temperatures °C, drift µm); each is zero-referenced to its start.
    responses : list of Record
        Step responses of every thermal input (``greedy-physics`` only; may be empty otherwise).
    methods : list of str
        Names from :data:`METHODS`.
    axes : tuple of str
        Drift axes.
    k_max : int
        Largest sensor count.
    max_rows : int
        Rows for the selection, thinned evenly within each record (at least 50 per record).
    log : callable or None
        Progress lines.

    Returns
    -------
    Selection
        The sets per method, axis and K, and the candidates' scores.
    """
    t0 = time.perf_counter()
    blocks, Xblocks = _training_blocks(records, max_rows)
    Xsel = np.vstack(Xblocks)
    out = Selection(rows=int(len(Xsel)))
    seed = SeedSelector(Xsel, random_state=0)
    pod = pod_modes(Xsel) if "qr-drift" in methods else None
    for axis in axes:
        _axis_sets(out, methods, axis, k_max, Xsel, [zero_referenced(r.drift[axis])[idx] for r, idx in blocks],
                   Xblocks, seed, pod)
        if log:
            log(f"selection for {axis} done ({time.perf_counter() - t0:.1f} s)")
    if "greedy-physics" in methods:
        _physics_sets(out, blocks, Xblocks, responses, axes, k_max)
        if log:
            log(f"greedy-physics selection done ({time.perf_counter() - t0:.1f} s)")
    return out


def _training_blocks(records, max_rows):
    """``([(record, kept rows)], [zero-referenced temperatures of the kept rows, °C])`` of the training records."""
    per = max(50, max_rows // len(records))
    blocks = [(r, thin(len(r.time_s), per)) for r in records]
    return blocks, [zero_referenced(r.temperatures)[idx] for r, idx in blocks]


def _axis_sets(out, methods, axis, k_max, Xsel, yblocks, Xblocks, seed, pod):
    """The per-axis methods' sets (all but ``greedy-physics``) for one axis, into ``out``."""
    ysel = np.concatenate(yblocks)
    scores = seed_scores(Xsel, ysel) if set(methods) & set(SEED_METHODS) else {}
    for name, v in scores.items():
        out.scores[f"{name}_{axis}"] = v
    for method in methods:
        if method in SEED_METHODS:
            out.sets[(method, axis)] = [seed.select(method, k, scores) for k in range(1, k_max + 1)]
        elif method == "greedy-loso":
            order, _hist, alone = greedy_loso(Xblocks, yblocks, k_max)
            out.sets[(method, axis)] = [order[:k] for k in range(1, k_max + 1)]
            out.scores[f"greedy_alone_{axis}"] = alone
        elif method == "qr-drift":
            picks = [qr_drift(Xsel, ysel, k, pod=pod) for k in range(1, k_max + 1)]
            out.sets[(method, axis)] = [p[0] for p in picks]
            out.scores[f"qr_weight_{axis}"] = picks[0][1]


def _physics_order(blocks, Xblocks, responses, axes, k_max):
    """``greedy-physics``'s ``(order, objective per step, each candidate alone)``: leave-one-block-out over the
    training records and the step responses, each axis weighted by 1 / its training peak drift."""
    axes = sorted(axes)        # the targets' order must not change the sums the greedy steps compare
    Ytr = [np.column_stack([zero_referenced(r.drift[a])[idx] for a in axes]) for r, idx in blocks]
    weights = 1.0 / np.maximum(np.max([np.abs(Y).max(axis=0) for Y in Ytr], axis=0), 1e-12)
    return greedy_loso(
        Xblocks + [zero_referenced(r.temperatures) for r in responses],
        Ytr + [np.column_stack([zero_referenced(r.drift[a]) for a in axes]) for r in responses], k_max,
        target_weights=weights)


def _physics_sets(out, blocks, Xblocks, responses, axes, k_max):
    """``greedy-physics``: one set for every axis (see :func:`_physics_order`), into ``out``."""
    order, _hist, alone = _physics_order(blocks, Xblocks, responses, axes, k_max)
    for axis in axes:
        out.sets[("greedy-physics", axis)] = [order[:k] for k in range(1, k_max + 1)]
    out.scores["physics_alone"] = alone


def select_one(records: list[Record], responses: list[Record], method: str, axis: str, axes: tuple, k: int,
               max_rows: int = 2000) -> list[int]:
    """The ``k`` sensors ``method`` chooses for ``axis`` on ``records``, as :func:`select_sets` would, for one K.

    Used to choose again on the same scenarios with the sensor noise drawn anew: how much a chosen set owes to
    one noise draw.

    Parameters
    ----------
    records, responses : list of Record
        Training records and step responses, as for :func:`select_sets` (°C, µm).
    method : str
        A name from :data:`METHODS`.
    axis : str
        The drift axis.
    axes : tuple of str
        Every drift axis of the study (``greedy-physics`` chooses one set for them all).
    k : int
        Sensors to choose.
    max_rows : int
        As for :func:`select_sets`.

    Returns
    -------
    list of int
        Candidate indices, in the order the method ranks them.
    """
    blocks, Xblocks = _training_blocks(records, max_rows)
    if method == "greedy-physics":
        return [int(i) for i in _physics_order(blocks, Xblocks, responses, axes, k)[0]]
    yblocks = [zero_referenced(r.drift[axis])[idx] for r, idx in blocks]
    if method == "greedy-loso":
        return [int(i) for i in greedy_loso(Xblocks, yblocks, k)[0]]
    Xsel, ysel = np.vstack(Xblocks), np.concatenate(yblocks)
    if method == "qr-drift":
        return [int(i) for i in qr_drift(Xsel, ysel, k)[0]]
    return [int(i) for i in SeedSelector(Xsel, random_state=0).select(method, k, seed_scores(Xsel, ysel))]
