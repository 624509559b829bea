"""Shared fixtures: the location of the shared measured recording, the default machine and its ROM."""
import os
from pathlib import Path

import pytest

FL_THERMAL_DIR = Path(os.environ.get("THERMAL_TWIN_FL_THERMAL")
                      or Path(__file__).resolve().parents[1].parent / "shared" / "data" / "fl_thermal")


# session scope: a path only, and module-scoped fixtures (a loaded recording) build on it
@pytest.fixture(scope="session")
def fl_thermal_csv():
    """Path to the FL_THERMAL recording (read from ../shared, never copied); skips when absent."""
    path = FL_THERMAL_DIR / "fl_thermal_part1.csv"
    if not path.exists():
        pytest.skip(f"FL_THERMAL data not found at {path}")
    return path


# Module scope, as before: each test module gets its own objects, so one module
# that changes them cannot affect another.  twin is imported only when asked
# for, so the models-only tests do not pay for it.
@pytest.fixture(scope="module")
def machine():
    """The twin of the default machine, ``vmc_ram`` (from the mesh and matrix caches)."""
    from twin.core.machine import build_machine

    return build_machine("vmc_ram")


@pytest.fixture(scope="module")
def rom(machine):
    """The reduced-order model of :func:`machine` at the default order (from the ROM cache)."""
    from twin.rom.reduction import DEFAULT_ORDER, cached_rom

    return cached_rom(machine, DEFAULT_ORDER)


def pytest_configure(config):
    # Two pytest workers share two cores: threaded BLAS inside each would only oversubscribe.
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
