"""Coverage of the grey-box model's 90 % intervals on τ and b, on a known network under several kinds of noise.

Usage::

    python bench/greybox_intervals.py                 # 100 draws per noise kind, about 2 min
    python bench/greybox_intervals.py --draws 40
    python bench/greybox_intervals.py --observer      # the observer form, about 2 min

The truth and the draws are those of ``tests/test_models_greybox_intervals.py``: the two-node network of
``tests/test_models_greybox.py`` (``solve_ivp``, time constants from its eigenvalues, P ∝ n^1.6 at 1500, 3000
and 4500 rpm, 48 h at 60 s), a 2-pole model fitted to its drift plus noise drawn anew for every fit. Each noise
kind is judged by three rules: the model's own (``time_constants_interval_``, ``exponent_interval_``: the
prewhitened sandwich of :mod:`models.robust_covariance`), Gauss–Newton's ``(JᵀJ)⁻¹σ²`` and a Bartlett
(Newey–West) sandwich with Andrews' bandwidth but no prewhitening, both with the normal quantile. Printed: the share
of fits whose interval holds τ₁, τ₂ and b (nominal 90 %) and the median half-width relative to the estimate.

``--observer`` fits the model in its observer form instead: a thermometer on node 1 (the node the spindle heats,
column 3 of the record) or on node 2 (a temperature of the same network, so a sum of the same lags as the drift,
which is what the model's observed output is) is an observed output, read with a noise of its own
(:data:`OBSERVER_NOISES`, independent of the drift's), and only the model's own rule is judged (the other two take
one output).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_models_greybox import record, simulate
from test_models_greybox_intervals import (
    STEP_S,
    ar1_noise,
    coverage_draws,
    fitted_intervals,
)

from models.greybox import GreyBoxRegressor, _log_time_constant_jacobian
from models.robust_covariance import bartlett_long_run

#: normal quantile of a two-sided 90 % interval, as the two rules without a t quantile take it
_Z90 = 1.6449


def hvac_cycle(rng, n_rows, std=1.0, period_s=1800.0, damping=0.98):
    """AR(2) noise that swings with a ``period_s`` cycle (an air conditioning that cycles), ``std`` µm."""
    angle = 2.0 * np.pi * STEP_S / period_s
    swing = lfilter([1.0], [1.0, -2.0 * damping * np.cos(angle), damping ** 2], rng.normal(size=n_rows))
    return std * swing / swing.std()


#: name → noise(rng, n_rows) in µm; the drift spans 46 µm
NOISES = {
    "AR(1) 1 µm, 30 min (the test's)": lambda rng, n: ar1_noise(rng, n, 1.0, 1800.0),
    "AR(1) 0.5 µm, 1 h": lambda rng, n: ar1_noise(rng, n, 0.5, 3600.0),
    "AR(1) 2 µm, 15 min": lambda rng, n: ar1_noise(rng, n, 2.0, 900.0),
    "AR(1) 30 min + white, 0.71 µm each": lambda rng, n: (ar1_noise(rng, n, 0.71, 1800.0)
                                                          + ar1_noise(rng, n, 0.71, 0.0)),
    "AR(1) 6 min + AR(1) 30 min, 0.71 µm each": lambda rng, n: (ar1_noise(rng, n, 0.71, 360.0)
                                                                + ar1_noise(rng, n, 0.71, 1800.0)),
    "30 min cycle, AR(2) 1 µm": hvac_cycle,
    "white 0.5 µm": lambda rng, n: ar1_noise(rng, n, 0.5, 0.0),
}

#: name → (noise on the drift in µm, noise on the thermometer in K, each (rng, n_rows) → (n_rows,); the network's
#: node the thermometer is on, 1 or 2); the node-1 thermometer's change spans 18 K
_DRIFT_AR1 = NOISES["AR(1) 1 µm, 30 min (the test's)"]


def _thermometer(sd_K, correlation_s):
    """Noise of the thermometer, K: AR(1) of ``correlation_s`` (0: white)."""
    return lambda rng, n: ar1_noise(rng, n, sd_K, correlation_s)


OBSERVER_NOISES = {
    "drift AR(1) 1 µm, 30 min; thermometer white 0.05 K": (_DRIFT_AR1, _thermometer(0.05, 0.0), 1),
    "drift AR(1) 1 µm, 30 min; thermometer white 0.1 K": (_DRIFT_AR1, _thermometer(0.1, 0.0), 1),
    "drift AR(1) 1 µm, 30 min; thermometer AR(1) 0.1 K, 30 min": (_DRIFT_AR1, _thermometer(0.1, 1800.0), 1),
    "drift AR(1) 1 µm, 30 min; thermometer white 0.3 K (coarse)": (_DRIFT_AR1, _thermometer(0.3, 0.0), 1),
    "drift white 0.5 µm; thermometer white 0.05 K": (NOISES["white 0.5 µm"], _thermometer(0.05, 0.0), 1),
    # the two rows below were added, and their settings fixed, before the per-output estimator was first run on any
    # observer row: the independent check of it
    "drift AR(1) 1 µm, 30 min; node-2 thermometer white 0.2 K": (_DRIFT_AR1, _thermometer(0.2, 0.0), 2),
    "drift AR(1) 1 µm, 30 min; thermometer AR(1) 0.3 K, 2 h": (_DRIFT_AR1, _thermometer(0.3, 7200.0), 1),
}


class _Recorded(GreyBoxRegressor):
    """The grey-box model, keeping what its intervals are made of for the rules it does not use."""

    def _intervals(self, best, segments, read, n_fitted, log_bounds):
        self.recorded = best, segments, n_fitted, log_bounds
        return super()._intervals(best, segments, read, n_fitted, log_bounds)


def other_rule(rule):
    """``intervals(model) → (estimates, (3, 2))`` of ``rule``, "gauss-newton" or "bartlett", in (log τ, b)."""
    def intervals(model):
        best, segments, n_fitted, log_bounds = model.recorded
        J, r = best.jac, best.fun
        bread = np.linalg.inv(J.T @ J)
        covariance = (bread * (r @ r) / (len(r) - n_fitted) if rule == "gauss-newton" else
                      bread @ bartlett_long_run(J * r[:, None], segments) @ bread)
        to_log = np.eye(3)
        to_log[:2, :2] = _log_time_constant_jacobian(best.x[:2], *log_bounds)
        covariance = to_log @ covariance @ to_log.T
        half = _Z90 * np.sqrt(np.diag(covariance))
        estimates = np.r_[model.time_constants_, model.exponent_]
        centre = np.r_[np.log(model.time_constants_), model.exponent_]
        ends = np.column_stack([centre - half, centre + half])
        ends[:2] = np.exp(ends[:2])
        return estimates, ends
    return intervals


def print_rows(name, results, rules):
    """One table row per rule: coverage of τ₁, τ₂, b and the median relative half-widths of τ₁ and b."""
    for rule, (covered, widths) in zip(rules, results):
        share, width = covered.mean(axis=0) * 100, np.median(widths, axis=0) * 100
        print(f"| {name} | {rule} | {share[0]:.0f} % | {share[1]:.0f} % | {share[2]:.0f} % | {width[0]:.1f} % | "
              f"{width[2]:.1f} % |")


def drift_only(X, drift, draws):
    """The three rules on a model fitted to the drift alone, one row set per kind of :data:`NOISES`."""
    rules = {"the model's (prewhitened sandwich, t)": fitted_intervals, "Gauss-Newton": other_rule("gauss-newton"),
             "Bartlett, no prewhitening": other_rule("bartlett")}
    for name, noise in NOISES.items():
        start = time.perf_counter()
        results = coverage_draws(X[:, :3], drift, noise, draws,
                                 model=_Recorded(n_poles=2, temperature_inputs=(2,)), rules=tuple(rules.values()))
        print_rows(name, results, rules)
        print(f"({name}: {time.perf_counter() - start:.0f} s)", file=sys.stderr)


def observer_form(X, drift, draws):
    """The model's rule on a model that observes a thermometer, one row per kind of :data:`OBSERVER_NOISES`."""
    model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), observed=(3,))
    for name, (noise, thermometer_noise, node) in OBSERVER_NOISES.items():
        start = time.perf_counter()
        results = coverage_draws(thermometer_on(X, node), drift, noise, draws, model=model,
                                 thermometer_noise=thermometer_noise)
        print_rows(name, results, ["the model's, observer form"])
        print(f"({name}: {time.perf_counter() - start:.0f} s)", file=sys.stderr)


def thermometer_on(X, node):
    """``X`` (time s, rpm, ambient °C, node-1 °C) with its thermometer column on ``node`` (1 or 2) of the network."""
    if node == 1:
        return X
    nodes, _ = simulate(X[:, 0], X[:, 1])
    return np.column_stack([X[:, :3], nodes[:, node - 1]])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=100, help="fits per noise kind (default 100)")
    parser.add_argument("--observer", action="store_true",
                        help="fit the observer form, a thermometer on node 1 or 2 observed (the model's rule only)")
    args = parser.parse_args()
    X, drift = record(np.arange(0.0, 48 * 3600.0, STEP_S), [1500.0, 3000.0, 4500.0])
    print(f"{args.draws} draws per noise kind; coverage of tau1, tau2, b (nominal 90 %); median half-width / estimate")
    print("| noise | rule | tau1 | tau2 | b | half-width tau1 | half-width b |\n|---|---|---|---|---|---|---|")
    (observer_form if args.observer else drift_only)(X, drift, args.draws)


if __name__ == "__main__":
    main()
