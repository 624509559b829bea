"""Dataset contract: exact round trip, atomic sidecar, measured-data import and its validation."""
import json

import numpy as np
import pytest

from twin.core.dataset import ChannelInfo, Dataset, name_listing, sidecar_path
from twin.errors import TwinInputError


def _dataset(n=50, seed=0):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.5, 2.0, n))
    values = rng.normal(size=(n, 3)) * np.array([1.0, 1e-7, 1e5])  # awkward magnitudes
    channels = [ChannelInfo("T01", "degC", "temperature", "strip", (0.1, 0.2, 0.3)),
                ChannelInfo("Z", "um", "displacement", "drift"),
                ChannelInfo("spindle", "rpm", "spindle_speed")]
    return Dataset(t, values, channels, {"machine": "m", "seed": 3})


def test_round_trip_is_exact(tmp_path):
    ds = _dataset()
    path = ds.write(tmp_path / "run.csv")
    back = Dataset.read(path)
    assert np.array_equal(back.time_s, ds.time_s)
    assert np.array_equal(back.values, ds.values)          # bit for bit, not approximately
    assert back.channels == ds.channels
    assert back.metadata == ds.metadata
    header = path.read_text().splitlines()[0]
    assert header == "time_s,T01_degC,Z_um,spindle_rpm"


def test_edited_csv_is_detected(tmp_path):
    path = _dataset().write(tmp_path / "run.csv")
    text = path.read_text().replace("\n", "\n", 1)
    path.write_text(text + "0,0,0,0\n")
    with pytest.raises(TwinInputError, match="does not match its sidecar"):
        Dataset.read(path)


def test_no_partial_files_left(tmp_path):
    _dataset().write(tmp_path / "run.csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv", "run.csv.json"]
    meta = json.loads(sidecar_path(tmp_path / "run.csv").read_text())
    assert meta["format"] == "thermal-twin-dataset" and meta["version"] == 1


def test_unknown_channel_lists_available():
    with pytest.raises(TwinInputError, match=r"unknown channel 'T99'.*T01"):
        _dataset()["T99"]


def _write(tmp_path, text, name="m.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_measured_import_and_gap_report(tmp_path):
    path = _write(tmp_path, "time_s,T01_degC,X_um\n0,20,0\n10,20.5,1\n20,21,2\n60,22,3\n70,22.5,4\n")
    ds = Dataset.from_measured_csv(path)
    assert ds.info("T01").kind == "temperature" and ds.info("X").unit == "um"
    report = ds.metadata["import"]
    assert report["sampling_interval_s"] == 10.0
    assert report["n_gaps"] == 1 and report["gaps"][0] == {"after_s": 20.0, "length_s": 40.0}


def test_measured_column_map(tmp_path):
    path = _write(tmp_path, "t,temp1,disp\n0,20,0\n1,21,1\n")
    ds = Dataset.from_measured_csv(path, column_map={"temp1": "T01_degC", "disp": "Z_um"}, time_column="t")
    assert ds.names == ["T01", "Z"]


def test_measured_nan_policies(tmp_path):
    path = _write(tmp_path, "time_s,T01_degC,Z_um\n0,20,0\n1,,1\n2,22,nan\n3,23,3\n")
    with pytest.raises(TwinInputError, match=r"T01_degC.*t = 1\.0 s"):
        Dataset.from_measured_csv(path)
    filled = Dataset.from_measured_csv(path, nan_policy="interpolate")
    assert filled["T01"][1] == pytest.approx(21.0) and filled["Z"][2] == pytest.approx(2.0)
    dropped = Dataset.from_measured_csv(path, nan_policy="drop")
    assert list(dropped.time_s) == [0.0, 3.0]
    assert dropped.metadata["import"]["dropped_rows"] == 2


@pytest.mark.parametrize("text, message", [
    ("time_s,T01_degC\n0,20\n5,21\n3,22\n", r"must increase strictly.*3\.0 s after 5\.0 s"),
    ("time_s,T01_degC\n0,20\n1,abc\n", r"'abc' is not a number"),
    ("time_s,temperature\n0,20\n", r"'temperature' is not named <name>_<unit>"),
    ("t,T01_degC\n0,20\n", r"no time column 'time_s'"),
    ("time_s,T01_degC\n", r"no data rows"),
    # pandas renames a repeated header to T01_degC.1: the message named that, not the repetition
    ("time_s,T01_degC,Z_um,T01_degC\n0,20,1,21\n", r"column 'T01_degC' appears 2 times \(columns 2, 4\); give each"),
    # the map's example named another channel (Z_mm → T01_degC); a map renames, it cannot convert mm
    ("time_s,Z_mm\n0,0.001\n", r"e.g. \{'Z_mm': 'Z_<unit>'\} \(a map renames, it does not convert"),
    # a spreadsheet's export with ';' (and decimal commas) read as one column: "'0,0;20,5' is not a number"
    ("time_s;T01_degC\n0,0;20,5\n", r"the header 'time_s;T01_degC' is separated by ';'; the twin reads comma"),
    ("time_s\tT01_degC\n0\t20.5\n", r"is separated by '\\t'"),
])
def test_measured_bad_input(tmp_path, text, message):
    with pytest.raises(TwinInputError, match=message):
        Dataset.from_measured_csv(_write(tmp_path, text))


@pytest.mark.parametrize("stamps, seconds, origin", [
    (["2026-11-23 23:59:50", "2026-11-24T00:00:05.5", "2026-11-24 00:00:20"], [0.0, 15.5, 30.0],
     "2026-11-23T23:59:50"),
    # the end of summer time in Central Europe: the wall clock repeats 02:00-03:00, the offsets say so
    (["2026-10-25T02:59:50+02:00", "2026-10-25T02:00:00+01:00", "2026-10-25T01:00:10Z"], [0.0, 10.0, 20.0],
     "2026-10-25T00:59:50+00:00"),
])
def test_a_loggers_date_time_stamps_are_seconds_since_the_first(tmp_path, stamps, seconds, origin):
    path = _write(tmp_path, "stamp,T01_degC\n" + "".join(f"{s},{20 + k}\n" for k, s in enumerate(stamps)))
    ds = Dataset.from_measured_csv(path, time_column="stamp")
    assert list(ds.time_s) == seconds and list(ds["T01"]) == [20.0, 21.0, 22.0]
    assert ds.metadata["import"]["time_origin"] == origin


@pytest.mark.parametrize("stamps, message", [
    (["2026-10-25 02:59:50", "2026-10-25 02:00:00"], (r"row 2 has 2026-10-25 02:00:00 after 2026-10-25 02:59:50 "
                                                     r"\(a clock set back, such as a daylight-saving change\?")),
    (["2026-10-25T02:59:50+02:00", "2026-10-25T02:00:00"], r"data row 2: '2026-10-25T02:00:00' has no UTC offset"),
    (["23.11.2026 14:05", "23.11.2026 14:06"], (r"data row 1: '23.11.2026 14:05' is neither a number \(s\) nor "
                                                r"an ISO 8601 date-time")),
    (["0", "abc"], r"data row 2: 'abc' is not a number"),           # the first stamp decides: s
    (["2026-11-23 14:05:00", ""], r"stamp is empty or NaN at data row 2"),
])
def test_bad_date_time_stamps_are_named(tmp_path, stamps, message):
    path = _write(tmp_path, "stamp,T01_degC\n" + "".join(f"{s},20\n" for s in stamps))
    with pytest.raises(TwinInputError, match=message):
        Dataset.from_measured_csv(path, time_column="stamp")


def test_the_nan_policy_is_about_the_channels_a_model_reads(tmp_path):
    """A dead thermometer that nothing reads drops no row and needs no policy; one that is read is refused or
    dropped as before, and dropping every row is named."""
    path = _write(tmp_path, "time_s,T01_degC,T02_degC,Z_um\n0,20,,0\n15,21,,1\n30,,,2\n45,23,,3\n")
    kept = Dataset.from_measured_csv(path, nan_policy="drop", nan_channels=["T01", "Z"])
    assert len(kept) == 3 and np.isnan(kept["T02"]).all()
    assert len(Dataset.from_measured_csv(path, nan_channels=["Z"])) == 4   # "error", and nothing read is missing
    with pytest.raises(TwinInputError, match=r"column 'T01_degC' is NaN/empty at t = 30.0 s .* 1 NaNs in 1 column"):
        Dataset.from_measured_csv(path, nan_channels=["T01", "Z"])
    with pytest.raises(TwinInputError, match="every row has a NaN in T02; nan_policy='drop' leaves none"):
        Dataset.from_measured_csv(path, nan_policy="drop", nan_channels=["T02", "Z"])


def test_a_csv_that_is_not_utf8_is_named(tmp_path):
    path = tmp_path / "ansi.csv"
    path.write_bytes("time_s,T01_degC\n0,20\n15,21 °C\n".encode("cp1252"))
    with pytest.raises(TwinInputError, match=r"ansi.csv: not UTF-8 text \(byte 0xb0 at offset 27\); save the CSV "
                                             "as UTF-8"):
        Dataset.from_measured_csv(path)


def test_real_recording_imports(fl_thermal_csv):
    ds = Dataset.from_measured_csv(fl_thermal_csv)
    assert len(ds) == 7711 and ds.info("t1").kind == "temperature" and ds.info("ch3").unit == "um"
    assert ds.metadata["import"]["n_gaps"] == 0


SPARE = "time_s,T01_degC,T_spare_degC,Z_um\n0,20.0,1372,0.0\n60,20.5,1372,1.0\n120,21.0,1372,2.0\n"


def test_an_open_thermocouple_stops_only_what_reads_it(tmp_path):
    """A spare type K thermocouple left open reads 1372 °C: refused when read, not when nothing reads it."""
    path = _write(tmp_path, SPARE)
    with pytest.raises(TwinInputError, match=r"'T_spare_degC' has value 1372 .* map its column to null"):
        Dataset.from_measured_csv(path)
    kept = Dataset.from_measured_csv(path, nan_channels=["T01", "Z"])        # what a model of T01 → Z reads
    assert list(kept["T_spare"]) == [1372.0] * 3
    with pytest.raises(TwinInputError, match="'T_spare_degC' has value 1372"):
        Dataset.from_measured_csv(path, nan_channels=["T_spare", "Z"])


def test_a_column_mapped_to_null_is_left_out(tmp_path):
    ds = Dataset.from_measured_csv(_write(tmp_path, SPARE), column_map={"T_spare_degC": None})
    assert ds.names == ["T01", "Z"]


def test_training_on_a_file_with_an_open_spare_thermocouple(tmp_path, capsys):
    from twin.cli import main

    path = _write(tmp_path, SPARE.replace("120,21.0,1372,2.0\n", "".join(
        f"{60 * k},{20 + 0.5 * k},1372,{1.0 * k}\n" for k in range(2, 40))))
    args = ["train", str(path), "--inputs", "T01", "--target", "Z", "--model", "mlr"]
    assert main([*args, "--out", str(tmp_path / "m.json")]) == 0
    assert main(["report", str(path), "--out", str(tmp_path / "r")]) == 2
    assert "map its column to null" in capsys.readouterr().err
    assert main(["report", str(path), "--column-map", '{"T_spare_degC": null}', "--out", str(tmp_path / "r")]) == 0


def test_a_message_lists_channels_with_numbered_runs_shortened():
    """A simulated record has 525 camera spots: a message names the run, not every spot."""
    names = ["spindle", *[f"T{i:02d}" for i in range(1, 15)], "T16", *[f"cam{i:03d}" for i in range(525)],
             "X", "T15", "T16", "T17"]
    assert name_listing(names) == "spindle,T01…T14,T16,cam000…cam524,X,T15,T16,T17"
    # a gap, another digit count or another prefix ends a run
    assert name_listing(["T1", "T2", "T3", "T5", "T6", "T7", "T8"]) == "T1,T2,T3,T5…T8"
    assert name_listing(["T8", "T9", "T10", "T11"]) == "T8,T9,T10,T11"
    ds = Dataset(np.arange(3.0), np.zeros((3, 600)), [ChannelInfo(f"cam{i:03d}", "degC", "temperature")
                                                      for i in range(600)])
    with pytest.raises(TwinInputError, match=r"^unknown channel 'cam600'; available: cam000…cam599$"):
        ds.index("cam600")
