"""The observer's concentrated-heat prior (issue 15): one unread source of σ_P W somewhere on the machine.

Fast (ROM only, no FE): the prior's columns against their definition, σ_P = 0 against the observer without it,
and a synthetic record of the ROM with a source the observer does not know, where no thermometer is.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from twin.live.cli import DEFAULT_THERMOMETERS
from twin.live.model import (
    AXES,
    CONCENTRATED_SHARE,
    ObserverModel,
    concentrated_columns,
    concentrated_components,
    concentrated_moment,
)
from twin.live.observer import NOISE, Adaptation, DriftObserver

THERMOMETERS = list(DEFAULT_THERMOMETERS)


# ``machine`` (vmc_ram) and ``rom`` (r = 80) are the fixtures of conftest.py.
@pytest.fixture(scope="module")
def columns(machine, rom):
    return concentrated_columns(machine, rom)


@pytest.fixture(scope="module")
def moment(rom, machine):
    return concentrated_moment(rom, machine)


def _drift_rows(rom):
    return np.array([rom.output_matrix[rom.output_index(a)] for a in AXES]) / rom.eigenvalues


def _noise(sigma_W, **kw):
    return dataclasses.replace(NOISE, concentrated_W=sigma_W, **kw)


def test_cell_columns_are_one_watt_and_the_moment_is_their_mean(rom, columns, moment):
    """Units: each column is 1 W into the machine — z₁ᵀbᵢ = 1, so the mean temperature rises at 1/C K/s, C the
    heat capacity |z₁|² — and the cached moment is meanᵢ bᵢbᵢᵀ of these columns."""
    capacity = float(rom.uniform_state @ rom.uniform_state)
    assert 1e5 < capacity < 1e8                                          # J/K: a casting of about a tonne
    assert np.allclose(rom.uniform_state @ columns, 1.0, atol=1e-9)      # W per W
    assert columns.shape[1] > 50                                         # cells over every part
    assert np.allclose(moment, columns @ columns.T / columns.shape[1], rtol=1e-12, atol=0.0)


def test_kept_components_carry_the_share_of_each_axis(rom, columns, moment):
    """S computed here from the cell columns; the kept components carry ≥ 95 % of each drift axis's steady variance
    of it, are orthogonal, and are part of S (S − KKᵀ is positive semi-definite)."""
    S = columns @ columns.T / columns.shape[1]
    kept = concentrated_components(rom, moment)
    rows = _drift_rows(rom)
    total = np.diag(rows @ S @ rows.T)
    carried = np.square(rows @ kept).sum(axis=1)
    assert np.all(carried >= CONCENTRATED_SHARE * total), carried / total
    assert np.all(carried <= total * (1 + 1e-9))
    gram = kept.T @ kept
    assert np.allclose(gram, np.diag(np.diag(gram)), atol=1e-12 * gram.max())
    assert np.linalg.eigvalsh(S - kept @ kept.T).min() > -1e-12 * np.abs(S).max()
    assert kept.shape[1] < rom.order


def test_observer_model_carries_sigma_P_squared_times_the_prior(rom, moment):
    """The model's concentrated disturbances: σ_P each, estimated (before the consider states), dense columns into the
    modes only, and their steady Z variance is σ_P² of the kept components' (so W, not kW nor W²)."""
    sigma = 20.0
    model = ObserverModel(rom, THERMOMETERS, _noise(sigma), concentrated=moment)
    picked = [(j, d) for j, d in enumerate(model.disturbances) if d.name.startswith("concentrated:")]
    kept = concentrated_components(rom, moment)
    assert len(picked) == kept.shape[1]
    assert all(not d.consider and d.sigma == sigma and d.excitation == "one" for _, d in picked)
    columns = np.column_stack([d.column for _, d in picked])
    assert np.array_equal(columns[:rom.order], kept) and not columns[rom.order:].any()
    dense = set(model.couplings[0])
    lagged = model.n - rom.order
    assert all(lagged + j in dense for j, _ in picked)                  # a dense column couples densely
    assert model.consider.start > model.n + picked[-1][0] and model.consider.stop == model.n + model.q
    zrow = _drift_rows(rom)[2]
    assert np.isclose(np.sum(np.square(zrow @ (sigma * columns[:rom.order]))),
                      sigma ** 2 * np.sum(np.square(zrow @ kept)), rtol=1e-12)


def _record(rom, column=None, power_W=0.0, dt=60.0, seed=0):
    """A ROM record (2 h at 9000 rpm, 1 h stopped, 20 °C air) with an extra spindle-driven source of ``power_W``
    at 9000 rpm entering through ``column``; DS18S20-like readings (±0.5 °C offsets, 0.0625 °C steps)."""
    from models.kalman import discretize

    model = ObserverModel(rom, THERMOMETERS, _noise(0.0))
    ss, n = model.ss, model.n
    t = np.arange(0.0, 3 * 3600.0 + 1.0, dt)
    rpm = np.where((t > 0) & (t <= 2 * 3600.0), 9000.0, 0.0)
    U = model.plant_inputs(rpm, 20.0)
    extra = np.zeros(n) if column is None else np.r_[column, np.zeros(n - rom.order)]
    F, G, _ = discretize(ss.A, np.column_stack([ss.B, extra]), dt)
    x, states = rom.plant_steady_state(U[0]), []
    for k in range(len(t)):
        if k:
            x = F @ x + G @ np.r_[U[k], power_W * rpm[k] / 9000.0]
        states.append(x)
    Y = np.array(states) @ ss.C.T + U @ ss.D.T + ss.offset
    rng = np.random.default_rng(seed)
    offsets = rng.uniform(-0.5, 0.5, len(THERMOMETERS) + 1)
    T = _steps(Y[:, [rom.output_index(nm) for nm in THERMOMETERS]] + offsets[:-1])
    return t, rpm, _steps(np.full(len(t), 20.0) + offsets[-1]), T, Y[:, rom.output_index("Z")]


def _steps(values):
    """DS18S20 readings: 0.0625 °C steps."""
    return np.round(values / 0.0625) * 0.0625


def test_no_concentrated_source_is_the_observer_without_it_and_a_source_widens_the_band(rom, moment):
    """σ_P = 0: no concentrated state and the band of the observer without the prior to the last bit (the moment is
    not even read); σ_P > 0: a strictly wider Z band at every sample after the start (where the disturbance has not
    yet acted on the state), never narrower, also with the NIS widening."""
    nominal = _record(rom)
    t, rpm, air, T, _ = nominal
    plain = Adaptation()
    base = DriftObserver(rom, THERMOMETERS, _noise(0.0), plain)
    assert not any(d.name.startswith("concentrated:") for d in base.model.disturbances)
    band0 = base.run(t, rpm, air, T)[1]
    ignored = DriftObserver(rom, THERMOMETERS, _noise(0.0), plain, concentrated=np.full_like(moment, np.nan))
    assert np.array_equal(ignored.run(t, rpm, air, T)[1], band0)
    for sigma in (5.0, 20.0):
        band = DriftObserver(rom, THERMOMETERS, _noise(sigma), plain, concentrated=moment).run(t, rpm, air, T)[1]
        assert band[0, 2] == band0[0, 2]                 # the start: the source has not acted on the state yet
        assert np.all(band[1:, 2] > band0[1:, 2])
    shipped = DriftObserver(rom, THERMOMETERS, _noise(0.0), concentrated=moment).run(t, rpm, air, T)[1]
    wider = DriftObserver(rom, THERMOMETERS, _noise(10.0), concentrated=moment).run(t, rpm, air, T)[1]
    assert np.all(wider[:, 2] >= shipped[:, 2])                         # with the NIS widening too


def test_band_covers_an_unknown_concentrated_source_no_thermometer_sees(machine, rom, columns, moment):
    """A 30 W spindle-driven source in a cell of the column's left side at mid-height (no default thermometer there;
    T16 is low on the right side) that the observer's model lacks: with σ_P = 30 W the band covers ≥ 80 % of the
    true Z over 3 noise draws; without the prior (σ_P = 0) it covers far less (the Z error is several times the
    band).  A prior wired wrong (units, columns, couplings) does not widen the band where this source acts."""
    from twin.gap.discovery import source_cells

    cells = source_cells(machine)
    centres = np.array([c[2] for c in cells])
    on_column = [i for i, c in enumerate(cells) if c[0] == "column"]
    i = on_column[int(np.argmin(np.linalg.norm(centres[on_column] - [-0.2, -0.2, 1.0], axis=1)))]
    assert np.linalg.norm(centres[i] - [-0.2, -0.2, 1.0]) < 0.1
    coverage = {}
    for sigma in (0.0, 30.0):
        inside = []
        for seed in range(3):
            t, rpm, air, T, z = _record(rom, columns[:, i], 30.0, seed=seed)
            drift, band = DriftObserver(rom, THERMOMETERS, _noise(sigma), concentrated=moment).run(t, rpm, air, T)
            inside.append(np.abs(drift[:, 2] - z) <= band[:, 2])
        coverage[sigma] = float(np.mean(inside))
    assert coverage[30.0] >= 0.8, coverage
    assert coverage[0.0] <= 0.4, coverage


# ----------------------------------------------------------------------------- hypotheses weighed by the readings
def test_multiple_model_weighs_the_unread_source_hypothesis_by_the_readings(machine, rom, columns, moment):
    """Two filters, σ_P = 0 and 40 W, weighed by their predictions of the readings (ROM records, DS18S20-like).

    - Nominal: the σ_P = 0 filter wins, and the band is within 1.6 × that filter's, under a third of the
      σ_P = 40 W filter's alone.
    - 40 W in the base under the table (the cell nearest (0, 0.5, 0.05) m; T22 and T26 see the base warm, and
      the σ_P = 0 filter gives it to the front zone's air): the σ_P = 40 W filter wins, the Z error is less than
      half the σ_P = 0 filter's, and the band covers ≥ 90 % where that filter's covers ≤ 30 %.
    - 40 W in every 4th cell of the machine: the pooled coverage goes from ≤ 70 % (σ_P = 0) to ≥ 85 %.  (Cells
      no thermometer sees stay uncovered: the readings cannot tell that source from none.)

    Weights that ignore the readings fail the first and second points."""
    from twin.gap.discovery import source_cells
    from twin.live.multiple_model import MultipleModelObserver

    def run(cell, power_W):
        t, rpm, air, T, z = _record(rom, columns[:, cell], power_W, seed=1)
        mixture = MultipleModelObserver(rom, THERMOMETERS, (0.0, 40.0), concentrated=moment)
        drift, band = mixture.run(t, rpm, air, T)
        single = DriftObserver(rom, THERMOMETERS, _noise(0.0), concentrated=moment).run(t, rpm, air, T)
        return z, (drift[:, 2], band[:, 2]), (single[0][:, 2], single[1][:, 2]), mixture.weights

    def covered(z, estimate):
        return np.abs(estimate[0] - z) <= estimate[1]

    def rms(z, estimate):
        return np.sqrt(np.mean((estimate[0] - z) ** 2))

    cells = source_cells(machine)
    base = [i for i, c in enumerate(cells) if c[0] == "base"]
    under_table = base[int(np.argmin(np.linalg.norm(np.array([cells[i][2] for i in base]) - [0.0, 0.5, 0.05], axis=1)))]

    z, mixture, single, weights = run(under_table, 0.0)
    t, rpm, air, T, _ = _record(rom)
    wide = DriftObserver(rom, THERMOMETERS, _noise(40.0), concentrated=moment).run(t, rpm, air, T)[1][:, 2]
    assert weights[0] > 0.8, weights
    assert np.mean(mixture[1]) <= 1.6 * np.mean(single[1]) and np.mean(mixture[1]) < np.mean(wide) / 3
    assert np.mean(covered(z, mixture)) >= 0.95

    z, mixture, single, weights = run(under_table, 40.0)
    assert weights[1] > 0.5, weights
    assert rms(z, mixture) < 0.5 * rms(z, single)
    assert np.mean(covered(z, mixture)) >= 0.9 and np.mean(covered(z, single)) <= 0.3

    inside = {"mixture": [], "single": []}
    for cell in range(0, columns.shape[1], 4):
        z, mixture, single, _ = run(cell, 40.0)
        inside["mixture"].append(covered(z, mixture))
        inside["single"].append(covered(z, single))
    assert np.mean(inside["single"]) <= 0.7 and np.mean(inside["mixture"]) >= 0.85, \
        {k: np.mean(v) for k, v in inside.items()}


def test_multiple_model_refuses_fewer_than_two_distinct_hypotheses(rom, moment):
    from twin.errors import TwinInputError
    from twin.live.multiple_model import MultipleModelObserver, live_observer

    for sizes in ((40.0,), (0.0, 0.0), (0.0, -5.0)):
        with pytest.raises(TwinInputError, match="two or more distinct sizes"):
            MultipleModelObserver(rom, THERMOMETERS, sizes, concentrated=moment)
    assert isinstance(live_observer(rom, THERMOMETERS, hypotheses_W=(0.0,)), DriftObserver)
