"""Independent truths of the gap benchmark: physics changed in a definition copy (full FE), sensor errors, sampling."""
import numpy as np
import pytest

from twin.core.scenario import load_scenario
from twin.errors import TwinInputError
from twin.gap.sensor_errors import dead_time, resample, sample_times, second_order_lag
from twin.gap.truth import PhysicsChange, physics_truth

SCENARIO = "gap_quick_8h"


def test_second_order_lag_step_response_is_analytic():
    t = np.arange(0.0, 4000.0, 10.0)
    u = np.where(t >= 100.0, 1.0, 0.0)
    tau1, tau2 = 300.0, 120.0
    y = second_order_lag(t, u, tau1, tau2)
    # the input is linear between samples: a ramp over 90–100 s, i.e. a step at 95 s once it has passed
    s = np.clip(t - 95.0, 0.0, None)
    exact = 1.0 - (tau1 * np.exp(-s / tau1) - tau2 * np.exp(-s / tau2)) / (tau1 - tau2)
    assert np.abs(y[t > 200] - exact[t > 200]).max() < 1e-4
    assert np.abs(y - exact).max() < 2e-3
    with pytest.raises(TwinInputError, match="uniformly sampled"):
        second_order_lag(np.array([0.0, 1.0, 3.0]), np.zeros(3), 1.0, 2.0)


def test_dead_time_and_sampling():
    t = np.arange(0.0, 600.0, 30.0)
    np.testing.assert_allclose(dead_time(t, 2.0 * t, 45.0)[3:], 2.0 * (t[3:] - 45.0))
    assert np.allclose(np.diff(sample_times(3600.0, "45s")), 45.0)
    irregular = np.diff(sample_times(3600.0, "irregular", seed=1))
    assert irregular.min() >= 30.0 and irregular.max() <= 70.0
    assert sample_times(3600.0, "clock_offset")[0] == 15.0
    with pytest.raises(TwinInputError, match="unknown sampling"):
        sample_times(3600.0, "sometimes")


@pytest.fixture()
def isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("THERMAL_TWIN_CACHE", str(tmp_path))
    return tmp_path


def test_physics_truth_changes_the_physics_and_is_cached(isolated_cache):
    nominal = physics_truth(SCENARIO, PhysicsChange(), noise=False)
    weak = physics_truth(SCENARIO, PhysicsChange(joints={"carrier-ram": 0.2}), noise=False)
    z = [c.name for c in nominal.channels].index("Z")
    # a weaker ram-guide joint changes the drift materially (≫ the 0.1 µm tolerance)
    assert np.abs(weak.values[:, z] - nominal.values[:, z]).max() > 0.5
    assert {c.kind for c in weak.channels} <= {"spindle_speed", "feed", "temperature", "air", "displacement",
                                               "strain"}
    assert len(list((isolated_cache / "gap-truth").glob("truth-*.csv"))) == 2
    again = physics_truth(SCENARIO, PhysicsChange(joints={"carrier-ram": 0.2}), noise=False)
    np.testing.assert_array_equal(again.values, weak.values)
    with pytest.raises(TwinInputError, match="unknown group"):
        physics_truth(SCENARIO, PhysicsChange(convection={"roof": 2.0}), noise=False)


def test_resample_to_a_clock_offset(isolated_cache):
    fine = physics_truth(SCENARIO, PhysicsChange(output_step_s=30.0), noise=False)
    sc = load_scenario(SCENARIO)
    times = sample_times(sc.duration_s - 60.0, "clock_offset")
    out = resample(fine, times, sc)
    np.testing.assert_array_equal(out.time_s, times)
    spindle = [c.name for c in out.channels].index("spindle")
    np.testing.assert_array_equal(out.values[:, spindle], sc.operating(times)[0])
    t01 = [c.name for c in out.channels].index("T01")
    np.testing.assert_allclose(out.values[:, t01], np.interp(times, fine.time_s, fine.values[:, t01]))


def test_expansion_change_gives_one_part_its_own_alpha_and_keeps_earlier_cache_keys():
    from twin.core.machine_definition import load_machine
    from twin.gap.truth import changed_definition

    nominal = load_machine("vmc_ram")
    changed = changed_definition(nominal, PhysicsChange(expansion={"ram": 1.1}))
    alpha = {p.name: changed.part_material(p.name).expansion for p in changed.geometry.parts}
    before = {p.name: nominal.part_material(p.name).expansion for p in nominal.geometry.parts}
    assert alpha["ram"] == pytest.approx(1.1 * before["ram"])
    assert {k: v for k, v in alpha.items() if k != "ram"} == {k: v for k, v in before.items() if k != "ram"}
    assert nominal.part_material("ram").expansion == before["ram"]            # the nominal definition is untouched
    assert changed.geometry.digest(0.045) == nominal.geometry.digest(0.045)   # same mesh from the cache
    assert "expansion" not in PhysicsChange(joints={"carrier-ram": 0.2}).key()
    assert "expansion" in PhysicsChange(expansion={"ram": 1.1}).key()
    with pytest.raises(TwinInputError, match=r"unknown part\(s\) \['roof'\]"):
        changed_definition(nominal, PhysicsChange(expansion={"roof": 1.1}))


@pytest.mark.slow
def test_expansion_truth_changes_drift_not_temperatures():
    """α enters only the displacement operator (built anew by adjoint solves, minutes, then in the user cache):
    every thermometer reads the same, the drift changes."""
    nominal = physics_truth(SCENARIO, PhysicsChange(), noise=False)
    hot_ram = physics_truth(SCENARIO, PhysicsChange(expansion={"ram": 1.1}), noise=False)
    kinds = [c.kind for c in nominal.channels]
    temps = [j for j, k in enumerate(kinds) if k == "temperature"]
    np.testing.assert_allclose(hot_ram.values[:, temps], nominal.values[:, temps], rtol=0, atol=1e-9)
    z = [c.name for c in nominal.channels].index("Z")
    assert np.abs(hot_ram.values[:, z] - nominal.values[:, z]).max() > 0.1
