"""Sensor selection: hand-computed scores, closure equivalence, pipelines, scale."""

import numpy as np
import pytest
from scipy.sparse.csgraph import minimum_spanning_tree

from models.selection import (
    METHODS,
    fuzzy_equivalence_clusters,
    grey_relational_grade,
    influence_weights,
    lambda_for_n_groups,
    max_min_transitive_closure,
    maximum_spanning_tree,
    select_sensors,
    similarity_matrix,
    similitude_degree,
    target_correlation,
    thermal_error_sensitivity,
    transitive_closure,
    tree_clusters,
)

Y = np.array([1.0, 2.0, 3.0])
X = np.column_stack([[1.0, 2.0, 4.0], [2.0, 2.0, 2.0]])


def test_grey_relational_grade_by_hand_raw():
    # Δ01 = |1-1|,|2-2|,|3-4| = (0, 0, 1);  Δ02 = (1, 0, 1)
    # Δmin = 0, Δmax = 1 (max over both sensors and all k), ρ = 0.5
    # ξ = (0 + 0.5) / (Δ + 0.5):  ξ01 = (1, 1, 1/3) → γ01 = 7/9
    #                              ξ02 = (1/3, 1, 1/3) → γ02 = 5/9
    assert np.allclose(grey_relational_grade(X, Y, normalization="none"), [7 / 9, 5 / 9])


def test_grey_relational_grade_by_hand_range_normalised():
    # y → (0, .5, 1); x1 → (0, 1/3, 1); x2 is constant → (0, 0, 0)
    # Δ01 = (0, 1/6, 0); Δ02 = (0, .5, 1); Δmin = 0, Δmax = 1
    # ξ01 = (1, .5/(1/6+.5) = .75, 1) → 2.75/3;  ξ02 = (1, .5, 1/3) → 11/18
    assert np.allclose(grey_relational_grade(X, Y), [2.75 / 3, 11 / 18])


def test_similitude_degree_by_hand():
    # zero-referenced: y⁰ = (0, 1, 2), x1⁰ = (0, 1, 3), x2⁰ = (0, 0, 0)
    # s0 - s1 = (1-1) + ½(2-3) = -0.5 → ε = 1/1.5;  s0 - s2 = 1 + ½·2 = 2 → ε = 1/3
    assert np.allclose(similitude_degree(X, Y), [1 / 1.5, 1 / 3])


def test_thermal_error_sensitivity_by_hand():
    y = np.array([0.0, 1.0, 2.0, 4.0])  # ΔY = (1, 2, 4)
    x = np.column_stack([[5.0, 6.0, 7.0, 9.0], [0.0, 1.0, 1.0, 1.0]])
    # sensor 1: ΔX/ΔY = (1, 1, 1) → spread 0 → G = ∞ (a perfectly steady ratio)
    # sensor 2: ΔX/ΔY = (1, .5, .25), mean 7/12 → Σ dev² = 25/144 + 1/144 + 16/144 = 42/144
    G = thermal_error_sensitivity(x, y)
    assert np.isinf(G[0])
    assert G[1] == pytest.approx(1 / np.sqrt(42 / 144))


def test_target_correlation_and_influence():
    rng = np.random.default_rng(0)
    Xs = rng.standard_normal((100, 3)).cumsum(axis=0)
    y = Xs @ np.array([0.0, 2.0, -1.0])
    assert np.allclose(target_correlation(Xs, -Xs[:, 1]), abs(np.corrcoef(Xs.T)[1]))
    w = influence_weights(Xs, y, "gm1n", ridge=0.0)
    assert w[0] < 1e-6 and w[1] > w[2] > 0.5


def random_similarity(n, seed):
    rng = np.random.default_rng(seed)
    A = rng.uniform(0, 1, (n, n))
    R = np.round((A + A.T) / 2, 2)  # rounding makes ties, the hard case
    np.fill_diagonal(R, 1.0)
    return R


@pytest.mark.parametrize("seed", range(5))
def test_tree_closure_equals_explicit_max_min_iteration(seed):
    R = random_similarity(15, seed)
    explicit = max_min_transitive_closure(R)
    assert np.array_equal(transitive_closure(R), explicit)
    # and the λ-cut of t(R) is the tree cut: same partition for every λ
    edges, weights = maximum_spanning_tree(R)
    for lam in np.unique(R):
        labels = tree_clusters(15, edges, weights, lam)
        same = explicit >= lam
        assert np.array_equal(labels[:, None] == labels[None, :], same)


def test_prim_tree_is_maximal():
    R = random_similarity(30, 7)
    _, weights = maximum_spanning_tree(R)
    assert weights.sum() == pytest.approx(-minimum_spanning_tree(-R).sum())


def test_lambda_for_n_groups():
    rng = np.random.default_rng(1)
    Xs = rng.standard_normal((50, 12))
    for k in (1, 3, 6, 12):
        labels, lam = fuzzy_equivalence_clusters(Xs, n_groups=k)
        assert len(np.unique(labels)) == k
        assert np.array_equal(fuzzy_equivalence_clusters(Xs, lam=lam)[0], labels)
    with pytest.raises(ValueError, match="cannot make 13 groups"):
        lambda_for_n_groups(np.ones(11), 13)


def grouped_sensors(n=300, seed=0):
    """Three latent thermal modes, four noisy sensors each; y driven by modes 0 and 2."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    modes = np.column_stack([1 - np.exp(-t / 40), np.sin(t / 15), np.cos(2 * np.pi * t / n)])
    noise = np.array([0.01, 0.03, 0.06, 0.1])
    X = np.hstack([modes[:, [g]] + noise * rng.standard_normal((n, 4)) for g in range(3)])
    y = 10 * modes[:, 0] - 6 * modes[:, 2] + 0.01 * rng.standard_normal(n)
    return X, y


@pytest.mark.parametrize("method", ["maximal-tree", "gra+fcm", "gm-influence+fcm"])
def test_pipelines_pick_one_sensor_per_thermal_mode(method):
    X, y = grouped_sensors()
    sel = select_sensors(X, y, method=method, n_select=3, random_state=0)
    assert sorted(sel.indices // 4) == [0, 1, 2]
    assert np.all(np.diff(sel.scores) <= 0)


def test_sensitivity_pre_selection_drops_the_mode_that_does_not_drive_y():
    X, y = grouped_sensors()
    sel = select_sensors(X, y, method="sensitivity+fuzzy-equivalence", n_select=3)
    # the sinusoidal mode (sensors 4-7) is not proportional to y: its ΔX/ΔY ratio
    # wanders, it is in the less sensitive half and never grouped (label -1)
    assert np.all(sel.groups[4:8] == -1)
    assert set((sel.indices // 4).tolist()) == {0, 2}


def test_maximal_tree_representative_is_the_cleanest_sensor():
    X, y = grouped_sensors()
    sel = select_sensors(X, y, method="maximal-tree", n_select=3)
    # modes 0 and 2 drive y: their least noisy sensors (0 and 8) correlate best
    assert {0, 8} <= set(sel.indices.tolist())


def test_ranking_methods_and_errors():
    X, y = grouped_sensors()
    for method in ("gra", "similitude", "gm0n", "gm1n", "sensitivity", "correlation"):
        sel = select_sensors(X, y, method=method, n_select=4)
        assert len(sel.indices) == 4 and len(set(sel.indices)) == 4
    with pytest.raises(ValueError, match="unknown method"):
        select_sensors(X, y, method="magic")
    with pytest.raises(ValueError, match="larger than the 12 candidate"):
        select_sensors(X, y, n_select=13)
    with pytest.raises(ValueError, match="cluster_on"):
        select_sensors(X, y, cluster_on="space")


def many_sensors(n=2000, m=2000):
    rng = np.random.default_rng(0)
    t = np.arange(n)
    modes = np.column_stack([np.sin(t / 200 + k) + k * t / 1000 for k in range(8)])
    X = modes[:, rng.integers(0, 8, m)] + 0.05 * rng.standard_normal((n, m))
    return X, modes @ rng.standard_normal(8)


def test_tree_methods_handle_2000_sensors():
    # timing: bench/bench_models.py (tests assert results, not seconds)
    X, y = many_sensors()
    for method in ("maximal-tree", "sensitivity+fuzzy-equivalence", "gra", "similitude", "correlation"):
        chosen = select_sensors(X, y, method=method, n_select=6).indices
        assert len(set(chosen.tolist())) == 6 and chosen.max() < 2000, method
    T = transitive_closure(similarity_matrix(X))
    assert T.shape == (2000, 2000) and np.allclose(T, T.T)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["gra+fcm", "gm-influence+fcm", "gm0n", "gm1n"])
def test_fcm_and_grey_methods_handle_2000_sensors(method):
    X, y = many_sensors()
    chosen = select_sensors(X, y, method=method, n_select=6, random_state=0).indices
    assert len(set(chosen.tolist())) == 6 and chosen.max() < 2000


def test_every_method_is_listed():
    assert set(METHODS) == {
        "gra", "similitude", "gm0n", "gm1n", "sensitivity", "correlation",
        "gra+fcm", "gm-influence+fcm", "sensitivity+fuzzy-equivalence", "maximal-tree",
    }
