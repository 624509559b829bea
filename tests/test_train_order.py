"""`twin train` gives one model whatever the order, names or folders of its record files.

The fit is not blind to the order of the stacked rows (the seeded FCM start of ANFIS, the random start of an ANN,
the rolling-origin folds of ``--select auto``, the first record's start kept as the training reference), so the
records are fitted in the canonical order of :mod:`twin.compensation.record_order`: first time stamp, then
content. On the code before it, each test here gives two different models (or a refusal) for two orders.
"""
import json
from itertools import permutations

import numpy as np
import pytest

from twin.cli import main
from twin.compensation.train import evaluate, train
from twin.core.dataset import ChannelInfo, Dataset
from twin.errors import TwinInputError

CHANNELS = [ChannelInfo("spindle", "rpm", "spindle_speed"), ChannelInfo("T1", "degC", "temperature"),
            ChannelInfo("T2", "degC", "temperature"), ChannelInfo("air", "degC", "air"),
            ChannelInfo("Z", "um", "displacement")]


def _day(levels, label, seed, start_s=0.0, hours=12, dt=120.0):
    """A record from rest: 1 h stops, each followed by 2 h at a speed of ``levels`` (rpm), two thermometers that lag
    the spindle heat (first order, 40 and 90 min), a room wave, and a drift Z linear in their changes (µm)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, hours * 3600.0, dt)
    phase = (t // (3 * 3600.0)).astype(int)
    speed = np.where((t % (3 * 3600.0) >= 3600.0) & (phase < len(levels)),
                     np.take(levels, np.minimum(phase, len(levels) - 1)), 0.0)
    heat = (speed / 6000.0) ** 1.5
    T1, T2 = np.zeros_like(t), np.zeros_like(t)
    for k in range(1, len(t)):
        T1[k] = T1[k - 1] + dt / 2400.0 * (6.0 * heat[k - 1] - T1[k - 1])
        T2[k] = T2[k - 1] + dt / 5400.0 * (3.0 * heat[k - 1] - T2[k - 1])
    air = 20.0 + 0.4 * np.sin(2 * np.pi * (t + 3600.0 * seed) / 86400.0)
    Z = -4.0 * T1 + 2.5 * T2 + 1.5 * (air - 20.0) + 0.05 * rng.standard_normal(len(t))
    values = np.column_stack([speed, 20.0 + T1 + 0.01 * rng.standard_normal(len(t)),
                              20.0 + T2 + 0.01 * rng.standard_normal(len(t)), air, Z])
    return Dataset(start_s + t, values, CHANNELS, {"kind": "synthetic", "scenario": label})


@pytest.fixture(scope="module")
def days():
    return [_day([3000.0, 6000.0], "day a", 1), _day([1500.0, 4500.0, 2500.0], "day b", 2),
            _day([5000.0], "day c", 3, hours=8)]


def _fitted(cm):
    """The model file's content that the fit decides: estimator, channels, preprocessing, metrics by record."""
    doc = cm.to_document()
    return json.dumps({k: doc[k] for k in ("model_name", "estimator", "inputs", "target", "preprocessing")},
                      sort_keys=True, default=str), cm.metadata["training_metrics"]


@pytest.mark.parametrize("model", ["anfis", "ann", "mlr"])
def test_every_order_of_the_records_trains_the_same_model(days, model):
    models = [_fitted(train(list(order), "T1,T2,air", "Z", model=model)) for order in permutations(days)]
    assert all(fit == models[0][0] for fit, _ in models)
    # the same metrics per record, listed in one order
    assert all(list(metrics.items()) == list(models[0][1].items()) for _, metrics in models)


def test_the_canonical_order_is_by_start_then_content(days):
    from twin.compensation.record_order import in_canonical_order   # here: the code before it has none

    names = ["T1", "T2", "air", "Z"]
    later = Dataset(days[2].time_s + 1e5, days[2].values, CHANNELS, {"scenario": "day c, later"})
    for order in permutations([*days, later]):
        ordered = in_canonical_order(list(order), names)
        assert ordered[-1] is later            # the latest start last, whatever its content
        assert ordered == in_canonical_order([*days, later], names)
    cm = train(days, "T1,T2,air", "Z", model="mlr")
    assert list(cm.metadata["training_metrics"]) == [ds.metadata["scenario"] for ds in in_canonical_order(days, names)]


def test_select_auto_chooses_and_scores_alike_in_every_order(days):
    first, reverse = (train(list(order), "spindle,T1,air", "Z", select="auto").metadata["selection"]
                      for order in (days, days[::-1]))
    for key in ("chosen", "trained", "ranking", "geometric_mean_rmse", "folds", "fold_rmse"):
        assert first[key] == reverse[key], key
    # blocks are numbered across the records: each fold names the record that holds its test block
    assert all(name.endswith(("(day a)", "(day b)", "(day c)")) for name in first["folds"])


def test_renamed_and_moved_files_given_in_another_order_train_the_same_model(days, tmp_path, capsys):
    here, there = tmp_path / "here", tmp_path / "elsewhere" / "renamed"
    here.mkdir()
    there.mkdir(parents=True)
    originals = [here / f"{k}.csv" for k in "abc"]
    moved = [there / f"zz_{k}.csv" for k in "cba"]      # renamed so that the name order is reversed too
    day_of = {}
    for k, (ds, a, b) in enumerate(zip(days, originals, moved[::-1])):
        for path in (a, b):     # measured CSVs: no sidecar, so each goes by its file name
            ds.write(path).with_suffix(".csv.json").unlink()
            day_of[str(path)] = k
    models = []
    for paths, out in ((originals, "m1.json"), (moved, "m2.json")):
        code = main(["train", *map(str, paths), "--inputs", "T1,T2,air", "--target", "Z", "--model", "anfis",
                     "--out", str(tmp_path / out)])
        assert code == 0, capsys.readouterr().err
        models.append(json.loads((tmp_path / out).read_text()))
    assert models[0]["estimator"] == models[1]["estimator"]
    assert models[0]["preprocessing"] == models[1]["preprocessing"]
    assert list(models[0]["metadata"]["training_metrics"].values()) == list(models[1]["metadata"]["training_metrics"].values())
    # each record keeps its own file and name, in the order of its content, not of the names
    order = [[day_of[t["source"]] for t in m["training"]] for m in models]
    assert order[0] == order[1]
    assert [t["label"] for t in models[1]["training"]] == [f"zz_{'abc'[k]}" for k in order[1]]


def test_a_record_cut_into_files_joins_whichever_file_comes_first(days, caplog):
    whole = days[1]
    cut = len(whole) // 2
    part = lambda rows, label: Dataset(whole.time_s[rows], whole.matrix(whole.names)[rows], CHANNELS,
                                       {"kind": "synthetic", "scenario": label})
    first, second = part(slice(0, cut), "day 1"), part(slice(cut, None), "day 2")
    with caplog.at_level("INFO", logger="thermal_twin"):
        backwards = train([second, days[0], first], "spindle,T1,air", "Z", model="greybox")
    assert "day 2 continues day 1: trained on as one record" in caplog.text
    forwards = train([first, second, days[0]], "spindle,T1,air", "Z", model="greybox")
    assert [t["label"] for t in backwards.training] == [t["label"] for t in forwards.training]
    assert "day 1 + day 2" in [t["label"] for t in backwards.training]
    np.testing.assert_array_equal(backwards.predict(whole), forwards.predict(whole))


def test_a_file_that_repeats_rows_of_another_is_refused_in_either_order(days):
    whole = days[0]
    part = lambda rows, label: Dataset(whole.time_s[rows], whole.matrix(whole.names)[rows], CHANNELS,
                                       {"kind": "synthetic", "scenario": label})
    first, overlapping = part(slice(0, 200), "day 1"), part(slice(199, None), "day 2")
    for order in ([first, overlapping], [overlapping, first]):
        with pytest.raises(TwinInputError, match=r"day 2 starts with a row of day 1 again \(t = 23880 s, the same "
                                                 r"readings\)"):
            train(order, "T1,air", "Z", model="mlr")


def test_a_repeated_label_goes_to_the_same_record_in_either_order(days):
    same_name = [Dataset(ds.time_s, ds.values, CHANNELS, {"kind": "measured", "source": f"/{folder}/run.csv"})
                 for ds, folder in zip(days[:2], ("monday", "tuesday"))]
    labels = [[(t["label"], t["source"]) for t in train(order, "T1,T2,air", "Z", model="mlr").training]
              for order in (same_name, same_name[::-1])]
    assert labels[0] == labels[1]
    assert [label for label, _ in labels[0]] == ["run", "run_2"]


def test_the_content_digest_ignores_names_and_sees_every_reading(days):
    from twin.compensation.record_order import content_digest

    ds = days[0]
    names = ["T1", "air", "Z"]
    renamed = Dataset(ds.time_s, ds.values, CHANNELS, {"kind": "measured", "source": "/elsewhere/other.csv"})
    assert content_digest(renamed, names) == content_digest(ds, names)
    touched = ds.values.copy()
    touched[-1, 1] += 1e-9
    assert content_digest(Dataset(ds.time_s, touched, CHANNELS, {}), names) != content_digest(ds, names)
    # a channel the model does not read is no part of its content
    spare = ds.values.copy()
    spare[:, 2] += 1.0
    assert content_digest(Dataset(ds.time_s, spare, CHANNELS, {}), names) == content_digest(ds, names)


def test_evaluate_scores_each_record_alike_in_any_order(days):
    cm = train(days[:2], "T1,T2,air", "Z", model="mlr")
    rows = [{r["dataset"]: r for r in evaluate(cm, list(order)).rows} for order in permutations(days)]
    assert all(r == rows[0] for r in rows)
