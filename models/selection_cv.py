"""Model selection by blocked cross-validation across operating regimes (arrays only).

A compensation model earns its keep on conditions it was not trained on, so
candidates are scored on whole *regime blocks* they did not see, never on
shuffled rows or on a tail of the same regime:

* **regime blocks** (:func:`regime_blocks`): a block starts where the spindle
  runs at a speed other than its last running speed, from standstill or
  while running, and holds every run and stop until the next such start;
  rows before the first run join the first block. A measured speed's noise
  and ramps are not regimes, nor is a restart at the same speed (a duty
  cycle at one speed is one regime);
* **leave one block out**: train on every other block, test on the block;
* **rolling origin**: train on blocks ``0..k-1``, test on block ``k``
  (a forecast into the next, unseen regime). For the last block this is
  the leave-one-block-out fold, and it is counted once: every fold is
  distinct, so each block weighs alike and the paired folds of the
  one-standard-error rule are not counted twice;
* **several records** (``record_starts``, e.g. test days that each start at
  rest): each record's regime blocks are its own (:func:`record_blocks`), so
  a block never spans two records, and the records keep their order;
* the score of a candidate is the **geometric mean** of its test RMSEs over
  all folds of both schemes (the mean of log RMSE; the arithmetic mean and
  the worst fold are reported too); the ranking is by that score and a
  candidate that diverges (non-finite prediction) ranks last;
* **parsimony among nested orders** (:func:`parsimonious_choice`): where the
  best-scored candidate has simpler versions of itself among the candidates
  (the same model, columns and parameters but a lower order, see
  :data:`ORDER_PARAMETERS`), the simplest one that is within one standard
  error of it is chosen: the mean over folds of the paired difference of log
  RMSE is at most its standard error (the one-standard-error rule of
  Breiman et al. 1984, on paired folds).  A higher order that wins by less
  than the folds' scatter is fitting slow modes the record cannot pin down:
  on the FE records of ``bench/selection_synthetic.py`` the simpler order
  did better on a continuation with new duty (17 of 18 changed choices) and
  worse on a later block at a speed next to those trained (27 of 30).

Why the geometric mean: the regimes differ in how large their drift is, so
an arithmetic mean of RMSEs is ruled by the regime with the largest drift
(often one fold that trains on a single speed), while the mean of logs
weighs a candidate's *relative* error on every regime alike.  Chosen on
full-FE records with a known continuation, before it was judged on others
(``bench/selection_synthetic.py``, ``docs/models.md``): on the last held-out
cases ("test 5", judged once) its median rank agreement was 0.85 with a
later block and 0.74 with the continuation, against 0.82 and 0.67 for the
arithmetic mean.

How a fold is fitted depends on the kind of model (:func:`model_kind`):

* ``"static"`` (MLR, PCR, ANN, ANFIS): fit on the training rows, predict the test rows;
* ``"series"`` (the grey GM/GMC/GNNMCI/AGO models): fit on the training rows
  joined in time order (a left-out middle block leaves a seam), then run over
  the whole history up to the end of the test block and read off the block,
  as the change since the history's first row added to the target there
  (not to the first *training* target, which is another block's start when
  the first block is left out);
* ``"weighted"`` (:class:`~models.greybox.GreyBoxRegressor`): run over the
  whole history with the test block's targets weighted 0, so the simulation
  passes through the block on its known inputs (speed, ambient) without
  seeing its drift, and read off the block. With several records, every
  record runs from its own start, and the test block's record is predicted
  from its start.

A ``"series"`` model trains on one record and cannot be scored across
several: its folds fail and it ranks last, so a caller leaves it out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
from numpy.typing import ArrayLike
from scipy.stats import spearmanr
from sklearn.base import BaseEstimator, clone

from .grey import GreySeriesRegressor
from .greybox import GreyBoxRegressor
from .metrics import rmse
from .speed import running

SCHEMES = ("leave-one-block-out", "rolling-origin")
#: The hyper-parameter that sets a model family's order, for the parsimony among nested candidates.
ORDER_PARAMETERS = {GreyBoxRegressor: "n_poles"}


#: a speed change by more than this fraction of the running speed starts another regime
SPEED_TOLERANCE = 0.05


def regime_blocks(speed: ArrayLike, min_rows: int = 2, tolerance: float = SPEED_TOLERANCE
                  ) -> list[tuple[int, int]]:
    """Row ranges ``[start, stop)`` of the operating-regime blocks of a speed record (rpm).

    A block starts where the spindle runs at a speed that differs from its
    last running speed by more than ``tolerance`` of it: a run from
    standstill at a new speed, or a speed step while running. A run that
    restarts at the last speed continues the block, and so does a speed
    still moving after a step (a ramp; the block starts at its first row).
    Speeds below :data:`~models.speed.STANDSTILL_FRACTION` of the top speed,
    or below :data:`~models.speed.STANDSTILL_RPM`, are standstill
    (:func:`models.speed.running`), so a measured speed's
    noise is no regime. The block ends where the next one starts.
    Blocks shorter than ``min_rows`` are merged into the previous one.

    Parameters
    ----------
    speed : array-like, shape (n_samples,)
        Spindle speed per row, rpm (set points or measured).
    min_rows : int, default 2
        Fewest rows of a block.
    tolerance : float, default :data:`SPEED_TOLERANCE`
        Relative speed change that starts another regime.

    Returns
    -------
    blocks : list of (int, int)
        ``[start, stop)`` row ranges, in time order, covering every row.
    """
    speed = np.asarray(speed, float)
    if speed.ndim != 1 or len(speed) < 2 or not np.all(np.isfinite(speed)):
        raise ValueError("regime_blocks: speed must be a finite 1-D series of at least 2 samples (rpm).")
    runs = running(speed)
    starts = []
    regime = None      # the settled running speed of the current block
    previous = None    # the speed of the row before, None at standstill
    departure = None   # the first row of a run start or speed step that has not settled yet
    for k, n in enumerate(speed):
        if not runs[k]:
            previous = departure = None
            continue
        if previous is None or abs(n - previous) > tolerance * abs(previous):   # starting, stepping or ramping
            departure = k if departure is None else departure
        elif departure is not None:   # settled: a new regime if the speed is not the block's
            if regime is None or abs(n - regime) > tolerance * abs(regime):
                starts.append(departure)
                regime = n
            departure = None
        previous = n
    edges = [0]
    for s in starts[1:]:   # the rows before the first run join the first block
        if s - edges[-1] >= min_rows:
            edges.append(s)
    stops = edges[1:] + [len(speed)]
    return list(zip(edges, stops))


def record_blocks(speed: ArrayLike, record_starts: Sequence[int] = (), min_rows: int = 2,
                  tolerance: float = SPEED_TOLERANCE) -> list[tuple[int, int]]:
    """The :func:`regime_blocks` of each record, in rows of the whole ``speed``.

    Parameters
    ----------
    speed : array-like, shape (n_samples,)
        Spindle speed per row of the records one after the other, rpm.
    record_starts : sequence of int, default ()
        Rows where another record begins (increasing).
    min_rows, tolerance
        As for :func:`regime_blocks`.

    Returns
    -------
    blocks : list of (int, int)
        ``[start, stop)`` row ranges, record by record, covering every row; none spans two records.
    """
    speed = np.asarray(speed, float)
    edges = [0, *(int(s) for s in record_starts), len(speed)]
    if any(b - a < 2 for a, b in pairwise(edges)):
        raise ValueError(f"record_blocks: record_starts must be increasing with at least 2 rows per record, got "
                         f"{list(record_starts)} for {len(speed)} rows.")
    return [(a + start, a + stop) for a, b in pairwise(edges)
            for start, stop in regime_blocks(speed[a:b], min_rows, tolerance)]


@dataclass(frozen=True)
class Fold:
    """One held-out block: the rows it tests and the rows that train for it."""

    scheme: str
    test_block: int
    test: tuple[int, int]      #: [start, stop) of the test rows
    train: np.ndarray = field(compare=False)  #: boolean mask of the training rows
    record_starts: tuple[int, ...] = ()       #: rows where another record begins (each starts at rest)

    @property
    def record_start(self) -> int:
        """First row of the record that holds the test block."""
        return max((s for s in self.record_starts if s <= self.test[0]), default=0)

    @property
    def name(self) -> str:
        """Scheme and 1-based test block, e.g. ``"rolling-origin block 3"``."""
        return f"{self.scheme} block {self.test_block + 1}"


def blocked_folds(blocks: Sequence[tuple[int, int]], schemes: Sequence[str] = SCHEMES,
                  record_starts: Sequence[int] = ()) -> list[Fold]:
    """Folds of leave-one-block-out and rolling origin over ``blocks`` (from :func:`regime_blocks` or
    :func:`record_blocks`).

    Parameters
    ----------
    blocks : sequence of (int, int)
        ``[start, stop)`` row ranges of the regime blocks, in time order.
    schemes : sequence of str, default :data:`SCHEMES`
        Which schemes to make folds of.
    record_starts : sequence of int, default ()
        Rows where another record begins (see :func:`record_blocks`).

    Returns
    -------
    folds : list of Fold
        Leave-one-block-out folds (one per block), then rolling-origin folds (one per block but the first
        and, with both schemes, the last: leaving out the last block trains on every block before it, so it
        is already there, named as leave-one-block-out). Every fold is distinct.
    """
    unknown = sorted(set(schemes) - set(SCHEMES))
    if unknown:
        raise ValueError(f"blocked_folds: unknown scheme {unknown[0]!r}; known: {', '.join(SCHEMES)}.")
    if len(blocks) < 2:
        raise ValueError(f"blocked cross-validation needs at least 2 operating-regime blocks, got {len(blocks)}.")
    n = blocks[-1][1]
    folds = []
    for scheme in schemes:
        tests = range(len(blocks)) if scheme == "leave-one-block-out" else range(1, len(blocks))
        for b in tests:
            train = np.zeros(n, bool)
            if scheme == "leave-one-block-out":
                train[:] = True
                train[blocks[b][0]: blocks[b][1]] = False
            else:
                train[: blocks[b][0]] = True
            # leaving out the last block is rolling origin into it: the same fold twice would weigh its block
            # double and shrink the standard error of the paired folds (one-standard-error rule) as if it were
            # new evidence
            if not any(f.test == blocks[b] and np.array_equal(f.train, train) for f in folds):
                folds.append(Fold(scheme, b, blocks[b], train, tuple(int(s) for s in record_starts)))
    return folds


def model_kind(estimator: BaseEstimator) -> str:
    """``"weighted"``, ``"series"`` or ``"static"``: how a fold fits it (see the module docstring).

    Parameters
    ----------
    estimator : BaseEstimator
        A model of :mod:`models`.

    Returns
    -------
    kind : str
        ``"weighted"``, ``"series"`` or ``"static"``.
    """
    if isinstance(estimator, GreyBoxRegressor):
        return "weighted"
    if isinstance(estimator, GreySeriesRegressor):
        return "series"
    return "static"


def fold_prediction(estimator: BaseEstimator, X: np.ndarray, y: np.ndarray, fold: Fold) -> np.ndarray:
    """Fit a clone of ``estimator`` for ``fold`` and return its prediction of the test rows.

    Parameters
    ----------
    estimator : BaseEstimator
        Unfitted model; it is cloned, never changed.
    X : ndarray, shape (n_samples, n_features)
        Time-ordered inputs (the model's own columns).
    y : ndarray, shape (n_samples,)
        Target, e.g. a drift in µm.
    fold : Fold
        The fold.

    Returns
    -------
    prediction : ndarray, shape (n_test_rows,)
        Prediction of ``y`` on the fold's test rows, in the unit of ``y``.
    """
    model = clone(estimator)
    start, stop = fold.test
    kind = model_kind(model)
    if kind == "static":
        model.fit(X[fold.train], y[fold.train])
        return model.predict(X[start:stop])
    if kind == "series":
        if fold.record_starts:
            raise ValueError(f"{type(model).__name__} trains on one record, not on several.")
        model.fit(X[fold.train], y[fold.train])
        # it predicts its first training target plus the change since row 0 of what it runs over; leaving out
        # the first block, that target is another block's start, so the run's own start level replaces it
        return model.predict(X[:stop])[start:] - model.y_reference_ + y[0]
    end = max(stop, int(np.flatnonzero(fold.train)[-1]) + 1)
    model.fit(X[:end], y[:end], sample_weight=fold.train[:end].astype(float),
              record_starts=[s for s in fold.record_starts if s < end])
    first = fold.record_start
    return model.predict(X[first:stop])[start - first:]


@dataclass
class Selection:
    """Outcome of :func:`select_by_blocked_cv`."""

    ranking: list[str]              #: candidate names, best score first
    chosen: str                     #: the choice: the best score, or a simpler order within one standard error
    score: dict[str, float]         #: geometric-mean held-out-block RMSE per candidate (inf: diverged somewhere)
    mean_rmse: dict[str, float]     #: arithmetic mean held-out-block RMSE per candidate
    worst_rmse: dict[str, float]    #: worst fold per candidate
    fold_rmse: dict[str, list[float]]  #: per fold, in the order of ``folds``
    folds: list[str]                #: fold names
    reason: str                     #: one paragraph: what was chosen and why


def held_out_rmse(estimator: BaseEstimator, X: np.ndarray, y: np.ndarray, fold: Fold) -> float:
    """RMSE of :func:`fold_prediction` on the fold's test rows; ``inf`` if the fit fails or the prediction diverges.

    Parameters
    ----------
    estimator, X, y, fold
        As for :func:`fold_prediction`.

    Returns
    -------
    rmse : float
        In the unit of ``y``; ``inf`` where the candidate cannot be scored (e.g. too few training rows for
        its parameters, or a non-finite prediction), so it cannot be chosen.
    """
    try:
        pred = np.asarray(fold_prediction(estimator, X, y, fold), float)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        return np.inf
    if not np.all(np.isfinite(pred)):
        return np.inf
    return rmse(y[fold.test[0]: fold.test[1]], pred)


def _log_rmse(fold_rmse: Sequence[float], floor: float) -> np.ndarray:
    return np.log(np.maximum(np.asarray(fold_rmse, float), floor))


def geometric_mean_rmse(fold_rmse: Sequence[float], floor: float) -> float:
    """``exp(mean(log RMSE))`` over folds; ``inf`` if any fold diverged.

    Parameters
    ----------
    fold_rmse : sequence of float
        RMSE per fold (``inf``: diverged or failed).
    floor : float
        RMSEs below it count as ``floor`` (an exact fold would otherwise score 0 whatever the other folds).

    Returns
    -------
    score : float
        The geometric mean, in the unit of the RMSEs.
    """
    if not np.all(np.isfinite(fold_rmse)):
        return np.inf
    return float(np.exp(np.mean(_log_rmse(fold_rmse, floor))))


def nested_lower_orders(candidates: Mapping[str, tuple[BaseEstimator, Sequence[int]]], name: str) -> list[str]:
    """The candidates that are ``name``'s model at a lower order, lowest order first.

    Nested means: the same class (one of :data:`ORDER_PARAMETERS`), the same columns, and every
    hyper-parameter equal but the order.

    Parameters
    ----------
    candidates : dict name → (estimator, columns)
        As for :func:`select_by_blocked_cv`.
    name : str
        The candidate whose simpler versions are wanted.

    Returns
    -------
    names : list of str
        Names of the nested candidates of lower order, by increasing order (empty if none).
    """
    estimator, columns = candidates[name]
    order = ORDER_PARAMETERS.get(type(estimator))
    if order is None:
        return []
    params = estimator.get_params()
    lower = []
    for other, (candidate, candidate_columns) in candidates.items():
        if type(candidate) is not type(estimator) or list(candidate_columns) != list(columns):
            continue
        candidate_params = candidate.get_params()
        same_otherwise = all(candidate_params[k] == v for k, v in params.items() if k != order)
        if same_otherwise and candidate_params[order] < params[order]:
            lower.append((candidate_params[order], other))
    return [other for _, other in sorted(lower)]


def within_one_standard_error(simpler_rmse: Sequence[float], best_rmse: Sequence[float], floor: float) -> bool:
    """Is a simpler candidate within one standard error of the best, on paired folds?

    With ``d`` the per-fold difference of log RMSE (simpler minus best), true when
    ``mean(d) <= std(d, ddof=1) / sqrt(n_folds)``; false if the simpler one failed on a fold.

    Parameters
    ----------
    simpler_rmse, best_rmse : sequence of float
        RMSE per fold of the two candidates, the same folds in the same order.
    floor : float
        RMSEs below it count as ``floor`` (as in :func:`geometric_mean_rmse`).

    Returns
    -------
    bool
    """
    if not np.all(np.isfinite(simpler_rmse)):
        return False
    d = _log_rmse(simpler_rmse, floor) - _log_rmse(best_rmse, floor)
    if len(d) < 2:
        return bool(d.mean() <= 0.0)
    return bool(d.mean() <= d.std(ddof=1) / np.sqrt(len(d)))


def parsimonious_choice(candidates: Mapping[str, tuple[BaseEstimator, Sequence[int]]],
                        fold_rmse: Mapping[str, Sequence[float]], best: str, floor: float) -> str:
    """The lowest order nested in ``best`` that is within one standard error of it, else ``best``.

    Parameters
    ----------
    candidates : dict name → (estimator, columns)
        As for :func:`select_by_blocked_cv`.
    fold_rmse : dict name → sequence of float
        RMSE per fold of every candidate (the same folds for all).
    best : str
        The candidate with the best score.
    floor : float
        RMSE floor (see :func:`geometric_mean_rmse`).

    Returns
    -------
    name : str
        The chosen candidate.
    """
    if not np.all(np.isfinite(fold_rmse[best])):
        return best
    for simpler in nested_lower_orders(candidates, best):
        if within_one_standard_error(fold_rmse[simpler], fold_rmse[best], floor):
            return simpler
    return best


def select_by_blocked_cv(candidates: Mapping[str, tuple[BaseEstimator, Sequence[int]]], X: ArrayLike,
                         y: ArrayLike, speed: ArrayLike, schemes: Sequence[str] = SCHEMES, unit: str = "µm",
                         min_rows: int = 2, record_starts: Sequence[int] = ()) -> Selection:
    """Rank candidate models by blocked cross-validation across the operating regimes of ``speed``.

    Parameters
    ----------
    candidates : dict name → (estimator, columns)
        Unfitted estimators and the columns of ``X`` each one takes.
    X : array-like, shape (n_samples, n_features)
        Time-ordered array holding every candidate's columns.
    y : array-like, shape (n_samples,)
        Target (e.g. a drift in µm).
    speed : array-like, shape (n_samples,)
        Spindle speed, rpm: it defines the regime blocks.
    schemes : sequence of str, default :data:`SCHEMES`
        Cross-validation schemes to score on.
    unit : str, default "µm"
        Unit of ``y`` for the reason text.
    min_rows : int, default 2
        Fewest rows of a regime block (see :func:`regime_blocks`).
    record_starts : sequence of int, default ()
        Rows where another record begins, each from rest (:func:`record_blocks`); a ``"series"`` candidate
        cannot be scored across records and ranks last.

    Returns
    -------
    selection : Selection
        Ranking, per-fold, geometric-mean and mean held-out-block RMSE (unit of ``y``) and the reason text.
    """
    X = np.asarray(X, float)
    y = np.asarray(y, float)
    if X.ndim != 2 or y.shape != (len(X),):
        raise ValueError(f"select_by_blocked_cv: X must be (n, d) and y (n,), got {X.shape} and {y.shape}.")
    if len(np.asarray(speed)) != len(X):
        raise ValueError(f"select_by_blocked_cv: speed has {len(np.asarray(speed))} rows, X has {len(X)}.")
    if not candidates:
        raise ValueError("select_by_blocked_cv: no candidate models.")
    folds = blocked_folds(record_blocks(speed, record_starts, min_rows), schemes, record_starts)
    scores = {name: [held_out_rmse(estimator, X[:, list(columns)], y, fold) for fold in folds]
              for name, (estimator, columns) in candidates.items()}
    floor = 1e-6 * max(float(np.std(y)), np.finfo(float).tiny)  # a millionth of the target's spread
    score = {k: geometric_mean_rmse(v, floor) for k, v in scores.items()}
    mean = {k: float(np.mean(v)) for k, v in scores.items()}
    worst = {k: float(np.max(v)) for k, v in scores.items()}
    ranking = sorted(scores, key=lambda k: (score[k], worst[k], k))
    chosen = parsimonious_choice(candidates, scores, ranking[0], floor)
    return Selection(ranking, chosen, score, mean, worst, scores, [f.name for f in folds],
                     _reason(ranking, chosen, score, worst, folds, schemes, unit)
                     + _margin(ranking, chosen, scores, floor))


def margin(ranking: Sequence[str], chosen: str, fold_rmse: Mapping[str, Sequence[float]], floor: float
           ) -> tuple[str, int, bool] | None:
    """How clearly ``chosen`` beats the next-best candidate (the best-scored one, if parsimony chose a lower order).

    Parameters
    ----------
    ranking : sequence of str
        Candidates, best score first.
    chosen : str
        The choice.
    fold_rmse : dict name → sequence of float
        RMSE per fold of every candidate (the same folds for all).
    floor : float
        RMSE floor (see :func:`geometric_mean_rmse`).

    Returns
    -------
    (rival, folds_ahead, indistinct) or None
        The next-best candidate that did not fail on a fold, on how many folds ``chosen`` has the
        lower RMSE, and whether the two are within one standard error of each other on paired folds
        (:func:`within_one_standard_error`: the folds cannot tell them apart). None when ``chosen``
        failed on a fold or no rival is left.
    """
    rivals = [k for k in ranking if k != chosen and np.all(np.isfinite(fold_rmse[k]))]
    if not rivals or not np.all(np.isfinite(fold_rmse[chosen])):
        return None
    rival = rivals[0]
    ahead = int(np.sum(np.asarray(fold_rmse[chosen]) < np.asarray(fold_rmse[rival])))
    return rival, ahead, within_one_standard_error(fold_rmse[rival], fold_rmse[chosen], floor)


def _margin(ranking, chosen, fold_rmse, floor) -> str:
    """The reason's last sentence: :func:`margin` in words."""
    found = margin(ranking, chosen, fold_rmse, floor)
    if found is None:
        return ""
    rival, ahead, indistinct = found
    text = f" It beats {rival} on {ahead} of {len(fold_rmse[chosen])} folds"
    if indistinct:
        return text + ", and the two are within one standard error: these folds do not tell them apart."
    return text + "."


def _rmse_text(value) -> str:
    """An RMSE for the reason: two decimals, or three significant digits below 1 (0.305, not 0.31)."""
    return f"{value:.2f}" if abs(value) >= 1 else f"{value:.3g}"


def _reason(ranking, chosen, score, worst, folds, schemes, unit) -> str:
    n_lobo = sum(f.scheme == "leave-one-block-out" for f in folds)
    n_rolling = len(folds) - n_lobo
    kinds = f"{n_lobo} leave-one-block-out" if n_lobo else f"{n_rolling} rolling-origin"
    if n_lobo and "rolling-origin" in schemes:
        kinds += (f", {n_rolling} more rolling-origin" if n_rolling else "") + \
            "; the last block's fold is rolling-origin too"
    best = ranking[0]
    over = f"over {len(folds)} folds ({kinds})"
    if chosen == best:
        text = (f"chose {best}: lowest geometric-mean RMSE on operating-regime blocks it did not see, "
                f"{_rmse_text(score[best])} {unit} {over}, worst fold {_rmse_text(worst[best])} {unit}")
        if len(ranking) > 1:
            second = ranking[1]
            text += f"; runner-up {second} {_rmse_text(score[second])} {unit}"
    else:
        text = (f"chose {chosen}: the lowest order within one standard error of {best}, whose geometric-mean "
                f"RMSE on operating-regime blocks it did not see is the lowest ({_rmse_text(score[best])} against "
                f"{_rmse_text(score[chosen])} {unit} {over}; worst fold {_rmse_text(worst[best])} against "
                f"{_rmse_text(worst[chosen])} {unit})")
    diverged = [k for k in ranking if not np.isfinite(score[k])]
    if diverged:
        text += f"; failed or diverged on some block: {', '.join(diverged)}"
    return text + "."


def rank_agreement(scores_a: dict, scores_b: dict) -> float:
    """Spearman rank correlation of two score dicts (lower = better) over their common names.

    Parameters
    ----------
    scores_a, scores_b : dict of str to float
        Candidate name → score (e.g. RMSE); ``inf`` (diverged) ranks last.

    Returns
    -------
    rho : float
        Spearman's ρ over the names both hold, in [−1, 1].
    """
    names = sorted(set(scores_a) & set(scores_b))
    if len(names) < 3:
        raise ValueError(f"rank_agreement needs at least 3 common candidates, got {len(names)}.")
    a = np.array([scores_a[k] for k in names], float)
    b = np.array([scores_b[k] for k in names], float)
    big = 1e300  # a diverged model (inf) ranks last, ties among them
    return float(spearmanr(np.nan_to_num(a, posinf=big), np.nan_to_num(b, posinf=big)).statistic)
