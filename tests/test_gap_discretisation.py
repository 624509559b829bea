"""The twin's discretisation floor: measured on a coarser mesh, it widens the sensors' σ_j and not the groups' σ_g.

The slow case is the false alarm it was made for: a densely sampled record of a finer mesh's full-FE truth with
no effect in it, where one thermometer beside a concentrated heat source read 5.8 σ off the twin.
"""
import dataclasses

import numpy as np
import pytest
from test_gap_verdict import SCALES, _channels, _result

from twin.gap import diagnose as gap_diagnose
from twin.gap import verdict
from twin.gap.fit import GROUP_FLOOR, Evaluator


def _evaluator():
    """Two thermometers and a drift channel, 40 rows, the last 12 held out, noise below the tolerances."""
    rng = np.random.default_rng(0)
    rows = np.arange(40)
    ev = Evaluator(rng.normal(size=(40, 3)), [0, 1, 2], ["temperature", "temperature", "displacement"],
                   rows < 28, rows >= 28, noise=np.array([0.01, 0.01, 0.02]))
    ev.set_weights()
    return ev


def test_the_discretisation_floor_widens_each_sensor_in_quadrature_and_no_group():
    ev = _evaluator()
    names = ["T01", "T24", "Z"]
    timing = np.array([0.0, 0.03, 0.0])
    plain = verdict.scales(ev, names, timing)
    floored = verdict.scales(ev, names, timing, np.array([0.0, 0.25, np.nan]))
    assert floored.group == plain.group
    assert floored.sensor["T01"] == plain.sensor["T01"] and floored.sensor["Z"] == plain.sensor["Z"]
    assert floored.sensor["T24"] == pytest.approx(np.sqrt(GROUP_FLOOR["temperature"] ** 2 + 0.03 ** 2 + 0.25 ** 2))
    assert floored.discretisation_sensor == {"T01": 0.0, "T24": 0.25, "Z": 0.0}
    assert plain.discretisation_sensor == {}


def test_a_sensor_is_mesh_limited_only_when_the_floor_alone_takes_it_under_the_gate():
    floors = {n: 0.0 for n in SCALES.sensor}
    floors["T07"] = 0.3
    sensor = {**SCALES.sensor, "T07": float(np.hypot(0.05, 0.3))}
    sc = verdict.Scales(SCALES.group, sensor, discretisation_sensor=floors)
    within = _result("nominal", {"temperature": 0.05, "displacement": 0.05}, _channels(0.03, 0.05, 0.29), 0, [])
    assert verdict.mesh_limited(within, sc) == ["T07"]                      # 5.8 σ without the floor, 0.95 σ with
    beyond = _result("nominal", {"temperature": 0.05, "displacement": 0.05}, _channels(0.03, 0.05, 2.0), 0, [])
    assert verdict.mesh_limited(beyond, sc) == []                           # a gap either way
    small = _result("nominal", {"temperature": 0.05, "displacement": 0.05}, _channels(0.03, 0.05, 0.1), 0, [])
    assert verdict.mesh_limited(small, sc) == []                            # no gap either way


def test_the_floor_is_measured_only_when_the_nominal_twin_has_a_gap(monkeypatch):
    """It only widens σ_j, so a record without a gap keeps its verdict without the coarser mesh's cost."""
    ev, names = _evaluator(), ["T01", "T24", "Z"]
    calls = []

    def floor(model, nominal, evaluator, engine):
        calls.append(model)
        return np.array([0.0, 0.4, 0.0])

    monkeypatch.setattr(gap_diagnose, "discretisation_floor", floor)
    quiet = _result("nominal", {"temperature": 0.05, "displacement": 0.05},
                    {"T01": 0.04, "T24": 0.06, "Z": 0.05}, 0, [])
    timings, notes = {}, []
    _, decision = gap_diagnose._judge("model", ev, names, None, quiet, [], timings, notes)
    assert decision.outcome == "no_significant_gap" and calls == [] and "discretisation_s" not in timings
    hot = _result("nominal", {"temperature": 0.07, "displacement": 0.05},
                  {"T01": 0.04, "T24": 0.3, "Z": 0.05}, 0, [])
    scales, decision = gap_diagnose._judge("model", ev, names, None, hot, [], timings, notes)
    assert calls == ["model"] and "discretisation_s" in timings and notes == []
    assert decision.outcome == "no_significant_gap" and scales.discretisation_sensor["T24"] == 0.4


def test_a_coarser_mesh_that_cannot_be_made_leaves_the_floor_out_and_says_why(monkeypatch):
    """The fits are done by then: a meshing failure must not throw them away, nor pass in silence."""
    from meshes.tomlspec import DefinitionError

    def fails(model, nominal, evaluator, engine):
        raise DefinitionError("machine.toml: meshing failed in pytetwild: no volume")

    monkeypatch.setattr(gap_diagnose, "discretisation_floor", fails)
    hot = _result("nominal", {"temperature": 0.07, "displacement": 0.05},
                  {"T01": 0.04, "T24": 0.3, "Z": 0.05}, 0, [])
    notes = []
    scales, decision = gap_diagnose._judge("model", _evaluator(), ["T01", "T24", "Z"], None, hot, [], {}, notes)
    assert decision.outcome == "not_explained" and scales.discretisation_sensor == {}
    assert notes == [("discretisation floor not measured (the verdict is judged without it): machine.toml: meshing "
                      "failed in pytetwild: no volume")]


@pytest.mark.slow
def test_a_dense_record_of_a_finer_mesh_without_an_effect_is_no_gap_and_names_the_sensor_the_mesh_limits():
    """gap_quick_8h sampled every 10 s from a 35 mm full-FE truth (the twin: a reduced model of the 45 mm mesh).

    Without the floor the verdict was 'not explained', T24 (the Z motor, beside the Z feed's heat) at 5.8 σ.
    """
    from twin.core.machine import build_machine
    from twin.core.scenario import load_scenario
    from twin.gap.truth import truth_dataset

    scenario = dataclasses.replace(load_scenario("gap_quick_8h"), sample_interval_s=10.0, time_step_s=10.0)
    record = truth_dataset(scenario, build_machine("vmc_ram", 0.035), seed=5)
    d = gap_diagnose.diagnose(record, gap_diagnose._machine("vmc_ram"), n_pairs=0, discovery=False)
    assert d.decision.outcome == "no_significant_gap", verdict.sentence(d)
    assert "T24" in verdict.mesh_limited(d.nominal, d.scales)
    assert "within the twin's discretisation floor only" in verdict.sentence(d)
