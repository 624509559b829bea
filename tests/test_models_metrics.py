"""Metrics against hand-computed values."""

import numpy as np
import pytest

from models.metrics import improvement_percent, max_abs_residual, nse, pearson_r, rmse

Z = np.array([1.0, 2.0, 3.0, 4.0])  # measured
P = np.array([1.0, 3.0, 3.0, 2.0])  # predicted; residuals 0, 1, 0, -2


def test_rmse_by_hand():
    # sqrt((0 + 1 + 0 + 4) / 4) = sqrt(1.25)
    assert rmse(Z, P) == pytest.approx(np.sqrt(1.25))


def test_nse_by_hand():
    # Σ(Z-P)² = 5, Σ(Z-Z̄)² = 2.25+0.25+0.25+2.25 = 5  → 1 - 5/5 = 0
    assert nse(Z, P) == pytest.approx(0.0)
    assert nse(Z, Z) == 1.0


def test_pearson_by_hand():
    # Z-Z̄ = [-1.5,-.5,.5,1.5], P-P̄ = [-1.25,.75,.75,-.25]
    # Σab = 1.875-.375+.375-.375 = 1.5; Σa²=5; Σb²=1.5625+.5625+.5625+.0625=2.75
    assert pearson_r(Z, P) == pytest.approx(1.5 / np.sqrt(5 * 2.75))


def test_max_residual_and_improvement_thesis_example():
    assert max_abs_residual(Z, P) == 2.0
    # thesis Test V: 64 µm error, ±4 µm residual → 93.75 %
    error = np.array([0.0, 32.0, 64.0])
    assert improvement_percent(error, error + np.array([0.0, -4.0, 4.0])) == pytest.approx(93.75)


def test_metric_errors():
    with pytest.raises(ValueError, match="y_pred has 3"):
        rmse(Z, P[:3])
    with pytest.raises(ValueError, match="constant"):
        nse(np.ones(3), np.arange(3.0))
    with pytest.raises(ValueError, match="zero everywhere"):
        improvement_percent(np.zeros(3), np.ones(3))
