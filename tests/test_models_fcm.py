"""Fuzzy c-means: recovery of separated clusters, validity indices, seeding."""

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from models.fcm import FuzzyCMeans, fcm_membership, partition_coefficient, xie_beni_index

CENTRES = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])


def blobs(seed=0, n=40):
    rng = np.random.default_rng(seed)
    X = np.vstack([c + 0.5 * rng.standard_normal((n, 2)) for c in CENTRES])
    return X, np.repeat(np.arange(3), n)


def test_recovers_well_separated_clusters():
    X, truth = blobs()
    fcm = FuzzyCMeans(n_clusters=3, random_state=0).fit(X)
    # each true blob maps to exactly one cluster, and the centres sit on the blobs
    mapping = {t: np.unique(fcm.labels_[truth == t]) for t in range(3)}
    assert all(len(v) == 1 for v in mapping.values())
    assert len({int(v[0]) for v in mapping.values()}) == 3
    for t, v in mapping.items():
        assert np.linalg.norm(fcm.cluster_centers_[v[0]] - CENTRES[t]) < 0.3
    assert np.allclose(fcm.membership_.sum(axis=1), 1.0)
    assert fcm.partition_coefficient_ > 0.9


def test_validity_indices_prefer_true_number_of_clusters():
    X, _ = blobs()
    fits = {c: FuzzyCMeans(n_clusters=c, random_state=1).fit(X) for c in (2, 3, 4, 5)}
    assert min(fits, key=lambda c: fits[c].xie_beni_index_) == 3
    assert max(fits, key=lambda c: fits[c].partition_coefficient_) == 3


def test_indices_by_hand():
    # two points, two centres on them: crisp memberships
    X = np.array([[0.0], [2.0]])
    U = np.array([[1.0, 0.0], [0.0, 1.0]])
    assert partition_coefficient(U) == 1.0
    assert xie_beni_index(X, U, X) == 0.0
    # membership of the midpoint is 0.5/0.5; a point on a centre gets 1 there
    U = fcm_membership(np.array([[1.0, 1.0], [0.0, 4.0]]), 2.0)
    assert np.allclose(U, [[0.5, 0.5], [1.0, 0.0]])


def test_seeded_and_predict():
    X, _ = blobs()
    a = FuzzyCMeans(n_clusters=3, random_state=5).fit(X)
    b = FuzzyCMeans(n_clusters=3, random_state=5).fit(X)
    assert np.array_equal(a.cluster_centers_, b.cluster_centers_)
    assert np.array_equal(a.predict(X), a.labels_)


def test_errors():
    X, _ = blobs(n=2)
    with pytest.raises(ValueError, match="larger than the number of samples"):
        FuzzyCMeans(n_clusters=7).fit(X)
    with pytest.raises(ValueError, match="m must be > 1"):
        FuzzyCMeans(m=1.0).fit(X)
    with pytest.raises(NotFittedError):
        FuzzyCMeans().predict(X)
