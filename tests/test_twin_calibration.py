"""The default machine meets the thesis calibration ranges (docs/calibration.md)."""
import pytest

from twin.core.machine import build_machine
from twin.run.calibration import TARGETS, calibration_table


@pytest.fixture(scope="module")
def rows():
    return calibration_table(build_machine("vmc_ram"))


@pytest.mark.parametrize("index", range(len(TARGETS)), ids=[t.name for t in TARGETS])
def test_calibration_target_met(rows, index):
    target, value, ok = rows[index]
    assert ok, f"{target.name}: simulated {value:.1f} µm outside {target.low}–{target.high} µm"
