"""The part attribution's resolution (:func:`twin.gap.attribution.region_estimate`), on a tiny fake structure.

Four parts, one node each: ``base`` carries a thermometer; ``column`` and ``head`` enter the one drift line X with
the same influence; ``cover`` is seen by nothing.  No FE: the estimate only reads these attributes.
"""
from types import SimpleNamespace

import numpy as np
import pytest

from twin.gap.attribution import RESOLVED, region_estimate

REGIONS = ["base", "column", "head", "cover"]
SIGMA = {"temperature": 0.01, "displacement": 0.1}
G = 10.0                                     # µm/K of X per kelvin of column and of head


def _case(ridge=1.0):
    names = ["T_base", "X"]
    output = np.array([[1.0, 0.0, 0.0, 0.0],   # the thermometer's row (not used by the drift influence)
                       [0.0, G, G, 0.0]])      # X: column and head alike, base and cover not at all
    structure = SimpleNamespace(region_names=REGIONS, node_region=np.array(REGIONS), output_matrix=output,
                                names=names, thermometers=[0], index={n: i for i, n in enumerate(names)},
                                kinds=["temperature", "displacement"],
                                thermometer_info=lambda: {"part": ["base"]})
    evaluator = SimpleNamespace(kinds=["temperature", "displacement"], sigma=SIGMA)
    t = np.linspace(0.0, 20.0, 400)
    c_base = 0.3 * np.sin(t)                  # K
    c_col, c_head = 0.1 * np.cos(t), 0.05 * np.sin(0.5 * t)
    R = np.column_stack([c_base, G * (c_col + c_head)])
    est = region_estimate(structure, evaluator, SimpleNamespace(R=R), names, ridge=ridge)
    prior = max(float(np.sqrt(np.mean(c_base ** 2))), 0.05)
    return est, prior


def test_a_part_with_a_thermometer_is_resolved_when_the_noise_is_small():
    est, _ = _case()
    assert est["resolution"]["base"] > 0.99
    assert "base" in est["resolved"]
    assert est["sd_K"]["base"] == pytest.approx(SIGMA["temperature"], rel=0.02)


def test_two_parts_seen_only_together_are_not_resolved_but_their_sum_is():
    est, _ = _case()
    for part in ("column", "head"):
        assert 0.4 < est["resolution"][part] <= 0.5
        assert est["resolution"][part] < RESOLVED and part not in est["resolved"]
    shares = est["shares"]["X"]
    together = shares["column"]["share"] + shares["head"]["share"]
    assert together == pytest.approx(1.0, abs=0.02)           # the pair explains the line
    assert est["unresolved_share"]["X"] == pytest.approx(together, abs=1e-12)  # cover adds 0, base is resolved


@pytest.mark.parametrize("ridge", [1.0, 4.0])
def test_a_part_seen_by_nothing_has_resolution_zero_and_the_prior_sd(ridge):
    est, prior = _case(ridge)
    assert est["resolution"]["cover"] == pytest.approx(0.0, abs=1e-12)
    assert est["sd_K"]["cover"] == pytest.approx(prior / np.sqrt(ridge), rel=1e-9)
    assert est["resolved"] == ["base"]
