"""Grey-box RC-network model: recovery of a known network, stability, observer, determinism, bad input.

Truths come from an independent route: a two-node thermal RC network written
in physical form (capacities, conductances) and integrated with
``scipy.integrate.solve_ivp`` (RK45, tight tolerances), piece by piece between
speed changes; the model under test is a modal form fitted by output error.
"""

import itertools
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from sklearn.exceptions import NotFittedError

from models.greybox import GreyBoxRegressor
from models.registry import estimator_classes

# two-node network: spindle node (C1) and structure node (C2), both losing heat to the ambient
C1, C2 = 4.0e5, 2.0e6          # J/K
G12, G1A, G2A = 60.0, 25.0, 40.0  # W/K
HEAT_AT_1000 = 120.0           # W at 1000 rpm
EXPONENT = 1.6                 # P ∝ n^1.6
DRIFT_PER_K = (3.0, -1.5)      # µm/K of the node temperatures above the ambient start
AMBIENT_GAIN = 0.8             # µm/K of the ambient itself (the measuring loop)


def true_time_constants():
    """Time constants of the network, s, from the eigenvalues of its conductance/capacity matrix."""
    A = np.array([[-(G12 + G1A) / C1, G12 / C1], [G12 / C2, -(G12 + G2A) / C2]])
    return np.sort(-1.0 / np.linalg.eigvals(A).real)


def ambient(t):
    return 20.0 + 1.5 * np.sin(2 * np.pi * t / 86400.0) + 0.4 * np.sin(2 * np.pi * t / 5400.0)


def simulate(times, speed, extra_heat=0.0):
    """Node temperatures and drift at ``times`` for a speed held between samples (solve_ivp per step run).

    ``extra_heat`` (W) is an unmodelled heat on node 1 from the middle of the record on.
    """
    def rhs(t, T, n):
        Ta = ambient(t)
        P = HEAT_AT_1000 * (n / 1000.0) ** EXPONENT + (extra_heat if t >= times[len(times) // 2] else 0.0)
        return [(P - G12 * (T[0] - T[1]) - G1A * (T[0] - Ta)) / C1,
                (G12 * (T[0] - T[1]) - G2A * (T[1] - Ta)) / C2]

    # piecewise integration: one solve per run of constant speed (and the extra heat switch)
    breaks = np.flatnonzero(np.diff(speed) != 0) + 1
    if extra_heat:
        breaks = np.union1d(breaks, [len(times) // 2])
    edges = np.unique(np.r_[0, breaks, len(times) - 1])
    Ta0 = ambient(times[0])
    state = np.array([Ta0, Ta0])  # equilibrium at rest
    out = np.empty((len(times), 2))
    out[0] = state
    for a, b in itertools.pairwise(edges):
        sol = solve_ivp(rhs, (times[a], times[b]), state, args=(speed[a],), t_eval=times[a: b + 1],
                        rtol=1e-10, atol=1e-10, method="RK45", max_step=600.0)
        out[a: b + 1] = sol.y.T
        state = sol.y[:, -1]
    drift = DRIFT_PER_K[0] * (out[:, 0] - Ta0) + DRIFT_PER_K[1] * (out[:, 1] - Ta0) + AMBIENT_GAIN * (ambient(times) - Ta0)
    return out, drift


def duty(times, levels, period):
    """A stop of ``period`` s, then each level for ``period`` s followed by a stop (starts at rest)."""
    slot = (times // period).astype(int)
    return np.where(slot % 2 == 1, np.asarray(levels)[(slot // 2) % len(levels)], 0.0)


def record(times, levels, period=4 * 3600.0, extra_heat=0.0):
    speed = duty(times, levels, period)
    nodes, drift = simulate(times, speed, extra_heat)
    X = np.column_stack([times, speed, ambient(times), nodes[:, 0]])  # columns: time, rpm, ambient, node-1 thermometer
    return X, drift


@pytest.fixture(scope="module")
def training():
    times = np.arange(0.0, 48 * 3600.0, 60.0)
    return record(times, [1500.0, 3000.0, 4500.0])


def test_recovers_a_known_network_and_extrapolates_to_an_unseen_speed(training):
    X, y = training
    model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(X, y)
    np.testing.assert_allclose(model.time_constants_, true_time_constants(), rtol=0.02)
    assert model.exponent_ == pytest.approx(EXPONENT, rel=0.02)
    assert np.all(model.poles_ < 0)
    # an unseen, higher speed and another duty rhythm
    times = np.arange(0.0, 24 * 3600.0, 60.0)
    X_new, y_new = record(times, [6000.0, 2000.0], period=3 * 3600.0)
    error = model.predict(X_new) - y_new
    assert np.sqrt(np.mean(error ** 2)) < 0.01 * np.ptp(y_new)


def test_one_running_speed_cannot_identify_the_exponent_so_it_stays_at_its_start(training):
    X, y = training
    fitted = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(X, y)
    assert fitted.exponent_fitted_
    # only the 1500 rpm run and its stop carry weight: n^b is one constant there, b only scales the gains
    one_speed = (X[:, 1] == 1500.0) | (X[:, 1] == 0.0)
    one_speed[np.argmax(X[:, 1] == 3000.0):] = False
    model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), exponent=1.2).fit(
        X, y, sample_weight=one_speed.astype(float))
    assert not model.exponent_fitted_ and model.exponent_ == 1.2
    assert np.all(np.isfinite(model.predict(X)))
    # a speed that wanders by less than 5 % is still one speed
    jitter = X.copy()
    jitter[:, 1] *= np.where(jitter[:, 1] > 0, 1.0 + 0.02 * np.sin(np.arange(len(X))), 1.0)
    wandering = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(jitter, y, sample_weight=one_speed * 1.0)
    assert not wandering.exponent_fitted_
    # and a standstill that reads a few rpm is no second speed
    creeping = X.copy()
    creeping[:, 1] = np.where(creeping[:, 1] > 0, creeping[:, 1], np.arange(len(X)) % 3)
    at_rest = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(creeping, y, sample_weight=one_speed * 1.0)
    assert not at_rest.exponent_fitted_


def test_irregular_sampling_recovers_the_network(training):
    rng = np.random.default_rng(3)
    gaps = rng.uniform(20.0, 180.0, 1500)
    switches = np.arange(0.0, 48 * 3600.0, 4 * 3600.0)  # the duty's speed changes fall on samples
    times = np.union1d(np.cumsum(np.r_[0.0, gaps]), switches)
    times = times[times < 48 * 3600.0]
    X, y = record(times, [1500.0, 3000.0, 4500.0])
    model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(X, y)
    np.testing.assert_allclose(model.time_constants_, true_time_constants(), rtol=0.02)
    assert model.exponent_ == pytest.approx(EXPONENT, rel=0.02)
    # the model fitted on irregular samples predicts the regular record
    X_reg, y_reg = training
    assert np.sqrt(np.mean((model.predict(X_reg) - y_reg) ** 2)) < 0.01 * np.ptp(y_reg)


def _day(start_h, level):
    """A 16 h record from rest at ``start_h`` on the ambient's clock: 4 h stops and 4 h runs at ``level`` rpm."""
    times = start_h * 3600.0 + np.arange(0.0, 16 * 3600.0, 60.0)
    speed = duty(times - times[0], [level], 4 * 3600.0)
    nodes, drift = simulate(times, speed)
    return np.column_stack([times, speed, ambient(times), nodes[:, 0]]), drift


@pytest.fixture(scope="module")
def days():
    """Three records apart (a day between them, at rest), one speed each: 1500, 3000 and 4500 rpm."""
    return [_day(start, level) for start, level in ((0, 1500.0), (30, 3000.0), (60, 4500.0))]


def test_several_records_each_from_rest_train_one_network(days):
    X = np.vstack([x for x, _ in days])
    y = np.concatenate([d for _, d in days])
    starts = np.cumsum([len(x) for x, _ in days])[:-1]
    model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(X, y, record_starts=starts)
    np.testing.assert_allclose(model.time_constants_, true_time_constants(), rtol=0.02)
    # one speed per record, three between them: together they identify the exponent
    assert model.exponent_fitted_ and model.exponent_ == pytest.approx(EXPONENT, rel=0.02)
    assert not GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(*days[0]).exponent_fitted_
    times = np.arange(0.0, 24 * 3600.0, 60.0)
    X_new, y_new = record(times, [6000.0, 2000.0], period=3 * 3600.0)
    assert np.sqrt(np.mean((model.predict(X_new) - y_new) ** 2)) < 0.01 * np.ptp(y_new)
    # each record's clock may restart at 0
    restarted = np.vstack([np.column_stack([x[:, 0] - x[0, 0], x[:, 1:]]) for x, _ in days])
    again = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(restarted, y, record_starts=starts)
    np.testing.assert_allclose(again.time_constants_, model.time_constants_, rtol=1e-9)
    # run on as one record, the model carries the last run's heat over every night and misses
    joined = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(X, y)
    assert np.max(np.abs(joined.time_constants_ / true_time_constants() - 1.0)) > 0.05


@pytest.mark.parametrize("starts, message", [([1], r"got \[1\.0\]"), ([100, 100], "increasing"),
                                             ([100, 101], "at least 2 rows in every record"),
                                             ([2.5], "row numbers"), ([199], r"2\.\.198 for 200 rows")])
def test_record_starts_are_checked(starts, message):
    with pytest.raises(ValueError, match=message):
        GreyBoxRegressor(n_poles=1).fit(*_small(), record_starts=starts)


@pytest.mark.parametrize("time_constant", [30.0, 3600.0, 1e6])
def test_the_lag_states_at_uneven_times_are_the_zoh_recurrence(time_constant):
    """The closed-form stretches of ``_states`` against the row-by-row recurrence, over jitter and holes
    longer than a stretch (300 time constants), to the recurrence's own rounding; a three-day hole is
    e^{8640} for τ = 30 s, past the floats, so such a step is the recurrence itself."""
    rng = np.random.default_rng(5)
    steps = 15.0 + rng.uniform(-5.0, 5.0, 4000)
    steps[[1000, 2500, 3500]] = [400 * 30.0, 5 * 3600.0, 3 * 86400.0]
    times = np.cumsum(np.r_[7.0e4, steps])
    U = rng.normal(0.0, 10.0, (len(times), 3))
    rate = 1.0 / time_constant
    expected = np.empty_like(U)
    expected[0] = U[0]
    for k, step in enumerate(steps):
        decay = np.exp(-rate * step)
        expected[k + 1] = decay * expected[k] + (1.0 - decay) * U[k]
    states = GreyBoxRegressor._states(times, U, np.array([rate]), [(0, len(times))])[:, 0, :]
    np.testing.assert_allclose(states, expected, rtol=0, atol=1e-12 * np.abs(U).max())


def test_poles_are_negative_and_the_response_bounded_even_on_noise():
    rng = np.random.default_rng(0)
    times = np.arange(0.0, 500 * 60.0, 60.0)
    X = np.column_stack([times, rng.uniform(0, 5000, len(times)), 20 + rng.standard_normal(len(times))])
    y = np.cumsum(rng.standard_normal(len(times)))  # a random walk: no stable model fits it
    model = GreyBoxRegressor(n_poles=3).fit(X, y)
    A = model.state_space()[0]
    assert np.all(np.linalg.eigvals(A).real < 0)
    assert np.all(model.time_constants_ >= model.time_constant_bounds[0])
    long = np.arange(0.0, 1e7, 600.0)
    Xl = np.column_stack([long, np.full(len(long), 5000.0), np.full(len(long), 25.0)])
    pred = model.predict(Xl)
    assert np.all(np.isfinite(pred))
    assert abs(pred[-1] - pred[-2]) < 1e-6 * max(1.0, abs(pred[-1]))  # settled, not growing


def test_every_time_constant_stays_inside_its_bounds():
    # a drift that integrates the spindle heat: the fit wants a pole slower than any bound allows
    times = np.arange(0.0, 48 * 3600.0, 120.0)
    speed = duty(times, (2000.0, 6000.0), 4 * 3600.0)
    X = np.column_stack([times, speed, ambient(times)])
    y = np.cumsum(speed / 1000.0) * 1e-3
    bounds = (60.0, 20 * 3600.0)
    for n_poles in (2, 3):
        model = GreyBoxRegressor(n_poles=n_poles, time_constant_bounds=bounds).fit(X, y)
        tau = model.time_constants_
        assert bounds[0] <= tau[0] and tau[-1] <= bounds[1] * (1 + 1e-9)
        assert np.all(tau[1:] >= 2.0 * tau[:-1] * (1 - 1e-9))  # distinct poles, at least twofold apart


def test_observer_fuses_a_thermometer_to_follow_an_unmodelled_heat():
    times = np.arange(0.0, 30 * 3600.0, 60.0)
    X, y = record(times, [1500.0, 3000.0, 4500.0])
    model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), observed=(3,)).fit(X, y)
    assert model.output_std_[1] < 0.01  # the node-1 thermometer is an output of the same network (°C)
    X_test, y_test = record(times, [2000.0, 4000.0], extra_heat=80.0)
    open_loop = model.predict_outputs(X_test)[:, 0] - y_test
    filtered = model.predict_filtered(X_test)
    np.testing.assert_array_equal(model.predict(X_test), filtered)
    half = len(times) // 2
    rms = lambda e: np.sqrt(np.mean(e[half:] ** 2))
    assert rms(filtered - y_test) < 0.3 * rms(open_loop)
    # missing readings: the filter carries on with the model
    X_gap = X_test.copy()
    X_gap[half: half + 100, 3] = np.nan
    assert np.all(np.isfinite(model.predict_filtered(X_gap)))
    # without observed columns the observer is the simulation itself
    plain = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(X, y)
    np.testing.assert_allclose(plain.predict_filtered(X_test), plain.predict(X_test), atol=1e-8)


def test_observed_thermometers_count_from_each_records_start(days):
    """Two days, each from rest; the second 5 K warmer throughout (room and machine alike). The thermometer's
    change since its record's start is the network's output; its absolute reading is not, and a fit or an
    observer taking it absolute would see 5 K of heat that is not there."""
    (X1, y1), (X2, y2) = days[0], days[2]
    X2 = X2 + np.r_[0.0, 0.0, 5.0, 5.0]
    X = np.vstack([X1, X2])
    model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), observed=(3,)).fit(
        X, np.r_[y1, y2], record_starts=[len(X1)])
    np.testing.assert_allclose(model.time_constants_, true_time_constants(), rtol=0.02)
    assert model.output_std_[1] < 0.01
    filtered = model.predict(X2)
    assert np.sqrt(np.mean((filtered - y2) ** 2)) < 0.01 * np.ptp(y2)
    np.testing.assert_allclose(model.predict_outputs(X2)[0], 0.0, atol=1e-3)   # at rest at the start: no change
    with pytest.raises(ValueError, match="observed column 3 is nan at row 0, a record's first row"):
        model.predict(np.where(np.arange(len(X2))[:, None] == 0, [X2[0, 0], 0.0, X2[0, 2], np.nan], X2))


def test_every_fit_runs_with_one_blas_thread():
    """A multi-threaded BLAS rounds long sums differently per thread count (models._threads): every fit is
    wrapped, not a helper it calls."""
    for name, cls in estimator_classes().items():
        assert hasattr(cls.fit, "__wrapped__"), f"{name}.fit is not wrapped by one_blas_thread"


def test_missing_readings_of_an_observed_thermometer_are_left_out_of_the_fit():
    times = np.arange(0.0, 30 * 3600.0, 60.0)
    X, y = record(times, [1500.0, 3000.0, 4500.0])
    full = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), observed=(3,)).fit(X, y)
    gappy = X.copy()
    gappy[300:500, 3] = np.nan    # the thermometer out for 200 min, in the first run
    gappy[1200::7, 3] = np.nan    # and one reading in seven later on
    model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), observed=(3,)).fit(gappy, y)
    np.testing.assert_allclose(model.time_constants_, full.time_constants_, rtol=0.02)
    assert np.all(np.isfinite(model.gains_)) and model.output_std_[1] < 0.01
    with pytest.raises(ValueError, match="column 2 is nan"):   # an input may not miss one
        gappy[10, 2] = np.nan
        GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), observed=(3,)).fit(gappy, y)


_DETERMINISM = """
import numpy as np
from models.greybox import GreyBoxRegressor
t = np.arange(0.0, 2000 * 60.0, 60.0)
rng = np.random.default_rng(1)
speed = np.repeat(rng.choice([0, 1000, 2500, 4000], 20), 100).astype(float)
ambient = 20 + np.sin(t / 9000.0)
y = np.convolve(speed / 1000.0, np.exp(-np.arange(300) / 80.0))[: len(t)] * 0.05 + ambient + 0.1 * rng.standard_normal(len(t))
m = GreyBoxRegressor(n_poles=3).fit(np.column_stack([t, speed, ambient]), y)
print(repr(m.time_constants_.tolist()), repr(m.exponent_), repr(m.gains_.ravel().tolist()))
"""


def test_same_result_for_one_and_two_blas_threads():
    outputs = []
    for threads in ("1", "2"):
        env = {**os.environ, "OPENBLAS_NUM_THREADS": threads, "OMP_NUM_THREADS": threads}
        done = subprocess.run([sys.executable, "-c", _DETERMINISM], env=env, capture_output=True, text=True, check=True)
        outputs.append(done.stdout)
    assert outputs[0] == outputs[1]


def _small():
    t = np.arange(0.0, 200 * 60.0, 60.0)
    return np.column_stack([t, np.full(len(t), 1000.0), np.full(len(t), 20.0)]), np.linspace(0, 1, len(t))


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda X, y: (X[[0, 2, 1, *range(3, len(X))]], y), "time \\(column 0\\) must increase strictly, but row 2 has 60.0 s after 120.0 s"),
        (lambda X, y: (np.where(np.arange(len(X))[:, None] == 5, [300.0, -1.0, 20.0], X), y), "spindle speed .* row 5"),
        (lambda X, y: (np.where(np.arange(len(X))[:, None] == 7, [420.0, 1000.0, np.nan], X), y), "row 7, column 2 is nan"),
        (lambda X, y: (X[:, :1], y), "at least 2 columns"),
        (lambda X, y: (X, y[:-1]), "one value per row"),
        (lambda X, y: (X[:8], y[:8]), "needs at least .* samples"),
    ],
)
def test_bad_input_is_refused_with_a_clear_message(change, message):
    X, y = change(*_small())
    with pytest.raises(ValueError, match=message):
        GreyBoxRegressor(n_poles=2).fit(X, y)


@pytest.mark.parametrize(
    "params, message",
    [
        ({"n_poles": 5}, "n_poles must be 1-4"),
        ({"n_poles": 0}, "n_poles must be an integer >= 1"),
        ({"temperature_inputs": (1,)}, "temperature_inputs has column 1"),
        ({"temperature_inputs": (2,), "observed": (2,)}, "both inputs and observed"),
        ({"time_constant_bounds": (100.0, 150.0), "n_poles": 2}, "too narrow"),
        ({"speed_reference": -1000.0}, "speed_reference must be a positive speed"),
        ({"process_noise": -0.5}, "process_noise must be finite and >= 0"),
        ({"exponent_bounds": (3.0, 0.5)}, "exponent_bounds must be low < high"),
        # as `--param` gives them: a number or a text where a list is wanted
        ({"time_constant_bounds": 60}, r"time_constant_bounds must be two numbers \[low, high\], got 60"),
        ({"exponent_bounds": "3,0.5"}, r"exponent_bounds must be two numbers \[low, high\], got '3,0.5'"),
        ({"exponent_bounds": [1, 2, 3]}, r"exponent_bounds must be two numbers"),
        ({"observed": 3}, "observed must be a list of column numbers, got 3"),
        ({"temperature_inputs": [2.5]}, r"temperature_inputs must be a list of column numbers, got \[2.5\]"),
    ],
)
def test_bad_hyperparameters_are_refused(params, message):
    with pytest.raises(ValueError, match=message):
        GreyBoxRegressor(**params).fit(*_small())


def test_predict_checks_fit_and_width():
    X, y = _small()
    with pytest.raises(NotFittedError):
        GreyBoxRegressor().predict(X)
    model = GreyBoxRegressor(n_poles=1).fit(X, y)
    with pytest.raises(ValueError, match="features"):
        model.predict(np.column_stack([X, X[:, 2]]))


def test_rows_at_a_fixed_interval_need_no_time_column(training):
    X, y = training
    with_time = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(X, y)
    without = GreyBoxRegressor(n_poles=2, temperature_inputs=(1,), sampling_interval=60.0).fit(X[:, 1:], y)
    np.testing.assert_allclose(without.time_constants_, with_time.time_constants_, rtol=1e-9)
    np.testing.assert_allclose(without.predict(X[:, 1:]), with_time.predict(X), rtol=1e-9, atol=1e-9)
    with pytest.raises(ValueError, match="sampling_interval must be a positive number of s or None, got -1"):
        GreyBoxRegressor(sampling_interval=-1).fit(X[:, 1:], y)
    with pytest.raises(ValueError, match="temperature columns are 1..2 \\(column 0 is spindle_rpm\\)"):
        GreyBoxRegressor(temperature_inputs=(3,), sampling_interval=60.0).fit(X[:, 1:], y)


def test_round_trip_with_an_observer_predicts_bit_for_bit(training, tmp_path):
    from models.persistence import load_model, save_model

    X, y = training
    model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), observed=(3,)).fit(X, y)
    loaded = load_model(save_model(model, tmp_path / "greybox.json"))
    assert repr(loaded) == repr(model)
    np.testing.assert_array_equal(loaded.predict(X), model.predict(X))
    assert loaded.y_reference_ == y[0]


def test_clone_keeps_hyperparameters_and_drops_the_fit(training):
    from sklearn.base import clone

    X, y = training
    model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), observed=(3,), process_noise=0.1).fit(X, y)
    copy = clone(model)
    assert copy.get_params() == model.get_params()
    assert not hasattr(copy, "time_constants_")
