"""A scenario's ambient CSV must cover the scenario, from its start (t = 0) to its duration: past the file's ends
the twin holds the first or last reading, so a day logged in hours or minutes under a ``time_s`` header (0…24,
0…1440), or a log timed from another origin, had been read as a room at one constant temperature.  No mesh."""
import numpy as np
import pytest

from meshes.tomlspec import DefinitionError
from twin.core.scenario import HOUR, load_scenario

DAY = """[scenario]
duration_h = 24
sample_interval_s = 600.0
"""


def _scenario(tmp_path, times, column="time_s", table=""):
    """A 24 h scenario whose ambient is ``air.csv``, its time column ``column`` holding ``times``."""
    rows = "".join(f"{t:g},{20.0 + 0.1 * k:g}\n" for k, t in enumerate(times))
    (tmp_path / "air.csv").write_text(f"{column},ambient_degC\n{rows}")
    path = tmp_path / "day.toml"
    path.write_text(DAY + f'[ambient]\nkind = "csv"\nfile = "air.csv"\n{table}')
    return path


def _error(path):
    with pytest.raises(DefinitionError) as excinfo:
        load_scenario(path)
    message = str(excinfo.value)
    assert "\n" not in message and message.startswith(f"{path}: ambient.file {path.parent / 'air.csv'}: ")
    return message


@pytest.mark.parametrize("times, unit", [(np.arange(25.0), "hours"), (np.arange(0.0, 1441.0, 60.0), "minutes")])
def test_a_day_logged_in_hours_or_minutes_is_refused(tmp_path, times, unit):
    message = _error(_scenario(tmp_path, times))
    assert f"column 'time_s' spans 0 … {times[-1]:g} s, short of the scenario's 86400 s (24 h)" in message
    assert f"the times look like {unit}" in message and "write them in s" in message


def test_a_file_that_ends_early_is_refused_without_a_unit_guess(tmp_path):
    message = _error(_scenario(tmp_path, np.arange(0.0, 20 * HOUR + 1, 600.0)))
    assert "column 'time_s' spans 0 … 72000 s, short of the scenario's 86400 s (24 h)" in message
    assert "look like" not in message


def test_the_time_column_named_in_the_scenario_is_the_one_named(tmp_path):
    path = _scenario(tmp_path, np.arange(25.0), column="t", table='time_column = "t"\n')
    assert "column 't' spans 0 … 24 s" in _error(path)


@pytest.mark.parametrize("times", [np.arange(8 * HOUR, 33 * HOUR, 600.0), np.arange(600.0, 24 * HOUR + 1, 600.0)])
def test_a_file_that_starts_after_the_scenario_is_refused(tmp_path, times):
    """Clock times (from 08:00: 28800 s) or a log begun late: the first reading had been held back to t = 0."""
    message = _error(_scenario(tmp_path, times))
    assert f"column 'time_s' starts at {times[0]:g} s, after the scenario's start (0 s)" in message
    assert f"subtract {times[0]:g} s" in message


def test_a_file_that_covers_the_scenario_is_read_as_it_is(tmp_path):
    times = np.arange(-HOUR, 25 * HOUR + 1, 600.0)             # readings before and after the scenario are kept
    scenario = load_scenario(_scenario(tmp_path, times))
    assert scenario.ambient(np.array([-HOUR, 0.0, 24 * HOUR])) == pytest.approx([20.0, 20.6, 35.0])
    load_scenario(_scenario(tmp_path, np.arange(0.0, 24 * HOUR + 1, 600.0)))      # exactly 0 … duration
