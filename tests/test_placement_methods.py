"""Selection methods of the placement study on small synthetic data (no FE): exactness and equivalences."""
import numpy as np
import pytest

from models import select_sensors
from models.selection import (
    SEED_METHODS,
    SeedSelector,
    greedy_loso,
    qr_drift,
    seed_scores,
)
from twin.placement.candidates import farthest_point_sample


def _blocks(seed=0, n_blocks=4, p=30, n=60):
    rng = np.random.default_rng(seed)
    Xs, ys = [], []
    for f in range(n_blocks):
        t = np.arange(n)
        modes = np.column_stack([1 - np.exp(-t / (10 + 5 * f)), np.sin(t / (6 + f)), t / n * (f % 2)])
        mix = rng.standard_normal((3, p))
        X = modes @ mix + 0.05 * rng.standard_normal((n, p))
        X -= X[0]
        y = 3 * modes[:, 0] - 2 * modes[:, 1] + 0.5 * modes[:, 2]
        Xs.append(X)
        ys.append(y - y[0])
    return Xs, ys


def _brute_objective(Xs, ys, cols, ridge_abs, criterion="sse"):
    """Leave-one-block-out normalised SSE by explicit refits (ridge on the non-intercept terms)."""
    total = 0.0
    for f in range(len(Xs)):
        Xt = np.vstack([np.column_stack([np.ones(len(X)), X[:, cols]]) for g, X in enumerate(Xs) if g != f])
        yt = np.concatenate([y for g, y in enumerate(ys) if g != f])
        R = ridge_abs * np.diag([0.0] + [1.0] * len(cols))
        beta = np.linalg.solve(Xt.T @ Xt + R, Xt.T @ yt)
        e = np.column_stack([np.ones(len(Xs[f])), Xs[f][:, cols]]) @ beta - ys[f]
        total += e @ e / (len(ys[f]) * np.max(np.abs(ys[f])) ** 2) if criterion == "sse" else np.abs(e).max()
    return total


@pytest.mark.parametrize("criterion", ["sse", "max"])
def test_greedy_loso_matches_explicit_refits(criterion):
    Xs, ys = _blocks()
    kw = dict(normalise="peak", criterion="sse") if criterion == "sse" else dict(normalise="none", criterion="max")
    order, history, alone = greedy_loso(Xs, ys, 4, ridge=1e-6, **kw)
    G = sum(np.column_stack([np.ones(len(X)), X]).T @ np.column_stack([np.ones(len(X)), X]) for X in Xs)
    lam = 1e-6 * np.mean(np.diag(G)[1:])
    # every step's objective equals the brute-force one, and the step is the brute-force argmin
    for k in range(1, 5):
        assert history[k - 1] == pytest.approx(_brute_objective(Xs, ys, list(order[:k]), lam, criterion),
                                               rel=1e-7)
        brute = [_brute_objective(Xs, ys, list(order[:k - 1]) + [c], lam, criterion) if c not in order[:k - 1] else np.inf
                 for c in range(Xs[0].shape[1])]
        assert int(np.argmin(brute)) == order[k - 1]
    assert alone[order[0]] == pytest.approx(history[0])
    assert history[2] < history[1] < history[0]         # the first sensors lower the held-out error
    with pytest.raises(ValueError, match="at least two blocks"):
        greedy_loso(Xs[:1], ys[:1], 2)


@pytest.mark.parametrize("method", SEED_METHODS)
def test_seed_selector_equals_select_sensors(method):
    Xs, ys = _blocks(1, p=24)
    X, y = np.vstack(Xs), np.concatenate(ys)
    sel = SeedSelector(X, random_state=0)
    scores = seed_scores(X, y)
    for k in (1, 3, 5):
        ours = sel.select(method, k, scores)
        ref = select_sensors(X, y, method=method, n_select=k, random_state=0)
        assert list(ours) == list(ref.indices)


def test_qr_drift_picks_one_sensor_per_mode():
    rng = np.random.default_rng(3)
    t = np.arange(300)
    modes = np.column_stack([1 - np.exp(-t / 60), np.sin(t / 25), np.cos(t / 70)])
    X = np.repeat(modes, 5, axis=1) * np.tile([1.0, 0.9, 0.8, 0.7, 0.6], 3) + 1e-3 * rng.standard_normal((300, 15))
    y = 10 * modes[:, 0] - 4 * modes[:, 1] + 2 * modes[:, 2]
    order, score = qr_drift(X, y, 3)
    assert sorted(order // 5) == [0, 1, 2]                  # three modes, three sensors: one per mode
    assert score.shape == (15,)
    more, _ = qr_drift(X, y, 5)                              # more sensors than modes: filled, no repeats
    assert len(set(more.tolist())) == 5


def test_farthest_point_sampling_spreads_points():
    rng = np.random.default_rng(0)
    cloud = np.vstack([rng.uniform(0, 0.1, (500, 3)), rng.uniform(0.9, 1.0, (20, 3))])
    pick = farthest_point_sample(cloud, 10)
    assert len(set(pick.tolist())) == 10
    assert np.sum(pick >= 500) >= 3                          # the small far cluster is not ignored
    assert np.array_equal(pick, farthest_point_sample(cloud, 10))
    assert len(farthest_point_sample(cloud[:5], 10)) == 5


def _brute_multi(Xs, Ys, cols, ridge_abs, weights, folds):
    """Σ_targets w_a Σ_{f in folds} max|e_fa| by explicit refits on the other blocks (all blocks train)."""
    total = 0.0
    for f in folds:
        Xt = np.vstack([np.column_stack([np.ones(len(X)), X[:, cols]]) for g, X in enumerate(Xs) if g != f])
        R = ridge_abs * np.diag([0.0] + [1.0] * len(cols))
        Xv = np.column_stack([np.ones(len(Xs[f])), Xs[f][:, cols]])
        for a, w in enumerate(weights):
            yt = np.concatenate([Y[:, a] for g, Y in enumerate(Ys) if g != f])
            beta = np.linalg.solve(Xt.T @ Xt + R, Xt.T @ yt)
            total += w * np.abs(Xv @ beta - Ys[f][:, a]).max()
    return total


def test_greedy_loso_several_targets_share_one_set_and_folds_limit_the_held_out_blocks():
    Xs, ys = _blocks(2, n_blocks=5, p=20)
    Ys = [np.column_stack([y, 0.3 * y + 0.5 * X[:, 3]]) for X, y in zip(Xs, ys)]
    weights, folds = [1.0, 2.0], [0, 2, 3]
    order, history, _alone = greedy_loso(Xs, Ys, 3, ridge=1e-6, target_weights=weights, folds=folds)
    G = sum(np.column_stack([np.ones(len(X)), X]).T @ np.column_stack([np.ones(len(X)), X]) for X in Xs)
    lam = 1e-6 * np.mean(np.diag(G)[1:])
    for k in range(1, 4):
        assert history[k - 1] == pytest.approx(_brute_multi(Xs, Ys, list(order[:k]), lam, weights, folds), rel=1e-7)
        brute = [_brute_multi(Xs, Ys, list(order[:k - 1]) + [c], lam, weights, folds) if c not in order[:k - 1]
                 else np.inf for c in range(20)]
        assert int(np.argmin(brute)) == order[k - 1]
    # one target in a 2-D array is the 1-D call
    one = greedy_loso(Xs, [Y[:, :1] for Y in Ys], 3)
    ref = greedy_loso(Xs, [Y[:, 0] for Y in Ys], 3)
    assert list(one[0]) == list(ref[0]) and np.allclose(one[1], ref[1])
    with pytest.raises(ValueError, match="target_weights"):
        greedy_loso(Xs, Ys, 2, target_weights=[1.0])


def test_step_response_blocks_reveal_the_sensor_that_also_follows_the_ambient():
    """Two sensors look alike on spindle-only training records; only one also follows the ambient as the drift
    does.  Without the twin's ambient step response the greedy choice takes the cleaner look-alike, with it the
    physically right one (what ``greedy-physics`` adds to ``greedy-loso``)."""
    rng = np.random.default_rng(5)
    t = np.arange(120.0)
    blocks_X, blocks_y = [], []
    for tau in (15.0, 30.0, 50.0):                          # spindle-only training records
        s = 5 * (1 - np.exp(-t / tau))
        X = np.column_stack([s + 0.02 * rng.standard_normal(len(t)), s, rng.standard_normal(len(t))])
        blocks_X.append(X - X[0])
        blocks_y.append(2 * s)
    plain, _, _ = greedy_loso(blocks_X, blocks_y, 1)
    assert plain[0] == 1                                    # the noise-free look-alike wins on training data
    amb = 2 * (1 - np.exp(-t / 40))                         # ambient step: sensor 0 follows it, sensor 1 does not
    step_X = np.column_stack([amb, 0.1 * amb, np.zeros(len(t))])
    physics, _, _ = greedy_loso(blocks_X + [step_X], blocks_y + [2 * amb], 1)
    assert physics[0] == 0
