"""The twin as a drift predictor, and the cross-condition, thesis-protocol and hybrid studies (short records)."""
import json

import numpy as np
import pytest

from twin.compensation.studies import cross_condition_study, hybrid_study, select_inputs
from twin.compensation.train import physics_prediction
from twin.core.dataset import ChannelInfo, Dataset
from twin.core.simulate import simulate
from twin.core.variants import MachineSpec

RECORD = """
[scenario]
name = "{name}"
sample_interval_s = 300.0
time_step_s = 300.0
[ambient]
kind = "piecewise"
times_h = [0, 6]
values_C = [20.0, {end_C}]
[[segments]]
duration_h = {h1}
spindle_rpm = {rpm1}
[[segments]]
duration_h = 1.5
spindle_rpm = {rpm2}
[[segments]]
duration_h = 1
spindle_rpm = 0
"""


def records(folder):
    spec = {"c_heat": (20.0, 2, 9000, 0), "c_steps": (20.0, 1, 4000, 8000), "c_room": (22.0, 1, 2000, 0),
            "c_test": (19.0, 1.5, 6000, 10000)}
    out = {}
    for name, (end, h1, r1, r2) in spec.items():
        path = folder / f"{name}.toml"
        path.write_text(RECORD.format(name=name, end_C=end, h1=h1, rpm1=r1, rpm2=r2))
        out[name] = str(path)
    return out


def test_physics_prediction_reproduces_the_twin_from_operating_channels(machine, tmp_path):
    path = records(tmp_path)["c_steps"]
    ds = simulate(path, machine, noise=False).dataset
    pred = physics_prediction(machine, ds, ("Z", "Y"))
    assert np.allclose(pred["Z"], ds["Z"], atol=1e-6) and np.allclose(pred["Y"], ds["Y"], atol=1e-6)
    # a record with one air thermometer instead of the zone ambients drives every zone with it
    from twin.core.dataset import ChannelInfo, Dataset

    air = Dataset(ds.time_s, np.column_stack([ds["spindle"], ds["ambient_room"]]),
                  [ChannelInfo("spindle", "rpm", "spindle_speed"), ChannelInfo("room_air", "degC", "air")])
    assert np.allclose(physics_prediction(machine, air, ("Z",))["Z"], ds["Z"], atol=1e-6)
    with pytest.raises(Exception, match="needs a 'spindle' channel"):
        physics_prediction(machine, ds.select(["Z", "T01"]))


def test_cross_condition_study_writes_the_transfer_matrix(machine, tmp_path):
    r = records(tmp_path)
    fams = {"heat": (r["c_heat"],), "steps": (r["c_steps"],), "room": (r["c_room"],)}
    res = cross_condition_study(families=fams, axes=("Z",), model="mlr", k=3, scheduler="serial",
                                out_dir=tmp_path / "cc", log=None)
    M = np.array(res.data["matrices"]["Z"])
    assert M.shape == (3, 3) and np.isfinite(M).all()
    assert np.mean(np.diag(M)) > np.mean(M[~np.eye(3, dtype=bool)])   # the training family fits best
    text = (tmp_path / "cc" / "cross-condition.md").read_text()
    assert "| train \\ test | heat | steps | room |" in text
    assert (tmp_path / "cc" / "transfer_matrix.png").stat().st_size > 10000
    assert len(json.loads((tmp_path / "cc" / "cross-condition.json").read_text())["tables"]["transfer"]) == 9


def test_hybrid_beats_physics_alone_when_the_twin_is_wrong(machine, tmp_path):
    r = records(tmp_path)
    gap = {"source_scale": (("front_bearings", 1.4), ("spindle_motor", 0.7)), "convection_scale": 0.8}
    res = hybrid_study(train=(r["c_heat"], r["c_steps"], r["c_room"]), test=(r["c_test"],), axes=("Z",),
                       model="mlr", k=3, gap=gap, scheduler="serial", out_dir=tmp_path / "hy", log=None)
    pooled = {row["approach"].split(" ")[0]: row for row in res.tables["hybrid_pooled"]}
    assert pooled["physics"]["max_residual"] > 1.0                      # the gap is visible
    assert pooled["hybrid"]["max_residual"] < pooled["physics"]["max_residual"]
    text = (tmp_path / "hy" / "hybrid.md").read_text()
    assert "front_bearings ×1.4" in text and "convection coefficient ×0.8" in text
    assert (tmp_path / "hy" / "hybrid_heldout.png").exists()
    # the perturbed machine really is different from the nominal one
    assert MachineSpec("vmc_ram", None, gap["source_scale"], 0.8).perturbed


def test_a_thermometer_that_never_moves_is_no_candidate_input():
    """A sensor stuck at one DS18S20 step through a short record carries nothing (and training refuses it)."""
    t = np.arange(0.0, 3600.0, 60.0)
    warming = 20.0 + 2.0 * (1.0 - np.exp(-t / 900.0))
    values = np.column_stack([warming, np.full_like(t, 20.25), 20.0 + 0.001 * t, 3.0 * (warming - 20.0)])
    channels = [ChannelInfo(name, "degC", "temperature") for name in ("T01", "T02", "T03")] + [
        ChannelInfo("Z", "um", "displacement")]
    record = Dataset(t, values, channels, {"scenario": "short"})
    assert sorted(select_inputs([record], "Z", k=3)) == ["T01", "T03"]
