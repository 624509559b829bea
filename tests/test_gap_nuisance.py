"""The initial-state nuisance of the gap diagnosis is fitted on the surface thermometers when they determine it.

The truths are written here, not simulated: free responses of two initial-state shapes with other time
constants at each channel, a known coefficient, and a fault at one channel that no nuisance explains.
"""
import numpy as np
import pytest

from twin.gap.fit import Evaluator
from twin.gap.model import Prediction

HOURS = np.linspace(0.0, 24.0, 289)
UNIFORM = np.exp(-HOURS / 6.0)                     # free response of a uniform initial offset, per K
RESIDUAL_HEAT = np.exp(-HOURS / 2.0)               # of heat left by earlier running, per unit
TRUE = {"initial_uniform": 1.5, "initial_residual_heat": -0.8}


def _residual(kinds, gains, fault=None, nan_thermometers=False):
    """Residual of a nominal twin (zero) against a record whose channels are the true nuisance responses
    (``gains`` (uniform, residual heat) per channel) plus ``fault`` (n_times, n_channels)."""
    N = {"initial_uniform": np.outer(UNIFORM, [g[0] for g in gains]),
         "initial_residual_heat": np.outer(RESIDUAL_HEAT, [g[1] for g in gains])}
    Y = sum(TRUE[n] * N[n] for n in N) + np.where(np.array(kinds) == "air", 20.0, 0.0)
    if fault is not None:
        Y = Y + fault
    if nan_thermometers:
        Y[:200, np.array(kinds) == "temperature"] = np.nan
    fit = HOURS < 16.0
    ev = Evaluator(Y, range(len(kinds)), kinds, fit, ~fit)
    ev.set_weights()
    zero = np.zeros_like(Y)
    return ev.residual(Prediction(zero, N, zero, None, None))


THERMOMETERS = [(1.0, 0.2), (0.9, 1.0), (1.1, 0.5)]
PROBES = [(4.0, 2.5), (-3.0, 1.0)]                  # µm per K of each shape


def test_a_faulty_probe_does_not_move_the_thermometers():
    """A Z probe reading 25 % high: its error stays on the probe, the nuisance is the true one."""
    kinds = ["temperature"] * 3 + ["displacement"] * 2
    gains = THERMOMETERS + PROBES
    truth = np.outer(TRUE["initial_uniform"] * UNIFORM, [g[0] for g in gains]) + \
        np.outer(TRUE["initial_residual_heat"] * RESIDUAL_HEAT, [g[1] for g in gains])
    fault = np.zeros_like(truth)
    fault[:, 3] = 0.25 * (truth[:, 3] + 30.0 * HOURS / 24.0)        # the gain acts on a drift that grows
    res = _residual(kinds, gains, fault)
    assert res.nuisance == pytest.approx(TRUE, abs=1e-9)
    assert np.nanmax(np.abs(res.R[:, :3])) < 1e-9                   # K: the thermometers are left alone
    assert np.nanmax(np.abs(res.R[:, 3])) > 1.0                     # µm: the fault stays where it is


@pytest.mark.parametrize("kinds, gains, nan_thermometers", [
    (["air", "displacement", "displacement"], [(0.0, 0.0)] + PROBES, False),          # air only: no response
    (["temperature", "displacement", "displacement"], THERMOMETERS[:1] + PROBES, True),  # none valid on fit rows
    (["temperature", "displacement", "displacement"], [(1.0, 0.0)] + PROBES, False),  # one shape unseen there
], ids=["air-sensors-only", "thermometers-nan-on-fit-rows", "a-shape-the-thermometers-do-not-see"])
def test_without_thermometers_that_determine_it_every_channel_fits_the_nuisance(kinds, gains, nan_thermometers):
    res = _residual(kinds, gains, nan_thermometers=nan_thermometers)
    assert res.nuisance == pytest.approx(TRUE, abs=1e-9)
    assert np.nanmax(np.abs(res.R[:, 1:])) < 1e-8                   # µm: the probes are explained
