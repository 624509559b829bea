"""Shared fixtures: the location of the shared measured recording, and a throwaway cache."""
import os
from pathlib import Path

import pytest

FL_THERMAL_DIR = Path(os.environ.get("THERMAL_TWIN_FL_THERMAL")
                      or Path(__file__).resolve().parents[1].parent / "shared" / "data" / "fl_thermal")


@pytest.fixture
def fl_thermal_csv():
    """Path to the FL_THERMAL recording (read from ../shared, never copied); skips when absent."""
    path = FL_THERMAL_DIR / "fl_thermal_part1.csv"
    if not path.exists():
        pytest.skip(f"FL_THERMAL data not found at {path}")
    return path


def pytest_configure(config):
    # Two pytest workers share two cores: threaded BLAS inside each would only oversubscribe.
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
