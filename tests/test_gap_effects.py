"""The gap effects change the twin as documented; linear effects are exactly linear; the ROM matches the FE."""
from dataclasses import replace

import numpy as np
import pytest

from twin.core.machine import operator_reusable, reassemble
from twin.core.scenario import load_scenario
from twin.gap.drive import ScenarioDrive
from twin.gap.effects import default_library, library_by_name
from twin.gap.engine import FullBackend
from twin.gap.model import GapModel
from twin.gap.signals import lag, uniform_grid
from twin.gap.structure import RADIATIVE_COEFFICIENT, facet_table
from twin.infra.sweep import cached

LIB = {e.name: e for e in default_library()}


@pytest.fixture(scope="module")
def machine():
    from twin.gap.diagnose import _machine

    return _machine("vmc_ram")


@pytest.fixture(scope="module")
def engine(machine):
    from twin.gap.diagnose import engine

    return engine(machine, default_library())


@pytest.fixture(scope="module")
def drive(machine):
    sc = load_scenario("gap_quick_8h")
    return ScenarioDrive(sc, machine, uniform_grid(0.0, sc.duration_s, 120.0))


def test_library_has_at_least_eight_documented_bounded_effects(machine):
    lib = default_library()
    assert len(lib) >= 8 and len({e.name for e in lib}) == len(lib)
    for e in lib:
        assert e.label and e.how and e.kind in ("system", "input", "output")
        for p in e.parameters(machine):
            assert p.lower <= p.nominal <= p.upper and p.lower < p.upper
        assert e.applicable(machine), e.name
    with pytest.raises(Exception, match="unknown effect"):
        library_by_name(["no_such_effect"])


@pytest.mark.parametrize("name, scale", [("convection_enclosure", 1.7), ("joint_ram_guides", 0.3)])
def test_system_terms_are_exact_affine_changes(machine, engine, name, scale):
    structure, _ = engine
    effect = LIB[name]
    d = machine.definition
    if effect.kind == "system" and name.startswith("convection"):
        changed = replace(d, convection=[replace(r, coefficient=r.coefficient * scale) if r.name in
                                         effect.hidden["groups"] else r for r in d.convection])
    else:
        changed = replace(d, joints=[(a, b, h * scale) if {a, b} == {"carrier", "ram"} else (a, b, h)
                                     for a, b, h in d.joints])
    truth = reassemble(machine, changed).thermal
    a = effect.coefficients([scale], structure)[name]
    dA, _ = structure.system_terms[name]
    A = structure.stiffness + a * dA
    assert abs(A - truth.stiffness).max() <= 1e-9 * abs(truth.stiffness).max()
    B = structure.input_matrix[:, : structure.n_machine_inputs] + a * structure.system_terms[name][1]
    assert abs(B - truth.input_matrix).max() <= 1e-9 * abs(truth.input_matrix).max() + 1e-15
    assert effect.coefficients([1.0], structure)[name] == 0.0


def test_extra_input_columns(machine, engine):
    structure, _ = engine
    B = structure.input_matrix
    belt = B[:, structure.input_index("gap:belt_drive")].toarray().ravel()
    assert belt.sum() == pytest.approx(1.0)                 # 1 W at the reference speed
    x0, x1, y0, y1, z0, z1 = LIB["belt_drive"].hidden["box"]
    pts = machine.thermal.points[belt > 0]
    assert (pts[:, 0] >= x0 - 0.05).all() and (pts[:, 2] >= z0 - 0.05).all()
    _, cents, areas, groups, h, _ = facet_table(machine)
    for g in ("outside", "front"):
        col = B[:, structure.input_index(f"gap:radiation:{g}")].toarray().ravel()
        assert col.sum() == pytest.approx(RADIATIVE_COEFFICIENT * areas[groups == g].sum())
    pocket = B[:, structure.input_index("gap:air_pocket")].toarray().ravel()
    assert 0 < pocket.sum() < np.sum(h * areas)
    assert machine.thermal.points[pocket > 0][:, 2].min() > 1.3    # around the spindle motor on top


def test_input_effects_change_the_documented_inputs(machine, engine, drive):
    structure, _ = engine
    src = [s for s in machine.definition.sources if s.driver == "spindle"]
    ch = LIB["spindle_power_scale"].input_changes([1.4], drive, structure)
    for s in src:
        np.testing.assert_allclose(ch[f"power:{s.name}"], 0.4 * s.power_W(drive.spindle_rpm, drive.feed_mm_min))
    ch = LIB["speed_exponent"].input_changes([0.5], drive, structure)
    at_ref = np.isclose(drive.spindle_rpm, 9000.0) | (drive.spindle_rpm == 0)
    assert all(np.allclose(v[at_ref], 0.0) for v in ch.values())
    assert any(np.abs(v[drive.spindle_rpm == 12000]).max() > 1.0 for v in ch.values())
    ch = LIB["stratification"].input_changes([0.2], drive, structure)
    np.testing.assert_allclose(ch["ambient_gradient"], 0.2 * drive.room_excursion())
    ch = LIB["enclosure_lag"].input_changes([6.0], drive, structure)
    expected = drive.zone_ambient(lags_s={"enclosure": 6 * 3600.0})["enclosure"] - drive.zone_ambient()["enclosure"]
    np.testing.assert_allclose(ch["ambient:enclosure"], expected)
    ch = LIB["door_draft"].input_changes([0.5], drive, structure)["ambient:enclosure"]
    amb = drive.zone_ambient()
    np.testing.assert_allclose(ch, 0.5 * (amb["front"] - amb["room"]))
    assert ch.min() == pytest.approx(-3.0) and np.abs(ch[drive.grid < 3.5 * 3600]).max() < 1e-12
    ch = LIB["air_pocket"].input_changes([3.0], drive, structure)["gap:air_pocket"]
    assert ch.max() == pytest.approx(3.0 * 12000 / 9000 * (1 - np.exp(-3.0)), rel=0.02) and ch[0] == 0.0  # 1 h, τ 20 min


def test_output_effects():
    t = np.zeros((50, 2))
    t[10:] = 1.0
    air = np.full_like(t, 5.0)
    np.testing.assert_allclose(LIB["sensor_mounting"].thermometer_change([0.25], t, air, 60.0), 0.75 * t + 1.25)
    lagged = LIB["sensor_lag"].thermometer_change([600.0], t, air, 60.0)
    np.testing.assert_allclose(lagged, lag(t, 60.0, 600.0))
    # a step through a 600 s first-order lag, sampled at 60 s: 1 − exp(−t/τ) up to the sampling error
    step_response = 1.0 - np.exp(-(np.arange(50) - 10) * 60.0 / 600.0)
    np.testing.assert_allclose(lagged[10:, 0], step_response[10:], atol=0.06)
    # the lag is exact for a ramp: y = x − τ after the transient
    ramp = np.arange(400.0)
    np.testing.assert_allclose(lag(ramp, 1.0, 10.0)[200:], ramp[200:] - 10.0, atol=1e-6)


def test_linear_effects_are_exactly_linear(machine, engine, drive):
    structure, backend = engine
    model = GapModel(structure, backend, drive, drive.grid)
    base = model.predict().values
    for e in default_library():
        if not e.linear:
            continue
        nominal = e.nominal(machine)
        span = np.array([p.upper - p.lower for p in e.parameters(machine)])
        y1 = model.predict([(e, nominal + 0.2 * span)]).values - base
        y2 = model.predict([(e, nominal + 0.6 * span)]).values - base
        assert np.abs(y1).max() > 1e-3, f"{e.name} changes nothing on this scenario"
        np.testing.assert_allclose(y2, 3.0 * y1, atol=1e-9 * np.abs(y2).max(), err_msg=e.name)


def test_reduced_model_matches_the_full_fe(machine, engine, drive):
    """The parametric ROM agrees with the full FE (backward Euler at 1/3 of the step) within a few % of each effect.

    The two system terms are taken beyond the parameter values their perturbed bases were built at.
    """
    structure, backend = engine
    fine = ScenarioDrive(drive.scenario, machine, uniform_grid(0.0, 4 * 3600.0, 40.0))
    times = fine.grid[::3]
    rom = GapModel(structure, backend, fine, times)
    fe = GapModel(structure, FullBackend(structure), fine, times)
    y0_rom, y0_fe = rom.predict().values, fe.predict().values
    T, D = structure.thermometers, structure.displacements
    # nominal: within the backward-Euler time-step error of the FE at 40 s (the ROM steps exactly)
    assert np.abs(y0_rom - y0_fe)[:, T].max() < 0.15 and np.abs(y0_rom - y0_fe)[:, D].max() < 0.3
    for name, theta in (("convection_enclosure", [2.5]), ("joint_ram_guides", [0.1])):
        e = LIB[name]
        d_rom = rom.predict([(e, np.array(theta))]).values - y0_rom
        d_fe = fe.predict([(e, np.array(theta))]).values - y0_fe
        for cols in (T, D):
            assert np.abs(d_rom - d_fe)[:, cols].max() <= 0.03 * np.abs(d_fe[:, cols]).max(), name


def test_structure_is_cached_per_process(machine):
    from twin.gap.diagnose import engine

    a = engine(machine, default_library())
    b = engine(machine, default_library())
    assert a is b
    assert cached(("machine", "vmc_ram", None), lambda: None) is machine


@pytest.mark.parametrize("name, amplitude, rest", [("radiation_walls", [0.3], [8.0]),
                                                   ("fixture_drift", [0.5, -1.0, 2.0], [45.0])])
def test_fitted_lags_leave_the_amplitudes_linear(machine, engine, drive, name, amplitude, rest):
    """ε of radiation and k of the fixture drift stay linear at a fixed (fitted) lag; the lag changes the shape."""
    structure, backend = engine
    model = GapModel(structure, backend, drive, drive.grid)
    base = model.predict().values
    e = LIB[name]
    y1 = model.predict([(e, np.r_[amplitude, rest])]).values - base
    y3 = model.predict([(e, np.r_[3 * np.array(amplitude), rest])]).values - base
    assert np.abs(y1).max() > 1e-3
    np.testing.assert_allclose(y3, 3.0 * y1, atol=1e-9 * np.abs(y3).max())
    other_lag = model.predict([(e, np.r_[amplitude, 4 * np.array(rest)])]).values - base
    assert np.abs(other_lag - y1).max() > 0.05 * np.abs(y1).max()


def test_reassemble_refuses_a_change_of_what_the_output_operator_is_made_of(machine):
    """A part's expansion coefficient enters the drift rows: reusing the operator would give a silently wrong
    drift, so reassemble refuses it (a convection change, which the operator does not see, is taken)."""
    from meshes.tomlspec import DefinitionError

    d = machine.definition
    material = d.part_material("ram")
    name = next(k for k, v in d.materials.items() if v is material)
    hotter = replace(d, materials={**d.materials, name: replace(material, expansion=material.expansion * 1.1)})
    assert not operator_reusable(machine, hotter)
    assert operator_reusable(machine, replace(d, joints=[(a, b, 2 * h) for a, b, h in d.joints]))
    with pytest.raises(DefinitionError, match="elastic properties"):
        reassemble(machine, hotter)
    moved = replace(d, support_points=[tuple(np.add(p, 0.01)) for p in d.support_points])
    with pytest.raises(DefinitionError, match="build the machine anew"):
        reassemble(machine, moved)
    assert reassemble(machine, replace(d, convection=list(d.convection))).outputs is machine.outputs
