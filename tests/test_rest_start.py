"""A twin record whose duty cycle starts at t = 0: the state before it is a rest state models can start from.

The truth here is the FE twin itself: a grey-box model trained on one spindle
record must predict another with a different duty pattern, and a static model
with the speed as an input must see the speed change at the start.
"""
import numpy as np
import pytest

from twin.compensation.records import with_rest_start
from twin.compensation.train import evaluate, train
from twin.core.scenario import load_scenario
from twin.core.simulate import simulate

DUTY = """
[scenario]
sample_interval_s = 120.0
time_step_s = 120.0
[ambient]
kind = "constant"
temperature_C = 20.0
{segments}
"""


def _record(machine, tmp_path, name, blocks):
    segments = "".join(f"[[segments]]\nduration_h = {h}\nspindle_rpm = {rpm}\n" for h, rpm in blocks)
    path = tmp_path / f"{name}.toml"
    path.write_text(DUTY.format(segments=segments))
    return simulate(load_scenario(path), machine, noise=False).dataset


@pytest.fixture(scope="module")
def records(machine, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("duty")
    return (_record(machine, tmp, "train", [(2, 6000), (1.5, 0), (1.5, 9000), (2, 0)]),
            _record(machine, tmp, "test", [(1, 12000), (1, 3000), (2, 0)]))


def test_a_twin_record_says_what_stood_before_its_start_and_gets_it_as_a_first_row(records):
    ds = records[0]
    before = ds.metadata["before_start"]
    assert before["spindle"] == 0.0 and ds["spindle"][0] == 6000.0
    assert all(before[f"feed_{a}"] == 0.0 for a in "xyz")
    assert all(value == 0.0 for name, value in before.items() if name.startswith("P_"))
    rest = with_rest_start(ds, ["spindle", "T05", "Z"])
    assert len(rest) == len(ds) + 1 and rest.time_s[0] == ds.time_s[0] - 120.0
    assert rest["spindle"][0] == 0.0 and rest["P_front_bearings"][0] == 0.0
    np.testing.assert_array_equal(rest.values[1:], ds.values)
    np.testing.assert_array_equal(rest.matrix(["T05", "Z", "ambient_room"])[0], ds.matrix(["T05", "Z", "ambient_room"])[0])
    assert with_rest_start(rest) is rest                      # added once
    # a model on temperatures reads nothing that changes at the start: the record as it is
    assert with_rest_start(ds, ["T05", "T06", "Z"]) is ds
    # a window that leaves out the start is not a start
    assert "before_start" not in ds.between(600.0).metadata
    assert with_rest_start(ds.between(600.0)) .time_s[0] == 600.0


def test_the_grey_box_trains_on_a_twin_spindle_record_and_predicts_another_duty(records, tmp_path):
    training, test = records
    cm = train([training], "spindle,T05", "Z", "greybox", out=tmp_path / "gb.json")
    result = evaluate(cm, [test])
    row = result.rows[0]
    assert row["uncompensated_max"] > 10.0                 # µm: the test's drift is real
    assert row["rmse"] < 0.05 * row["uncompensated_max"], row


def test_a_static_model_sees_the_speed_change_at_the_start(records):
    """MLR on the speed and a thermometer: with the first row as reference the speed read 0 change during the
    whole first block (the old behaviour); from the rest row it reads the speed."""
    training, test = records
    cm = train([training], "spindle,T05", "Z", "mlr")
    assert cm.training[0]["reference"]["inputs"][0] == 0.0       # the speed at the reference: stopped
    features = cm.features(with_rest_start(test, cm.inputs + [cm.target]))
    assert features[1, 0] == 12000.0


def test_a_model_file_written_before_rest_starts_reads_records_as_it_was_trained(records):
    """Its speed reference was the first row's: evaluating it from the rest row would change its predictions."""
    training, test = records
    cm = train([training], "spindle,T05", "Z", "mlr")
    assert cm.preprocessing["rest_start"] is True
    new = evaluate(cm, [test]).rows[0]
    del cm.preprocessing["rest_start"]                       # as in a file written before
    old = evaluate(cm, [test]).rows[0]
    assert (new["rows"], old["rows"]) == (len(test) + 1, len(test))


def test_averaging_the_reference_over_a_rest_row_and_running_rows_is_refused(records):
    from twin.errors import TwinInputError

    with pytest.raises(TwinInputError, match=r"^train: the record's spindle changes at its first row .* "
                                             r"--reference-samples 3 would average it with running rows; use "
                                             r"--reference-samples 1$"):
        train([records[0]], "spindle,T05", "Z", "mlr", reference_samples=3)
    train([records[0]], "T05,T06", "Z", "mlr", reference_samples=3)     # a model on temperatures: no rest row


def test_reference_train_takes_a_record_from_zero_as_a_restarted_clock_after_a_rest_row(records, tmp_path):
    """The rest row sits one interval before a twin record's start (−120 s here), where no clock read: a record
    whose clock starts at 0 again had been refused as starting inside the training record (−120 … 28680 s)."""
    training, test = records
    model = train([training], "spindle,T05", "Z", model="mlr", out=tmp_path / "m.json")
    assert model.training[0]["time_span_s"][0] == training.time_s[0] == 0.0
    evaluation = evaluate(model, [test], reference="train", plots=False)
    assert len(evaluation.rows) == 1
