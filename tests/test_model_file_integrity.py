"""A compensation-model file edited after `twin train` saved it is refused in one line naming the file, the field
and the value; `twin evaluate` warns of a model saved unstable and of a speed far above the training ones.

`twin train` stores a SHA-256 per field (`field_sha256`, `twin.compensation.integrity`); a file written before
the digests is read with a warning, and what the estimator cannot hold (`GreyBoxRegressor.check_fitted`,
`models.persistence`) is refused whether the file has digests or not.
"""
import json

import numpy as np
import pytest
from test_models_greybox import ambient, duty, simulate

from models.greybox import GreyBoxRegressor
from twin.cli import main
from twin.compensation.integrity import FIELD
from twin.compensation.store import CompensationModel
from twin.compensation.train import evaluate, train
from twin.core.dataset import ChannelInfo, Dataset
from twin.errors import TwinInputError

CHANNELS = [ChannelInfo("spindle", "rpm", "speed"), ChannelInfo("air", "degC", "air"),
            ChannelInfo("Z", "um", "displacement")]


def _record(levels, label, hours=16):
    """The two-node network of ``tests/test_models_greybox.py`` from rest, 4 h stops and runs at ``levels``."""
    times = np.arange(0.0, hours * 3600.0, 120.0)
    speed = duty(times, list(levels), 4 * 3600.0)
    return Dataset(times, np.column_stack([speed, ambient(times), simulate(times, speed)[1]]), CHANNELS,
                   {"kind": "synthetic", "scenario": label})


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """``(path, document)`` of a grey-box model trained on 1500 and 3000 rpm."""
    path = tmp_path_factory.mktemp("model") / "m.json"
    train([_record((1500.0, 3000.0), "train")], "spindle,air", "Z", model="greybox", params={"n_poles": 1}, out=path)
    return path, json.loads(path.read_text())


def _edited(saved, tmp_path, edit, name="edited.json"):
    doc = json.loads(json.dumps(saved[1]))
    edit(doc)
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def _set(*keys, value):
    """An edit that sets ``doc[keys...] = value``."""
    def edit(doc):
        for key in keys[:-1]:
            doc = doc[key]
        doc[keys[-1]] = value
    return edit


def test_a_saved_model_carries_a_digest_per_field_and_reads_back_reformatted(saved, tmp_path, caplog):
    path, doc = saved
    digests = doc[FIELD]
    for name in ("model_name", "inputs", "preprocessing.zero_reference", "metadata.training_top_speed_rpm",
                 "estimator.class", "estimator.params.n_poles", "estimator.learned.gains_"):
        assert len(digests[name]) == 64
    again = tmp_path / "again.json"
    again.write_text(json.dumps(doc, indent=4, sort_keys=True))   # another layout, the same values
    record = _record((2000.0,), "test", hours=10)
    with caplog.at_level("WARNING", logger="thermal_twin"):
        np.testing.assert_array_equal(CompensationModel.load(again).predict(record),
                                      CompensationModel.load(path).predict(record))
    assert not caplog.text


def _offset_plus_one(doc):
    doc["estimator"]["learned"]["offset_"]["__ndarray__"]["data"][0] += 1.0


@pytest.mark.parametrize("edit, message", [
    (_set("preprocessing", "zero_reference", value="yes"), "field 'preprocessing.zero_reference' = \"yes\" was changed"),
    (_set("inputs", value=["air", "spindle"]), "field 'inputs' = [\"air\",\"spindle\"] was changed"),
    (_set("estimator", "params", "speed_reference", value=500.0),
     "field 'estimator.params.speed_reference' = 500.0 was changed"),
    (_offset_plus_one, "field 'estimator.learned.offset_' = {\"__ndarray__\":"),
    (lambda doc: doc.pop("training"), "field 'training' was removed"),
    (_set("metadata", "note", value="retuned"), "field 'metadata.note' = \"retuned\" was added"),
    (_set("metadata", "training_top_speed_rpm", "spindle", value=12000.0),
     "field 'metadata.training_top_speed_rpm' = {\"spindle\":12000.0} was changed"),
    # values the estimator cannot even read: the digest names them before the estimator chokes on them
    (_set("estimator", "params", "speed_reference", value=None),
     "field 'estimator.params.speed_reference' = null was changed"),
    (_set("estimator", "params", "process_noise", value=[1]), "field 'estimator.params.process_noise' = [1] was"),
])
def test_a_field_changed_after_saving_is_refused_naming_it(saved, tmp_path, edit, message):
    path = _edited(saved, tmp_path, edit)
    with pytest.raises(TwinInputError) as info:
        CompensationModel.load(path)
    text = str(info.value)
    assert text.startswith(f"{path}: {message}") and "after the model was saved" in text
    assert text.endswith("train again or restore the file")


def test_twin_evaluate_refuses_an_edited_file_in_one_line(saved, tmp_path, capsys):
    path = _edited(saved, tmp_path, _offset_plus_one)
    _record((2000.0,), "test", hours=10).write(tmp_path / "test.csv")
    assert main(["evaluate", str(path), str(tmp_path / "test.csv")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert f"{path}: field 'estimator.learned.offset_'" in err


def _learned(name, value):
    return _set("estimator", "learned", name, value=value)


def _array(name, data, shape):
    return _learned(name, {"__ndarray__": {"dtype": "<f8", "shape": shape, "data": data}})


def _unsealed(edit):
    def both(doc):
        doc.pop(FIELD, None)
        edit(doc)
    return both


@pytest.mark.parametrize("edit, message", [
    (_learned("exponent_", "1.6"), r"learned attribute 'exponent_' is '1.6', expected a finite number > 0"),
    (lambda doc: doc["estimator"]["learned"].pop("offset_"), r"learned attribute 'offset_' is missing"),
    (_array("gains_", [float("nan"), 1.0], [1, 1, 2]),
     r"learned attribute 'gains_' is \[\[\[nan, 1.0\]\]\], expected finite numbers"),
    (_array("gains_", [1.0, 2.0, 3.0], [1, 1, 2]), r"field 'learned.gains_' has value .*cannot reshape array"),
    (_array("gains_", [1.0, 2.0], [1, 2, 1]), r"learned attribute 'gains_' has shape \(1, 2, 1\), but n_poles = 1"),
    (_array("poles_", [1.0 / 5400.0], [1]), r"learned attribute 'poles_' is \[0.000185.*\] 1/s; a pole >= 0"),
    (_array("time_constants_", [-5400.0], [1]),
     r"learned attribute 'time_constants_' is \[-5400.0\] s; a time constant must be > 0 s"),
    (_array("time_constants_", [0.0], [1]), r"'time_constants_' is \[0.0\] s; a time constant must be > 0 s"),
    (_array("time_constants_", [5400.0], [1]),
     r"learned attribute 'poles_' is .* but time_constants_ \[5400.0\] s make them"),
    (_set("estimator", "params", "n_poles", value=2),
     r"learned attribute 'time_constants_' has shape \(1,\), but n_poles = 2"),
    (_set("estimator", "params", "colour", value="red"),
     r"field 'params.colour' has value \"red\", but GreyBoxRegressor has no parameter 'colour'"),
    (_set("preprocessing", "zero_reference", value="yes"),
     r"field 'preprocessing.zero_reference' has value \"yes\", expected true or false"),
    (_set("preprocessing", "rest_start", value=1), r"field 'preprocessing.rest_start' has value 1, expected true"),
    (_set("estimator", "params", "speed_reference", value=None), r"\[estimator\]: float\(\) argument must be"),
])
def test_a_value_no_fit_gives_is_refused_in_a_file_without_digests(saved, tmp_path, edit, message):
    path = _edited(saved, tmp_path, _unsealed(edit))
    with pytest.raises(TwinInputError, match=message) as info:
        CompensationModel.load(path)
    assert str(info.value).startswith(str(path))


def test_a_file_without_digests_is_read_with_a_warning(saved, tmp_path, caplog):
    path = _edited(saved, tmp_path, lambda doc: doc.pop(FIELD, None), "old.json")
    with caplog.at_level("WARNING", logger="thermal_twin"):
        CompensationModel.load(path)
    assert f"{path}: written without field digests ({FIELD}; project version" in caplog.text


def test_the_greybox_checks_its_learned_attributes_before_it_predicts():
    times = np.arange(0.0, 16 * 3600.0, 120.0)
    speed = duty(times, [1500.0, 3000.0], 4 * 3600.0)
    X = np.column_stack([times, speed, ambient(times)])
    model = GreyBoxRegressor(n_poles=1).fit(X, simulate(times, speed)[1])
    model.poles_ = -model.poles_
    with pytest.raises(ValueError, match=r"learned attribute 'poles_' is \[.*\] 1/s; a pole >= 0 is an unstable"):
        model.predict(X)


def test_evaluate_warns_of_a_speed_far_above_the_training_ones(saved, caplog):
    path, doc = saved
    assert doc["metadata"]["training_top_speed_rpm"] == {"spindle": 3000.0}
    with caplog.at_level("WARNING", logger="thermal_twin"):
        evaluate(path, [_record((4500.0,), "faster", hours=10)])   # 1.5×: within the factor
    assert "over 2×" not in caplog.text
    with caplog.at_level("WARNING", logger="thermal_twin"):
        evaluate(path, [_record((9000.0,), "in rpm", hours=10)])
    assert ("in rpm: spindle runs up to 9000 rpm, over 2× the top speed of the training records (3000 rpm): the "
            "model extrapolates") in caplog.text


def _growing(n=300):
    """A drift that grows exponentially while the temperature oscillates: GM(1,N) identifies a < 0."""
    t = np.arange(n) * 60.0
    return Dataset(t, np.column_stack([20 + np.sin(t / 3000.0), np.expm1(t / 9000.0)]),
                   [ChannelInfo("T1", "degC", "temperature"), ChannelInfo("Z", "um", "displacement")],
                   {"kind": "synthetic", "scenario": "growing"})


def test_evaluate_warns_of_a_model_saved_unstable(tmp_path, capsys):
    _growing().write(tmp_path / "growing.csv")
    path = tmp_path / "gm.json"
    train([_growing()], "T1", "Z", model="gm1n", out=path, allow_unstable=True)
    assert main(["evaluate", str(path), str(tmp_path / "growing.csv")]) == 0
    err = capsys.readouterr().err
    assert (f"{path}: saved with --allow-unstable although its check refused it (UNSTABLE: gm1n: development "
            "coefficient a = ") in err
