"""Timing and accuracy figures for the models package (prints; not a test).

Run from the repository root:

    python bench/bench_models.py

1. ANFIS hybrid training: 10,000 samples, 5 inputs, 3 rules (FCM init), 100 epochs.
2. GMC(1,N) PSO calibration: 90 particles × 100 epochs (2,000 samples, 5 inputs).
3. Mackey–Glass (Jang 1993): 500 train / 500 test, 4 inputs, 2 MFs per input,
   16 rules; test RMSE and NDEI (RMSE / std of the test target). Jang
   integrates with RK4 at step 0.1; the series is chaotic, so a finer step
   (0.01) gives a different trajectory and test set: both are printed.
4. Two-input sinc, 121 points, 16 rules: training RMSE of both premise rules,
   and of Levenberg–Marquardt over seeds 0–29 (on the training points and on
   a 201 × 201 grid between them).
5. Sensor selection on 2,000 candidate sensors: seconds per method.
6. Only if anfis-toolbox is importable: the same cases with anfis-toolbox
   0.2.2. It is NOT a project dependency; measure it in a throwaway venv:

       python -m venv ../anfis-venv          # beside the repository, not in it
       ../anfis-venv/bin/pip install anfis-toolbox==0.2.2 scikit-learn scipy
       ../anfis-venv/bin/python bench/bench_models.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from models import ANFISRegressor, GMCRegressor, rmse, select_sensors  # noqa: E402
from models.gmc import deaccumulated_response  # noqa: E402
from models.grey import ago  # noqa: E402


def mackey_glass_series(n_time: int = 1200, tau: float = 17.0, dt: float = 0.1, x0: float = 1.2) -> np.ndarray:
    """x(t) for t = 0, 1, …, n_time of ``dx/dt = 0.2 x(t-τ)/(1 + x(t-τ)^10) - 0.1 x(t)``.

    Jang (1993): fourth-order Runge–Kutta with step 0.1, x(0) = 1.2, τ = 17,
    x(t) = 0 for t < 0. The delayed value at the RK half-step is the mean of
    its neighbours (linear interpolation on the 0.1 grid).
    """
    lag = int(round(tau / dt))
    steps = int(round(n_time / dt))
    x = np.zeros(steps + 1)
    x[0] = x0

    def delayed(i):
        return x[i - lag] if i >= lag else 0.0

    def rate(xt, xl):
        return 0.2 * xl / (1.0 + xl**10) - 0.1 * xt

    for i in range(steps):
        d0, d1 = delayed(i), delayed(i + 1)
        dm = 0.5 * (d0 + d1)
        k1 = rate(x[i], d0)
        k2 = rate(x[i] + 0.5 * dt * k1, dm)
        k3 = rate(x[i] + 0.5 * dt * k2, dm)
        k4 = rate(x[i] + dt * k3, d1)
        x[i + 1] = x[i] + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x[:: int(round(1 / dt))]


def mackey_glass_pairs(dt: float = 0.1):
    """Jang's 1000 pairs [x(t-18), x(t-12), x(t-6), x(t)] → x(t+6), t = 118..1117 (500 train, 500 test)."""
    x = mackey_glass_series(dt=dt)
    t = np.arange(118, 1118)
    X = np.column_stack([x[t - 18], x[t - 12], x[t - 6], x[t]])
    return X[:500], x[t + 6][:500], X[500:], x[t + 6][500:]


def sinc_grid(n: int = 11):
    """Jang's 121 points on the 11×11 grid (``n`` × ``n``) over [-10, 10]² of sin(x)/x · sin(y)/y."""
    g = np.linspace(-10.0, 10.0, n)
    xx, yy = np.meshgrid(g, g)
    X = np.column_stack([xx.ravel(), yy.ravel()])
    return X, np.sinc(X[:, 0] / np.pi) * np.sinc(X[:, 1] / np.pi)


def speed_case(n_samples: int = 10_000, n_inputs: int = 5, seed: int = 0):
    """Smooth nonlinear regression data for the ANFIS timing case (10,000 × 5)."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1.0, 1.0, (n_samples, n_inputs))
    y = np.sin(2 * X[:, 0]) + X[:, 1] * X[:, 2] + 0.5 * X[:, 3] ** 2 - 0.3 * X[:, 4]
    return X, y + 0.05 * rng.standard_normal(n_samples)


def timed(fn):
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


def gmc_case(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    X = np.column_stack([np.sin(t / (40 + 15 * j)) + 0.01 * rng.standard_normal(n) for j in range(5)]).cumsum(0) / 50
    y = deaccumulated_response(ago(X - X[0]) @ np.array([0.5, -0.2, 0.3, 0.1, -0.4]) + 0.01, 0.05)
    return X, y + 0.01 * rng.standard_normal(n)


def main():
    X, y = speed_case()
    model, seconds = timed(lambda: ANFISRegressor(n_rules=3, epochs=100, random_state=0).fit(X, y))
    print(f"ANFIS hybrid, 10000 x 5, 3 rules, 100 epochs (jang rule): {seconds:.2f} s, "
          f"training RMSE {model.training_rmse_[0]:.4f} -> {model.training_rmse_[-1]:.4f}")
    model, seconds = timed(
        lambda: ANFISRegressor(n_rules=3, epochs=100, premise_update="levenberg-marquardt", random_state=0).fit(X, y)
    )
    print(f"ANFIS hybrid, 10000 x 5, 3 rules, 100 epochs (levenberg-marquardt): {seconds:.2f} s, "
          f"training RMSE {model.training_rmse_[0]:.4f} -> {model.training_rmse_[-1]:.4f}")

    X, y = gmc_case()
    model, seconds = timed(lambda: GMCRegressor(calibration="pso", random_state=0).fit(X, y))
    print(f"GMC(1,N) PSO, 2000 x 5, 90 particles x 100 epochs: {seconds:.2f} s, "
          f"training RMSE {rmse(y, model.predict(X)):.4f}")

    # the series is chaotic: the integrator step changes the trajectory, hence the test set
    for dt in (0.1, 0.01):
        Xtr, ytr, Xte, yte = mackey_glass_pairs(dt)
        for rule, epochs in (("jang", 500), ("levenberg-marquardt", 100)):
            model, seconds = timed(
                lambda: ANFISRegressor(init="grid", n_mfs=2, epochs=epochs, premise_update=rule,
                                       random_state=0).fit(Xtr, ytr)
            )
            err = rmse(yte, model.predict(Xte))
            print(f"Mackey-Glass (RK4 step {dt}), 16 rules, {rule}, {epochs} epochs: train RMSE "
                  f"{model.training_rmse_[-1]:.4f}, test RMSE {err:.4f}, NDEI {err / yte.std():.4f} ({seconds:.2f} s)")
        model = ANFISRegressor(init="grid", n_mfs=2, epochs=0, random_state=0).fit(Xtr, ytr)
        print(f"Mackey-Glass (RK4 step {dt}), least squares on the initial grid only: "
              f"test RMSE {rmse(yte, model.predict(Xte)):.4f}")

    X, y = sinc_grid()
    for rule, epochs in (("jang", 500), ("levenberg-marquardt", 100)):
        model, seconds = timed(
            lambda: ANFISRegressor(init="grid", n_mfs=4, epochs=epochs, premise_update=rule, random_state=0).fit(X, y)
        )
        print(f"sinc 121 points, 16 rules, {rule}, {epochs} epochs: training RMSE {model.training_rmse_[-1]:.2g} "
              f"({seconds:.2f} s)")
    # the seed moves the grid centres off the symmetric saddle (models.anfis): how much does it matter?
    X_between, y_between = sinc_grid(201)
    fits = [ANFISRegressor(init="grid", n_mfs=4, epochs=100, premise_update="levenberg-marquardt", random_state=seed)
            .fit(X, y) for seed in range(30)]
    train = np.array([m.training_rmse_[-1] for m in fits])
    between = np.array([rmse(y_between, m.predict(X_between)) for m in fits])
    print(f"sinc, levenberg-marquardt, seeds 0-29: training RMSE < 0.01 for {np.sum(train < 0.01)} of 30 "
          f"(median {np.median(train):.2g}, worst {train.max():.2g}); on the 201 x 201 grid between the "
          f"training points median {np.median(between):.2g}, worst {between.max():.2g}")


def selection_timings(n_samples: int = 2000, n_sensors: int = 2000):
    """Seconds of ``select_sensors`` on 2,000 sensors (8 latent modes plus noise), per method."""
    rng = np.random.default_rng(0)
    t = np.arange(n_samples)
    modes = np.column_stack([np.sin(t / 200 + k) + k * t / 1000 for k in range(8)])
    X = modes[:, rng.integers(0, 8, n_sensors)] + 0.05 * rng.standard_normal((n_samples, n_sensors))
    y = modes @ rng.standard_normal(8)
    for method in ("maximal-tree", "sensitivity+fuzzy-equivalence", "gra", "similitude", "correlation",
                   "gra+fcm", "gm-influence+fcm", "gm0n", "gm1n"):
        _, seconds = timed(lambda: select_sensors(X, y, method=method, n_select=6, random_state=0))
        print(f"select_sensors {method}, {n_samples} x {n_sensors} sensors: {seconds:.2f} s")


def toolbox(anfis_toolbox, n_mfs, epochs, learning_rate=0.01, rules=None):
    return anfis_toolbox.ANFISRegressor(
        n_mfs=n_mfs, mf_type="gaussian", init="grid", optimizer="hybrid",
        learning_rate=learning_rate, epochs=epochs, rules=rules, random_state=0,
    )


def compare_with_anfis_toolbox(anfis_toolbox):
    """The speed, Mackey–Glass and sinc cases run by anfis-toolbox 0.2.2 (ours: see main)."""
    X, y = speed_case()
    three_rules = [[k] * 5 for k in range(3)]
    model, seconds = timed(lambda: toolbox(anfis_toolbox, 3, 100, rules=three_rules).fit(X, y))
    print(f"anfis-toolbox speed case 10000 x 5, 3 rules, 100 epochs: {seconds:.2f} s, "
          f"training RMSE {rmse(y, model.predict(X)):.4f}")

    Xtr, ytr, Xte, yte = mackey_glass_pairs()
    for lr in (0.01, 0.1):
        model, seconds = timed(lambda: toolbox(anfis_toolbox, 2, 500, learning_rate=lr).fit(Xtr, ytr))
        print(f"anfis-toolbox Mackey-Glass, lr={lr}, 500 epochs: test RMSE {rmse(yte, model.predict(Xte)):.4f} "
              f"({seconds:.1f} s)")

    X, y = sinc_grid()
    model, seconds = timed(lambda: toolbox(anfis_toolbox, 4, 500, learning_rate=0.1).fit(X, y))
    print(f"anfis-toolbox sinc, lr=0.1, 500 epochs: training RMSE {rmse(y, model.predict(X)):.4f} ({seconds:.1f} s)")
    ours = ANFISRegressor(init="grid", n_mfs=4, epochs=100, premise_update="levenberg-marquardt", random_state=0)
    ours.fit(X, y)
    far = np.array([[60.0, -60.0]])
    print(f"sinc model at (60, -60), far outside [-10, 10]^2: anfis-toolbox {model.predict(far)[0]:.3g}, "
          f"ours {ours.predict(far)[0]:.3g} (nearest rule's linear consequent)")


if __name__ == "__main__":
    main()
    selection_timings()
    try:
        import anfis_toolbox
    except ImportError:
        print("(anfis-toolbox not installed: comparison skipped, see the module docstring)")
    else:
        compare_with_anfis_toolbox(anfis_toolbox)
