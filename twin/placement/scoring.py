"""Scoring of the placement study's sensor sets: a compensation model per set, judged on records it did not see.

For each method, axis and K an MLR model (zero-referenced inputs and target,
with intercept) is fitted on all training rows of the chosen sensors and
scored on the *validation* scenarios: max |residual| and RMSE pooled over
them (µm), against the uncompensated drift change.  The best method and K per
axis are chosen on those validation scores (:func:`choose_best`); only the
chosen sets are then scored on the *test* scenarios (:func:`score_choices`),
which no choice has seen.  ANFIS-FCM is fitted on the chosen sets as a check.
"""
from __future__ import annotations

import numpy as np

from ..compensation.store import make_estimator
from ..core.variants import zero_referenced
from .candidates import Candidates
from .records import Record
from .selection import METHODS

#: The sensor counts among which each axis's best set is reported: the thesis goal of 4–5 sensors.
REPORT_K = (4, 5)


def stack(records: list[Record], cols: np.ndarray, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """Zero-referenced inputs (°C, columns ``cols``) and drift (µm) of ``records``, stacked row-wise.

    Parameters
    ----------
    records : list of Record
        The records.
    cols : ndarray of int
        Candidate columns.
    axis : str
        Drift axis.

    Returns
    -------
    X : ndarray, shape (n_rows, len(cols))
        Temperature changes, K.
    y : ndarray, shape (n_rows,)
        Drift changes, µm.
    """
    X = np.vstack([zero_referenced(r.temperatures[:, cols]) for r in records])
    y = np.concatenate([zero_referenced(r.drift[axis]) for r in records])
    return X, y


def score_set(train: list[Record], test: list[Record], cols: np.ndarray, axis: str,
              model: str = "mlr") -> tuple[float, float, dict]:
    """Fit ``model`` on ``train`` with the sensors ``cols``; score it on ``test``.

    Parameters
    ----------
    train, test : list of Record
        Records to fit on and to score on.
    cols : ndarray of int
        Candidate columns (the sensor set).
    axis : str
        Drift axis.
    model : str, default "mlr"
        Model name (see :mod:`models.registry`).

    Returns
    -------
    max_residual : float
        Max |residual| pooled over ``test``, µm.
    rmse : float
        RMSE pooled over ``test``, µm.
    per_scenario : dict
        Scenario → ``max_residual``, ``uncompensated_max`` (max |drift change|), ``rmse`` (µm) and ``rows``.
    """
    X, y = stack(train, cols, axis)
    est = make_estimator(model).fit(X, y)
    res, per = [], {}
    for r in test:
        Xt = zero_referenced(r.temperatures[:, cols])
        yt = zero_referenced(r.drift[axis])
        e = est.predict(Xt) - yt
        res.append(e)
        per[r.scenario] = {"max_residual": float(np.abs(e).max()), "uncompensated_max": float(np.abs(yt).max()),
                           "rmse": float(np.sqrt(np.mean(e ** 2))), "rows": len(e)}
    e = np.concatenate(res)
    return float(np.abs(e).max()), float(np.sqrt(np.mean(e ** 2))), per


def uncompensated(records: list[Record], axis: str) -> tuple[float, float]:
    """Max |drift change| and its RMS pooled over ``records``, µm: the error without compensation.

    Parameters
    ----------
    records : list of Record
    axis : str
        Drift axis.

    Returns
    -------
    max : float
        µm.
    rms : float
        µm.
    """
    y = np.concatenate([zero_referenced(r.drift[axis]) for r in records])
    return float(np.abs(y).max()), float(np.sqrt(np.mean(y ** 2)))


def score_table(sets: dict, train: list[Record], test: list[Record], candidates: Candidates, methods: list[str],
                axes: tuple) -> tuple[list[dict], dict]:
    """One row per method, K and axis: the MLR on that set scored on ``test`` (µm), and the uncompensated
    (max, RMS) per axis.  ``sets``: ``(method, axis)`` → sets per K (see :class:`~twin.placement.selection.Selection`).

    Parameters
    ----------
    sets : dict
        ``(method, axis)`` → candidate index lists per K.
    train, test : list of Record
        Records to fit on and to score on.
    candidates : Candidates
        Names the sensors.
    methods : list of str
        Methods scored.
    axes : tuple of str
        Drift axes.

    Returns
    -------
    table : list of dict
        ``method``, ``K``, ``axis``, ``max_residual``, ``rmse`` (µm), ``reduction_percent``, ``sensors``,
        ``per_scenario``.
    uncompensated : dict
        Axis → (max, RMS) drift change of ``test``, µm.
    """
    table, uncomp = [], {}
    for axis in axes:
        uncomp[axis] = uncompensated(test, axis)
        for method in methods:
            for k, cols in enumerate(sets[(method, axis)], start=1):
                mx, rm, per_sc = score_set(train, test, np.asarray(cols), axis)
                table.append({"method": method, "K": k, "axis": axis, "max_residual": mx, "rmse": rm,
                              "reduction_percent": 100 * (1 - mx / uncomp[axis][0]),
                              "sensors": [candidates.names[c] for c in cols], "per_scenario": per_sc})
    return table, uncomp


def best_k_pool(k_max: int) -> list[int]:
    """The K among which each axis's best set is chosen: those of :data:`REPORT_K` studied, else every K studied.

    Parameters
    ----------
    k_max : int
        Largest K studied.

    Returns
    -------
    list of int
    """
    return [k for k in REPORT_K if k <= k_max] or list(range(1, k_max + 1))


def choose_best(table: list[dict], candidates: Candidates, axes: tuple, k_max: int,
                methods: tuple | None = None) -> dict:
    """Axis → (method, K, candidate indices) of the smallest max |residual| in ``table`` (the validation
    scores) among the K of :func:`best_k_pool` and, if given, among ``methods``.  A tie goes to the smaller K,
    then to the method first in :data:`~twin.placement.selection.METHODS` — never to the order methods were
    given in.

    Parameters
    ----------
    table : list of dict
        Rows of :func:`score_table`.
    candidates : Candidates
        To turn sensor names back into indices.
    axes : tuple of str
        Drift axes.
    k_max : int
        Largest K studied.
    methods : tuple of str, optional
        Restrict the choice to these methods.

    Returns
    -------
    dict
        Axis → (method, K, candidate indices).
    """
    best = {}
    for axis in axes:
        rows = [r for r in table if r["axis"] == axis and r["K"] in best_k_pool(k_max)
                and (methods is None or r["method"] in methods)]
        b = min(rows, key=lambda r: (r["max_residual"], r["K"], METHODS.index(r["method"])))
        best[axis] = (b["method"], b["K"], [candidates.names.index(n) for n in b["sensors"]])
    return best


def score_choices(choices: dict, train: list[Record], test: list[Record], candidates: Candidates) -> dict:
    """Axis → the MLR on the chosen set of that axis scored on ``test`` (µm), as a row of the score table.

    ``choices``: axis → (method, K, candidate indices), as :func:`choose_best` returns.

    Parameters
    ----------
    choices : dict
        Axis → (method, K, candidate indices).
    train, test : list of Record
        Records to fit on and to score on.
    candidates : Candidates
        Names the sensors.

    Returns
    -------
    dict
        Axis → a row like those of :func:`score_table`.
    """
    out = {}
    for axis, (method, k, idx) in choices.items():
        mx, rm, per_sc = score_set(train, test, np.asarray(idx), axis)
        out[axis] = {"method": method, "K": k, "axis": axis, "max_residual": mx, "rmse": rm,
                     "reduction_percent": 100 * (1 - mx / uncompensated(test, axis)[0]),
                     "sensors": [candidates.names[c] for c in idx], "per_scenario": per_sc}
    return out


def anfis_scores(best: dict, sets: dict, train: list[Record], test: list[Record], uncomp: dict,
                k_max: int) -> list[dict]:
    """ANFIS-FCM (3 rules) on the best method's sets with 4 and 5 sensors, scored like the MLR on ``test`` (µm);
    ``uncomp``: axis → (max, RMS) drift change of ``test``.

    Parameters
    ----------
    best : dict
        Axis → (method, K, candidate indices).
    sets : dict
        ``(method, axis)`` → candidate index lists per K.
    train, test : list of Record
        Records to fit on and to score on.
    uncomp : dict
        Axis → (max, RMS) drift change of ``test``, µm.
    k_max : int
        Largest K studied (K = 4, 5 beyond it are skipped).

    Returns
    -------
    list of dict
        One row per axis and K: ``max_residual``, ``rmse`` (µm), ``reduction_percent``; or ``error`` if the fit
        failed.
    """
    rows = []
    for axis, (method, _k, _idx) in best.items():
        for k in (4, 5):
            if k > k_max:
                continue
            cols = np.asarray(sets[(method, axis)][k - 1])
            try:
                mx, rm, _per = score_set(train, test, cols, axis, model="anfis")
            except (ValueError, np.linalg.LinAlgError) as exc:  # pragma: no cover - reported, not fatal
                rows.append({"axis": axis, "method": method, "K": k, "error": str(exc)})
                continue
            rows.append({"axis": axis, "method": method, "K": k, "model": "anfis-fcm", "max_residual": mx,
                         "rmse": rm, "reduction_percent": 100 * (1 - mx / uncomp[axis][0])})
    return rows
