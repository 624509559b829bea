"""End to end on the default machine: physical sanity of synthetic runs, CLI outputs, atomic results."""
import json

import numpy as np
import pytest

from twin.cli import main
from twin.core.dataset import Dataset
from twin.core.scenario import load_scenario
from twin.core.simulate import record_channel_names, simulate
from twin.run.summary import format_summary, run_summary


def _scenario(tmp_path, body, name="probe"):
    path = tmp_path / f"{name}.toml"
    path.write_text(body)
    return load_scenario(path)


def test_drift_grows_while_heating_and_relaxes_after(machine, tmp_path):
    sc = _scenario(tmp_path, """
[scenario]
sample_interval_s = 120.0
time_step_s = 120.0
[ambient]
kind = "constant"
temperature_C = 20.0
[[segments]]
duration_h = 2
spindle_rpm = 9000
[[segments]]
duration_h = 2
spindle_rpm = 0
""")
    ds = simulate(sc, machine, noise=False).dataset
    t, z = ds.time_s, ds["Z"]
    heating = t <= 7200
    magnitude = np.abs(z)
    assert np.all(np.diff(magnitude[heating]) > 0), "drift must grow monotonically while the spindle runs"
    assert magnitude[heating][-1] > 10.0                          # µm: a real, not a numerical, response
    assert magnitude[-1] < 0.7 * magnitude[heating][-1], "drift must relax after the spindle stops"
    hottest = max(ds.names_of_kind("temperature"), key=lambda n: ds[n].max())
    assert np.argmax(ds[hottest]) == np.flatnonzero(heating)[-1]  # hottest at the moment the spindle stops
    assert ds.metadata["energy_balance_relative_error"] < 1e-8
    # the channels a study checks its --inputs against before simulating are the record's, in its order
    assert record_channel_names(machine) == ds.names
    cameras = [c.name for c in machine.channels if c.kind == "camera"]
    assert [n for n in record_channel_names(machine, camera=True) if n not in cameras] == ds.names


def test_ambient_sine_gives_drift_at_the_same_period(machine, tmp_path):
    sc = _scenario(tmp_path, """
[scenario]
duration_h = 96
sample_interval_s = 600.0
time_step_s = 600.0
[initial]
kind = "steady"
[ambient]
kind = "sinusoid"
mean_C = 20.0
amplitude_K = 2.5
period_h = 12
""")
    ds = simulate(sc, machine, noise=False).dataset
    keep = (ds.time_s >= 48 * 3600) & (ds.time_s < 96 * 3600)    # two whole periods past the transient
    z = ds["Z"][keep] - ds["Z"][keep].mean()
    spectrum = np.abs(np.fft.rfft(z))
    freq = np.fft.rfftfreq(len(z), d=600.0)
    assert abs(freq[np.argmax(spectrum[1:]) + 1] - 1 / (12 * 3600)) < 1e-9
    assert np.ptp(z) > 2.0                                       # µm for a ±2.5 K swing
    assert ds.metadata["energy_balance_relative_error"] < 1e-8


def test_same_seed_same_noise(machine):
    a = simulate("heat_cool_9000", machine).dataset
    b = simulate("heat_cool_9000", machine).dataset
    c = simulate("heat_cool_9000", machine, seed=99).dataset
    assert np.array_equal(a.values, b.values)
    assert not np.array_equal(a["T01"], c["T01"])
    clean = simulate("heat_cool_9000", machine, noise=False).dataset
    offsets = a["T01"] - clean["T01"]
    assert np.abs(offsets).max() <= 0.5 + 0.0625 / 2 + 1e-9      # DS18S20: ±0.5 °C + half a step
    assert np.allclose(a["T01"] / 0.0625, np.round(a["T01"] / 0.0625))


def test_cli_run_writes_dataset_plots_and_summary(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "heat_cool_9000", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "peak drift" in printed and "hottest sensor" in printed
    for name in ("heat_cool_9000.csv", "heat_cool_9000.csv.json", "drift.png", "temperatures.png",
                 "summary.md", "summary.json"):
        assert (out / name).exists(), name
    ds = Dataset.read(out / "heat_cool_9000.csv")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["run_seconds"] > 0 and "- run time: " in (out / "summary.md").read_text()
    change = ds["Z"] - ds["Z"][0]                                   # ISO 230-3: the change since the first reading
    assert summary["drift"]["Z"]["peak_um"] == pytest.approx(change[np.argmax(np.abs(change))])
    assert "Z_um" in (out / "heat_cool_9000.csv").read_text().splitlines()[0]


def test_interrupted_run_leaves_nothing_that_looks_complete(tmp_path, monkeypatch):
    import twin.run.workflows as workflows

    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(workflows.plots, "plot_drift", interrupt)   # dies after the dataset was written
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        workflows.run_scenario("heat_cool_9000", out_dir=out)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args, message", [
    (["run", "no_such_scenario"], "unknown scenario 'no_such_scenario'"),
    (["run", "heat_cool_9000", "--machine", "no_such_machine"], "unknown machine 'no_such_machine'"),
    (["mesh", "no_such_machine"], "unknown machine 'no_such_machine'"),
])
def test_cli_bad_input_is_one_clear_line(args, message, capsys):
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_reported_time_step_is_the_one_taken(machine, tmp_path):
    """A 70 s limit on a 300 s sampling interval gives five equal 60 s steps: the metadata and the summary
    say 60 s, and the run equals one with 60 s asked for."""
    body = """
[scenario]
duration_h = 1
sample_interval_s = 300
time_step_s = {step}
[ambient]
kind = "constant"
temperature_C = 20.0
[[segments]]
duration_h = 1
spindle_rpm = 6000
"""
    runs = {step: simulate(_scenario(tmp_path, body.format(step=step), f"dt{step}"), machine, noise=False,
                           step_error=False).dataset for step in (70, 60)}
    meta = runs[70].metadata
    assert (meta["time_step_s"], meta["time_step_limit_s"]) == (60.0, 70.0)
    assert np.array_equal(runs[70]["Z"], runs[60]["Z"])
    assert "60 s steps (time_step_s = 70 s is a limit" in format_summary(run_summary(runs[70], 1.0))
