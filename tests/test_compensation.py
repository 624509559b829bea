"""`twin train` / `twin evaluate` and the compensation-model store, on small synthetic datasets (no FE)."""
import json

import numpy as np
import pytest

from models.registry import model_names
from twin.cli import main
from twin.compensation.store import (
    CompensationModel,
    fit_compensation_model,
    make_estimator,
    parse_params,
)
from twin.compensation.train import evaluate, load_dataset, score, train
from twin.core.dataset import ChannelInfo, Dataset
from twin.errors import TwinInputError


def _record(seed=0, n=400, dt=30.0, offsets=(0.0, 0.0, 0.0), gain=1.0, label=None):
    """Three thermometers, an air sensor and a drift Z that is linear in the temperature changes."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    heat = 1 - np.exp(-t / (3000 + 500 * seed))
    wave = np.sin(2 * np.pi * t / (4000 + 300 * seed))
    T1 = 20 + 6 * gain * heat + 0.01 * rng.standard_normal(n)
    T2 = 20 + 2 * gain * heat + 0.8 * wave + 0.01 * rng.standard_normal(n)
    T3 = 20 + 0.5 * wave + 0.01 * rng.standard_normal(n)
    air = 20 + 0.5 * wave
    Z = -4.0 * (T1 - 20) + 2.5 * (T2 - 20) + 0.02 * rng.standard_normal(n)
    values = np.column_stack([T1 + offsets[0], T2 + offsets[1], T3 + offsets[2], air, Z + 3.0])
    channels = [ChannelInfo("T1", "degC", "temperature"), ChannelInfo("T2", "degC", "temperature"),
                ChannelInfo("T3", "degC", "temperature"), ChannelInfo("air", "degC", "air"),
                ChannelInfo("Z", "um", "displacement")]
    return Dataset(t, values, channels, {"kind": "synthetic", "scenario": label or f"rec{seed}"})


def test_train_save_load_predicts_identically(tmp_path):
    a, b = _record(0), _record(1)
    cm = train([a, b], "T1,T2,T3", "Z", model="mlr", out=tmp_path / "m.json")
    back = CompensationModel.load(tmp_path / "m.json")
    assert back.inputs == ["T1", "T2", "T3"] and back.target == "Z" and back.target_unit == "um"
    assert [t["label"] for t in back.training] == ["rec0", "rec1"]
    assert back.preprocessing["zero_reference"] is True
    c = _record(2)
    assert np.array_equal(back.predict(c), cm.predict(c))
    s = score(cm.target_values(c), cm.predict(c))
    assert s["improvement_percent"] > 95 and s["nse"] > 0.99


def test_constant_sensor_offsets_do_not_hurt():
    cm = fit_compensation_model([_record(0), _record(1)], ["T1", "T2", "T3"], "Z", "mlr")
    clean, shifted = _record(2), _record(2, offsets=(0.4, -0.3, 0.25))
    assert np.allclose(cm.predict(clean), cm.predict(shifted), atol=1e-9)
    raw = fit_compensation_model([_record(0), _record(1, offsets=(0.5, -0.5, 0.2))], ["T1", "T2", "T3"], "Z",
                                 "mlr", zero_reference=False)
    zeroed = fit_compensation_model([_record(0), _record(1, offsets=(0.5, -0.5, 0.2))], ["T1", "T2", "T3"], "Z",
                                    "mlr")
    err_raw = score(raw.target_values(clean), raw.predict(clean))["max_residual"]
    err_zero = score(zeroed.target_values(clean), zeroed.predict(clean))["max_residual"]
    assert err_zero < 0.5 * err_raw


def test_anfis_and_grey_models_train_and_round_trip(tmp_path):
    a = _record(0)
    for name in ("anfis", "gm0n", "gm1n"):
        cm = fit_compensation_model([a], ["T1", "T2"], "Z", name, {"epochs": 5} if name == "anfis" else None)
        cm.save(tmp_path / f"{name}.json")
        back = CompensationModel.load(tmp_path / f"{name}.json")
        b = _record(1)
        assert np.array_equal(back.predict(b), cm.predict(b))
        assert abs(cm.predict(b)[0]) < 1.0       # a change since the start: ~0 at the first row


def test_grey_model_resamples_other_sampling_and_refuses_several_records():
    cm = fit_compensation_model([_record(0, dt=30.0)], ["T1", "T2"], "Z", "gm0n")
    assert cm.sampling_interval_s == 30.0
    fine = _record(0, n=1200, dt=10.0)
    p = cm.predict(fine)
    s = score(cm.target_values(fine), p)
    assert s["improvement_percent"] > 80
    with pytest.raises(TwinInputError, match="one contiguous record"):
        fit_compensation_model([_record(0), _record(1)], ["T1"], "Z", "gm1n")


def test_clear_errors_list_what_is_available(tmp_path):
    a = _record(0)
    with pytest.raises(TwinInputError, match=r"lacks input channel\(s\) \['T9'\].*T1"):
        fit_compensation_model([a], ["T1", "T9"], "Z", "mlr")
    with pytest.raises(TwinInputError, match="unknown model 'svm'; available: .*'anfis'"):
        make_estimator("svm")
    with pytest.raises(TwinInputError, match="has no parameter"):
        make_estimator("anfis", {"n_rulez": 3})
    cm = fit_compensation_model([a], ["T1", "T2"], "Z", "mlr")
    other = a.select(["T1", "T3", "Z"])
    with pytest.raises(TwinInputError, match=r"lacks input channel\(s\) \['T2'\]"):
        evaluate(cm, [other])
    bad_unit = Dataset(a.time_s, a.values, [ChannelInfo("T1", "degC", "temperature"),
                                            ChannelInfo("T2", "K_m", "temperature")] + a.channels[2:])
    with pytest.raises(TwinInputError, match="units do not match: T2 is 'K_m'"):
        cm.predict(bad_unit)
    with pytest.raises(TwinInputError, match="neither a dataset file nor a scenario"):
        load_dataset("no_such_thing_42")
    assert parse_params(["n_rules=4", "init=grid", "step_size=0.02"]) == {"n_rules": 4, "init": "grid",
                                                                           "step_size": 0.02}


def _wide_record(n_rows, n_inputs=16, seed=0, speed_first=False):
    """``n_inputs`` random-walk thermometers T00.. and a drift Z, ``n_rows`` rows one minute apart (with
    ``speed_first``, T00 is a spindle speed in rpm, as the grey-box model takes it)."""
    rng = np.random.default_rng(seed)
    T = 20 + rng.standard_normal((n_rows, n_inputs)).cumsum(axis=0) * 0.1
    Z = (T - 20) @ rng.standard_normal(n_inputs)
    channels = [ChannelInfo(f"T{j:02d}", "degC", "temperature") for j in range(n_inputs)]
    if speed_first:   # from standstill, as the grey-box model takes a record's first row as rest
        channels[0] = ChannelInfo("T00", "rpm", "speed")
        T[:, 0] = np.abs(T[:, 0] - T[0, 0])
    return Dataset(np.arange(n_rows) * 60.0, np.column_stack([T, Z]),
                   channels + [ChannelInfo("Z", "um", "displacement")], {"kind": "synthetic", "scenario": "wide"})


WIDE_INPUTS = [f"T{j:02d}" for j in range(16)]


@pytest.mark.parametrize("model", sorted(set(model_names()) - {"pcr"}))
def test_every_model_refuses_more_parameters_than_rows(model):
    # 10 rows × 16 inputs: before, MLR "fitted" it with RMSE 1.5e-16 and 100 % improvement.
    # (PCR regresses on the 4 components that explain 85 % of the variance: 5 parameters, a real fit.)
    with pytest.raises(TwinInputError, match=r"cannot fit .* on 10 rows × 16 inputs: .*(parameters|rules)"):
        fit_compensation_model([_wide_record(10, speed_first=model == "greybox")], WIDE_INPUTS, "Z", model)


@pytest.mark.parametrize("model", sorted(set(model_names()) - {"greybox"}))   # greybox: its speed input, own tests
def test_every_model_trains_to_the_same_result_twice(model):
    # `twin train --model ago-anfis` used an unseeded FCM: two runs gave different models
    a, b = _record(0), _record(1)
    first, second = (fit_compensation_model([a], ["T1", "T2"], "Z", model) for _ in range(2))
    assert np.array_equal(first.predict(b), second.predict(b))


def test_bad_training_requests_are_refused(tmp_path, capsys):
    with pytest.raises(TwinInputError, match=r"'mlr' on 10 rows × 16 inputs: .*17 parameters .* at least 18 samples"):
        fit_compensation_model([_wide_record(10)], WIDE_INPUTS, "Z", "mlr")
    with pytest.raises(TwinInputError, match=r"2\*\*16 = 65,536 rules: use FCM .*--model anfis-fcm"):
        fit_compensation_model([_wide_record(400)], WIDE_INPUTS, "Z", "anfis-grid")
    a = _record(0)
    with pytest.raises(TwinInputError, match=r"input channel\(s\) \['T1'\] given more than once"):
        fit_compensation_model([a], ["T1", "T2", "T1"], "Z", "mlr")
    with pytest.raises(TwinInputError, match=r"reference_samples .* must be a whole number of rows, at least 1; got 0"):
        fit_compensation_model([a], ["T1", "T2"], "Z", "mlr", reference_samples=0)
    with pytest.raises(TwinInputError, match=r"rec0: reference_samples .* = 401 is more than the 400 rows"):
        fit_compensation_model([a], ["T1", "T2"], "Z", "mlr", reference_samples=401)
    # a model referenced on 50 rows cannot reference a 30-row record
    cm = fit_compensation_model([a], ["T1", "T2"], "Z", "mlr", reference_samples=50)
    with pytest.raises(TwinInputError, match=r"short: reference_samples .* = 50 is more than the 30 rows it has"):
        evaluate(cm, [_record(1, n=30, label="short")])
    # on the command line: one line naming the counts, exit code 2
    _wide_record(10).write(tmp_path / "ten.csv")
    common = ["train", str(tmp_path / "ten.csv"), "--target", "Z", "--model", "mlr", "--out", str(tmp_path / "m.json")]
    assert main(common + ["--inputs", ",".join(WIDE_INPUTS)]) == 2
    err = capsys.readouterr().err
    assert "10 rows × 16 inputs" in err and "17 parameters" in err and "Traceback" not in err
    assert main(common + ["--inputs", "T00,T01", "--reference-samples", "11"]) == 2
    assert "reference_samples (--reference-samples) = 11 is more than the 10 rows" in capsys.readouterr().err
    assert main(common + ["--inputs", "T00", "--inputs", "T00"]) == 2
    assert "['T00'] given more than once" in capsys.readouterr().err


def test_select_auto_on_one_speed_regime_is_one_clear_line(tmp_path, capsys):
    # before: the ValueError of the blocked cross-validation escaped as a traceback (exit 1)
    rec = _record(0)
    steady = Dataset(rec.time_s, np.column_stack([np.full(len(rec), 6000.0), rec.values]),
                     [ChannelInfo("spindle", "rpm", "speed"), *rec.channels], rec.metadata)
    steady.write(tmp_path / "steady.csv")
    code = main(["train", str(tmp_path / "steady.csv"), "--inputs", "spindle,T1,T2", "--target", "Z",
                 "--select", "auto", "--out", str(tmp_path / "m.json")])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "rec0: --select auto cannot cross-validate on this record: " in err
    assert "at least 2 operating-regime blocks, got 1" in err and not (tmp_path / "m.json").exists()


def test_incompatible_model_files_are_refused(tmp_path):
    cm = fit_compensation_model([_record(0)], ["T1", "T2"], "Z", "mlr")
    path = cm.save(tmp_path / "m.json")
    doc = json.loads(path.read_text())
    doc["version"] = 99
    (tmp_path / "future.json").write_text(json.dumps(doc))
    with pytest.raises(TwinInputError, match="version 99.*reads version 1 only"):
        CompensationModel.load(tmp_path / "future.json")
    from models import MLRRegressor, save_model

    save_model(MLRRegressor(), tmp_path / "bare.json")
    with pytest.raises(TwinInputError, match="bare models.save_model file"):
        CompensationModel.load(tmp_path / "bare.json")
    doc = json.loads(path.read_text())
    doc["estimator"]["version"] = 7
    (tmp_path / "inner.json").write_text(json.dumps(doc))
    with pytest.raises(TwinInputError, match="field 'estimator.version' = 7 was changed after the model was saved"):
        CompensationModel.load(tmp_path / "inner.json")
    (tmp_path / "junk.json").write_text("{not json")
    with pytest.raises(TwinInputError, match="not a JSON model file"):
        CompensationModel.load(tmp_path / "junk.json")


def test_a_dead_thermometer_the_model_does_not_read_leaves_every_row(tmp_path):
    a = _record(0)
    values = np.column_stack([a.time_s, a.values, np.full(len(a), np.nan)])
    header = "time_s," + ",".join(c.column for c in a.channels) + ",dead_degC"
    csv = tmp_path / "dead.csv"
    csv.write_text(header + "\n" + "\n".join(",".join("" if np.isnan(v) else f"{v:.6f}" for v in row)
                                              for row in values) + "\n")
    for policy in ("error", "drop", "interpolate"):
        cm = train([csv], "T1,T2", "Z", model="mlr", nan_policy=policy)
        assert cm.metadata["training_metrics"]["dead"]["rows"] == len(a)
    assert evaluate(cm, [csv], nan_policy="drop").rows[0]["rows"] == len(a)


def test_cli_train_on_measured_csv_and_evaluate(tmp_path, capsys):
    a, b = _record(0), _record(1)
    # a measured CSV with foreign column names, imported through a column map
    csv = tmp_path / "measured.csv"
    cols = ["t", "probe1", "probe2", "probe3", "room", "zdisp"]
    csv.write_text(",".join(cols) + "\n" + "\n".join(",".join(f"{v:.6f}" for v in row) for row in
                                                      np.column_stack([a.time_s, a.values])) + "\n")
    cmap = tmp_path / "map.json"
    cmap.write_text(json.dumps({"t": "time_s", "probe1": "T1_degC", "probe2": "T2_degC", "probe3": "T3_degC",
                                "room": "air_degC", "zdisp": "Z_um"}))
    b.write(tmp_path / "rec1.csv")
    model = tmp_path / "model.json"
    code = main(["train", str(csv), "--inputs", "T1,T2", "--inputs", "T3", "--target", "Z", "--model", "mlr",
                 "--out", str(model), "--column-map", str(cmap)])
    assert code == 0
    out = capsys.readouterr().out
    assert "mlr (MLRRegressor, static): T1, T2, T3 → Z [um]" in out and "model saved" in out
    code = main(["evaluate", str(model), str(tmp_path / "rec1.csv"), "--out", str(tmp_path / "ev")])
    assert code == 0
    out = capsys.readouterr().out
    assert "| rec1 |" in out
    assert (tmp_path / "ev" / "evaluation.md").exists() and (tmp_path / "ev" / "rec1_Z.png").stat().st_size > 5000
    rows = json.loads((tmp_path / "ev" / "evaluation.json").read_text())["rows"]
    assert rows[0]["improvement_percent"] > 90
    # labels whose file names would be one ("rec 1", "rec_1") keep a plot each; a flat record's undefined
    # correlation is null in the JSON files (NaN is not JSON)
    flat = Dataset(b.time_s, np.column_stack([b.values[:, :-1], np.zeros(len(b))]), b.channels,
                   {"scenario": "rec_1"})
    Dataset(b.time_s, b.values, b.channels, {"scenario": "rec 1"}).write(tmp_path / "rec 1.csv")
    flat.write(tmp_path / "rec_1.csv")
    flat_model = tmp_path / "flat.json"
    assert main(["train", str(tmp_path / "rec_1.csv"), "--inputs", "T1", "--target", "Z", "--model", "mlr",
                 "--out", str(flat_model)]) == 0
    assert main(["evaluate", str(model), str(tmp_path / "rec 1.csv"), str(tmp_path / "rec_1.csv"),
                 "--out", str(tmp_path / "ev2")]) == 0
    assert sorted(p.name for p in (tmp_path / "ev2").glob("*.png")) == ["rec_1_2_Z.png", "rec_1_Z.png"]
    strict = {"parse_constant": lambda word: pytest.fail(f"{word} in a JSON file")}
    assert json.loads(flat_model.read_text(), **strict)["metadata"]["training_metrics"]["rec_1"]["r"] is None
    assert json.loads((tmp_path / "ev2" / "evaluation.json").read_text(), **strict)["rows"][1]["r"] is None
    # errors are one line and exit code 2
    assert main(["train", str(tmp_path / "rec1.csv"), "--inputs", "T7", "--target", "Z", "--out",
                 str(tmp_path / "x.json")]) == 2
    assert "lacks input channel(s) ['T7']" in capsys.readouterr().err
    assert main(["train", str(tmp_path / "rec1.csv"), "--inputs", "T1", "--target", "Z", "--model", "xgb",
                 "--out", str(tmp_path / "x.json")]) == 2
    assert "unknown model 'xgb'" in capsys.readouterr().err
