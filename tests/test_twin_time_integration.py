"""Scenario runs integrate their inputs exactly, check their energy, estimate their time-step error, and
compute only the outputs they record.

On the default machine: an NC cycle whose segments are not whole time steps
(45 s at 9000 rpm + 15 s stop, 60 s steps), the energy balance of the run
against the energy the scenario asks for, the step-doubling error estimate
against the error measured with a fine-step reference, and the outputs the
solver is asked to compute.
"""
import dataclasses

import numpy as np
import pytest

import fea
from twin.core.scenario import load_scenario
from twin.core.simulate import ScenarioInputs, simulate
from twin.run.summary import format_summary, run_summary

NC_CYCLE = """
[scenario]
name = "nc_45_15"
duration_h = 1
{extra}
[ambient]
kind = "constant"
temperature_C = 20.0
[[segments]]
repeat = 60
steps = [ {{ duration_s = 45, spindle_rpm = 9000 }}, {{ duration_s = 15, spindle_rpm = 0 }} ]
"""

HEAT_COOL = """
[scenario]
name = "heat_cool_1h"
sample_interval_s = 60.0
scheme = "{scheme}"
[ambient]
kind = "constant"
temperature_C = 20.0
[[segments]]
duration_h = 1
spindle_rpm = 9000
[[segments]]
duration_h = 1
spindle_rpm = 0
"""


def _scenario(tmp_path, text, name="probe"):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return load_scenario(path)


def _with_step(scenario, step_s):
    return dataclasses.replace(scenario, time_step_s=float(step_s))


def _analytic_source_energy_J(definition, rpm, seconds):
    """Energy of each source running ``seconds`` at ``rpm`` (feeds 0): c (n/n_ref)^b · t, written out here."""
    out = {}
    for src in definition.sources:
        if src.driver == "constant":
            out[src.name] = src.coefficient_W * 3600.0                 # runs all the hour, idle or not
        elif src.driver == "spindle":
            out[src.name] = src.coefficient_W * (rpm / src.reference) ** src.exponent * seconds
        else:
            out[src.name] = 0.0                                        # feed-driven: no axis moves
    return out


# ------------------------------------------------------------------ segments off the step grid
def test_off_grid_duty_cycle_converges_to_the_fine_step_result(machine, tmp_path):
    """60 × (45 s on + 15 s off) at 60 s steps: the drift of a 5 s reference, converging as the step shrinks."""
    sc = _scenario(tmp_path, NC_CYCLE.format(extra=""))
    assert sc.time_step_s == 60.0
    z = {step: simulate(_with_step(sc, step), machine, noise=False).dataset["Z"] for step in (60, 15, 5)}
    reference = np.abs(z[5]).max()
    assert reference > 20.0                                            # µm: 45 min of spindle heat
    error_60 = np.abs(z[60] - z[5]).max()
    error_15 = np.abs(z[15] - z[5]).max()
    print(f"\nZ: max |Z_60 − Z_5| = {error_60:.4f} µm, |Z_15 − Z_5| = {error_15:.4f} µm of {reference:.2f} µm")
    assert error_60 < 0.01 * reference
    assert error_15 < 0.5 * error_60                                   # first order: the error shrinks with the step


def test_off_grid_duty_cycle_injects_the_analytic_energy(machine, tmp_path):
    sc = _scenario(tmp_path, NC_CYCLE.format(extra=""))
    result = simulate(sc, machine, noise=False)
    balance = result.dataset.metadata["energy_balance"]
    expected = _analytic_source_energy_J(machine.definition, 9000.0, 60 * 45.0)
    assert sum(expected.values()) > 1e5                                # J: the test moves real energy
    assert balance["sources_injected_J"] == pytest.approx(sum(expected.values()), rel=1e-12)
    assert balance["sources_requested_J"] == pytest.approx(sum(expected.values()), rel=1e-12)
    assert balance["ok"] and balance["relative_error"] < 1e-10


# ------------------------------------------------------------------ the energy balance of a run
@pytest.mark.parametrize("body", [
    '[scenario]\nduration_h = 2\n[ambient]\nkind = "constant"\ntemperature_C = 20.0\n',           # idle
    '[scenario]\nduration_h = 12\nsample_interval_s = 600.0\n[initial]\nkind = "steady"\n'
    '[ambient]\nkind = "sinusoid"\nmean_C = 20.0\namplitude_K = 2.5\nperiod_h = 12\n',            # ETVE
    "iso230_3_spindle_short",                                                                      # spindle
], ids=["idle", "etve", "spindle"])
def test_energy_balance_is_small_for_normal_runs(machine, tmp_path, body):
    sc = load_scenario(body) if "\n" not in body else _scenario(tmp_path, body)
    ds = simulate(sc, machine, noise=False).dataset
    balance = ds.metadata["energy_balance"]
    assert balance["ok"]
    # Round-off only: ~1e-14 K of the whole machine when idle (against the 10 mK floor), ~1e-13 otherwise.
    assert balance["stored_vs_loads"] < 1e-7 and balance["sources_vs_scenario"] < 1e-12
    assert ds.metadata["energy_balance_relative_error"] < 1e-7
    assert "FAILED" not in format_summary(run_summary(ds, 0.0))


def test_a_lost_heat_source_is_flagged(machine, tmp_path, monkeypatch):
    """Driven by its step ends instead of its step means, the 45/15 cycle loses its heat: the check says so."""
    monkeypatch.delattr(ScenarioInputs, "means")
    sc = _scenario(tmp_path, NC_CYCLE.format(extra=""))
    with pytest.warns(RuntimeWarning, match="energy balance fails"):
        ds = simulate(sc, machine, noise=False).dataset
    balance = ds.metadata["energy_balance"]
    assert not balance["ok"]
    assert balance["sources_vs_scenario"] > 0.5                          # most of the throughput is missing
    assert balance["stored_vs_loads"] < 1e-7                             # the solver itself is consistent
    assert "**FAILED**" in format_summary(run_summary(ds, 0.0))


# ------------------------------------------------------------------ time-step error estimate
@pytest.mark.parametrize("scheme", ["backward_euler", "crank_nicolson"])
def test_step_error_estimate_tracks_the_true_error(machine, tmp_path, scheme):
    """Step doubling at 60 s against the error measured with 5 s steps: within a factor 2 per channel kind."""
    sc = _scenario(tmp_path, HEAT_COOL.format(scheme=scheme))
    ds = simulate(sc, machine, noise=False, step_error=True).dataset
    reference = simulate(_with_step(sc, 5.0), machine, noise=False).dataset
    estimate = ds.metadata["time_step_error"]
    for kind, key in (("temperature", "temperature_K"), ("displacement", "displacement_um")):
        names = ds.names_of_kind(kind)
        true = max(float(np.abs(ds[n] - reference[n]).max()) for n in names)
        print(f"\n{scheme} {kind}: estimated {estimate[key]:.3g}, true {true:.3g}")
        assert 0.5 * true < estimate[key] < 2.0 * true
    summary = format_summary(run_summary(ds, 0.0))
    assert "estimated time-step error (step doubling)" in summary


# ------------------------------------------------------------------ only what is recorded
@pytest.mark.parametrize("camera", [False, True])
def test_only_recorded_outputs_are_computed(machine, tmp_path, monkeypatch, camera):
    computed = []
    run = fea.ThermalSolver.run

    def spy(self, T0, times, schedule, outputs=None, *args, **kwargs):
        computed.append(list(outputs.names))
        return run(self, T0, times, schedule, outputs, *args, **kwargs)

    monkeypatch.setattr(fea.ThermalSolver, "run", spy)
    sc = dataclasses.replace(_scenario(tmp_path, NC_CYCLE.format(extra="")), record_camera=camera)
    ds = simulate(sc, machine, noise=False).dataset
    spots = [c.name for c in machine.channels if c.kind == "camera"]
    assert len(spots) > 500
    assert (set(spots) <= set(computed[0])) == camera
    assert set(computed[0]) <= set(ds.names)                           # nothing computed that is not recorded
    assert ("cam000" in ds.names) == camera


def test_twin_run_exits_1_on_a_failed_energy_balance(tmp_path, monkeypatch, capsys):
    """The results are written and marked, but a script must not take them for good ones."""
    from twin.cli import main

    monkeypatch.delattr(ScenarioInputs, "means")
    path = tmp_path / "lossy.toml"
    path.write_text(NC_CYCLE.format(extra=""))
    with pytest.warns(RuntimeWarning, match="energy balance fails"):
        code = main(["run", str(path), "--out", str(tmp_path / "out"), "--no-views"])
    assert code == 1
    assert "the energy balance FAILED" in capsys.readouterr().err
    assert "**FAILED**" in (tmp_path / "out" / "summary.md").read_text()
