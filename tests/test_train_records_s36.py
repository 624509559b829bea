"""Records that continue one another: an ambiguous join is refused, not guessed; `--reference train` refuses a
record that starts inside the training record."""
import json

import numpy as np
import pytest

from twin.cli import main

ROWS, STEP_S = 300, 60.0


def one_error_line(capsys):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def write_record(path, start_s, seed, rows=ROWS):
    """A measured record of ``rows`` rows every 60 s from ``start_s``: a warming thermometer and a drift."""
    rng = np.random.default_rng(seed)
    t = start_s + STEP_S * np.arange(rows)
    temp = 20.0 + 3.0 * (1.0 - np.exp(-(t - t[0]) / 3600.0)) + 0.05 * rng.standard_normal(rows) + seed
    drift = 4.0 * (temp - 20.0) + 0.1 * rng.standard_normal(rows)
    path.write_text("time_s,T01_degC,Z_um\n" + "".join(f"{a:g},{b:.5f},{c:.5f}\n" for a, b, c in zip(t, temp, drift)))
    return path


def train_args(*files, out):
    return ["train", *map(str, files), "--inputs", "T01", "--target", "Z", "--model", "mlr", "--out", str(out)]


def test_two_records_that_a_third_could_continue_are_refused(tmp_path, capsys):
    day1 = write_record(tmp_path / "day1.csv", 0.0, seed=1)
    restart = write_record(tmp_path / "restart.csv", 0.0, seed=2)              # its clock restarts at 0
    day2 = write_record(tmp_path / "day2.csv", ROWS * STEP_S, seed=3)           # one interval after both end
    for order in ([day1, restart, day2], [day2, restart, day1]):
        assert main(train_args(*order, out=tmp_path / "m.json")) == 2
        err = one_error_line(capsys)
        assert "day1.csv (0–17940 s)" in err and "restart.csv (0–17940 s)" in err and "day2.csv" in err
        assert "18000 s" in err and "ambiguous" in err and "one file" in err and "shift the clock" in err
    assert not (tmp_path / "m.json").exists()
    shifted = write_record(tmp_path / "restart.csv", 1e6, seed=2)                # the clock shifted: no doubt
    assert main(train_args(day1, shifted, day2, out=tmp_path / "m.json")) == 0
    labels = [t["label"] for t in json.loads((tmp_path / "m.json").read_text())["training"]]
    assert labels == ["day1 + day2", "restart"]


def test_two_records_that_could_each_continue_one_are_refused(tmp_path, capsys):
    day1 = write_record(tmp_path / "day1.csv", 0.0, seed=1)
    day2 = write_record(tmp_path / "day2.csv", ROWS * STEP_S, seed=3)
    other = write_record(tmp_path / "other.csv", ROWS * STEP_S, seed=4)        # starts where day2 does
    assert main(train_args(day1, day2, other, out=tmp_path / "m.json")) == 2
    err = one_error_line(capsys)
    assert "day2.csv (18000–35940 s)" in err and "other.csv (18000–35940 s)" in err
    assert "after day1.csv ends (t = 17940 s)" in err and "ambiguous" in err


@pytest.fixture
def trained(tmp_path):
    """A static model trained on rows 0–199 (0–11940 s) of a record, and that record's file."""
    whole = write_record(tmp_path / "whole.csv", 0.0, seed=1, rows=600)
    lines = whole.read_text().splitlines(keepends=True)
    training = tmp_path / "train.csv"
    training.write_text("".join(lines[:201]))
    assert main(train_args(training, out=tmp_path / "m.json")) == 0
    return tmp_path / "m.json", training, lines


def test_reference_train_refuses_a_record_that_starts_inside_the_training_record(trained, tmp_path, capsys):
    model, training, lines = trained
    overlap = tmp_path / "overlap.csv"
    overlap.write_text(lines[0] + "".join(lines[101:301]))                   # rows 100–299: 6000–17940 s
    for history in ([], ["--history", str(training)]):
        assert main(["evaluate", str(model), str(overlap), "--reference", "train", *history]) == 2
        err = one_error_line(capsys)
        assert "overlap.csv" in err and "6000 to 17940 s" in err and "train (0–11940 s)" in err
    after = tmp_path / "after.csv"
    after.write_text(lines[0] + "".join(lines[201:401]))                     # continues it: accepted
    assert main(["evaluate", str(model), str(after), "--reference", "train"]) == 0
    assert main(["evaluate", str(model), str(training), "--reference", "train"]) == 0   # a clock from its start



def write_stamped(path, first, rows, offset="", seed=1):
    """A measured record of ``rows`` rows every 60 s from the date-time ``first``, its stamps ending in ``offset``
    (``"+01:00"``, or ``""`` for none)."""
    import pandas as pd

    plain = write_record(path, 0.0, seed=seed, rows=rows).read_text().splitlines()
    stamps = pd.date_range(first, periods=rows, freq="60s")
    path.write_text("time_s,T01_degC,Z_um\n" + "".join(f"{t.isoformat(sep=' ')}{offset},{line.split(',', 1)[1]}\n"
                                                        for t, line in zip(stamps, plain[1:])))
    return path


def test_reference_train_refuses_stamps_with_and_without_offset(tmp_path, capsys):
    trained = write_stamped(tmp_path / "tr_tz.csv", "2026-03-02 08:00:00", 200, "+01:00")
    assert main(train_args(trained, out=tmp_path / "m_tz.json")) == 0
    naive = write_stamped(tmp_path / "ev_naive.csv", "2026-03-02 12:00:00", 200)
    assert main(["evaluate", str(tmp_path / "m_tz.json"), str(naive), "--reference", "train"]) == 2
    err = one_error_line(capsys)
    assert "ev_naive.csv" in err and "without a UTC offset" in err and "tr_tz" in err and "one clock" in err


def test_stamped_spans_are_date_times_and_several_records_name_history(tmp_path, capsys):
    first = write_stamped(tmp_path / "first.csv", "2026-03-02 08:00:00", 200)
    inside = write_stamped(tmp_path / "inside.csv", "2026-03-02 09:00:00", 200, seed=2)
    assert main(train_args(first, out=tmp_path / "one.json")) == 0
    assert main(["evaluate", str(tmp_path / "one.json"), str(inside), "--reference", "train"]) == 2
    err = one_error_line(capsys)
    assert "2026-03-02 09:00:00 to 2026-03-02 12:19:00" in err and "(2026-03-02 08:00:00–2026-03-02 11:19:00)" in err
    assert "--history" not in err
    later = write_stamped(tmp_path / "later.csv", "2026-03-09 08:00:00", 200, seed=3)
    assert main(train_args(first, later, out=tmp_path / "two.json")) == 0
    assert main(["evaluate", str(tmp_path / "two.json"), str(inside), "--reference", "train"]) == 2
    assert "first training record" in (err := one_error_line(capsys)) and "--history" in err
