"""The co-simulation example runs (fast mode), writes its plot and compensates most of the drift."""
import importlib.util
from pathlib import Path

import numpy as np

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "cosim_compensation.py"


def test_cosim_compensation_example_fast(tmp_path):
    spec = importlib.util.spec_from_file_location("cosim_compensation", EXAMPLE)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    res = example.main(["--fast", "--out", str(tmp_path)])
    png = Path(res["png"])
    assert png.exists() and png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"
    drift, residual = res["drift_um"], res["residual_um"]
    assert np.abs(drift[:, 2]).max() > 5.0                      # the spindle heats the machine
    rms = lambda a: np.sqrt(np.mean(a ** 2))
    assert rms(residual[:, 2]) < 0.2 * rms(drift[:, 2])         # compensation removes most of it
    assert len(res["time_h"]) == 121
    # --fmu: the zones come from the FMU itself, so a given FMU drives the same loop (no hard-coded zones)
    again = example.main(["--fast", "--out", str(tmp_path / "given"), "--fmu", str(res["fmu"])])
    np.testing.assert_array_equal(again["drift_um"], drift)
    assert example.measured_zones(res["fmu"]) == ["front", "room"]
