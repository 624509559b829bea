"""Unit errors in a measured record that the gap diagnosis must name, not diagnose: a spindle in krpm, feeds in
m/min, air in °F, time in ms, a dead probe, and a time column renamed by the column map."""
from types import SimpleNamespace

import numpy as np
import pytest

from twin.core.dataset import KIND_OF_UNIT, ChannelInfo, Dataset, split_column
from twin.errors import TwinInputError

MACHINE = SimpleNamespace(name="rig", max_spindle_rpm=12000.0, max_feed_mm_min=30000.0)
T = np.arange(241) * 120.0                      # 8 h every 2 min


def _steps(levels):
    """A held operating condition: ``levels`` one after the other, equal time each, over :data:`T`."""
    return np.repeat(np.asarray(levels, float), -(-len(T) // len(levels)))[:len(T)]


def _dataset(columns, time_s=T, source="rig.csv"):
    """A dataset of ``{column: values}`` (``<name>_<unit>`` columns) with ``source`` as its file."""
    channels = [ChannelInfo(*split_column(c), KIND_OF_UNIT[split_column(c)[1]]) for c in columns]
    return Dataset(time_s, np.column_stack(list(columns.values())), channels, {"source": source})


def _warning(column, values):
    from twin.gap.measured import check_operating_range

    data = _dataset({column: values})
    return check_operating_range(data, data.channels[0], values, MACHINE)


def test_a_spindle_in_krpm_is_warned_about_with_both_factors():
    """12000 rpm logged in krpm peaks at 12, exactly 0.1 % of the top speed: it had passed and the search beyond
    the library reported 10^5 W sources."""
    warning = _warning("spindle_rpm", _steps([0, 4.5, 9, 10, 12, 0]))
    assert warning is not None and "peaks at about 12 rpm" in warning
    assert "in Hz (rev/s), the speed is 720 rpm (× 60)" in warning and "in krpm, 12000 rpm (× 1000)" in warning
    assert _warning("spindle_rpm", _steps([0, 6, 0])) is not None          # 0.05 %: below the old Hz band


def test_a_spindle_at_rest_or_running_in_rpm_is_not_warned_about():
    noise = np.random.default_rng(1).uniform(-3.0, 3.0, len(T))            # a tachometer at standstill
    assert _warning("spindle_rpm", noise) is None
    assert _warning("spindle_rpm", np.zeros(len(T))) is None
    assert _warning("spindle_rpm", _steps([0, 4500, 9000, 12000])) is None


def test_feeds_in_m_min_are_warned_about():
    warning = _warning("feed_x_mm_min", _steps([0, 5, 0, 5]))
    assert warning is not None and "column 'feed_x_mm_min' peaks at about 5 mm/min" in warning
    assert "in m/min, the feed is 5000 mm/min (× 1000)" in warning
    assert _warning("feed_x_mm_min", _steps([0, 5000, 0, 30000])) is None
    assert _warning("feed_y_mm_min", np.zeros(len(T))) is None


@pytest.mark.parametrize("fahrenheit", [68.0, 64.0])
def test_air_in_fahrenheit_is_refused_in_one_line(fahrenheit):
    from twin.core.plausible import check_plausible

    values = np.full(len(T), fahrenheit)
    data = _dataset({"A_top_degC": values})
    with pytest.raises(TwinInputError) as err:
        check_plausible(data, data.channels[0], "air", values)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"rig.csv: column 'A_top_degC' has value {fahrenheit:g}")
    assert f"°F? (°F − 32)/1.8 = {(fahrenheit - 32) / 1.8:.2f} °C" in message
    check_plausible(data, data.channels[0], "air", np.full(len(T), 38.0))     # a hot hall passes


def test_cold_air_in_fahrenheit_is_refused_against_the_thermometers():
    """8 °C of air reads 46 in °F, inside the shop-air range: the surface thermometers at 8 °C give it away."""
    from twin.core.plausible import check_air_against_surfaces

    surfaces = [np.full(len(T), 8.0) + 0.1 * k for k in range(5)]
    with pytest.raises(TwinInputError, match=r"rig.csv: column 'A_top_degC' starts at 46.4 degC, .*°F\? "
                                             r"\(°F − 32\)/1.8 = 8.00 °C"):
        check_air_against_surfaces("rig.csv", [("A_top_degC", np.full(len(T), 46.4))], surfaces)
    warm = [s + 9.0 for s in surfaces]                                      # a warm machine in cool air
    check_air_against_surfaces("rig.csv", [("A_top_degC", np.full(len(T), 8.0))], warm)


def test_time_in_ms_gets_a_hint_and_no_grid_beyond_the_cap():
    """8 h every 2 min logged in ms span 333 "days" in steps of 33 "h"; the diagnosis had built a 480 000-step grid
    and grown to 8.7 GB."""
    from twin.core.dataset import ms_hint
    from twin.gap.diagnose import _check_grid_size

    data = _dataset({"T01_degC": np.full(len(T), 20.0)}, time_s=T * 1000.0)
    hint = ms_hint(data)
    assert hint is not None and "is the time in ms (÷ 1000 to s: 8 h in steps of 120 s)" in hint
    assert ms_hint(_dataset({"T01_degC": np.full(len(T), 20.0)})) is None
    week = np.arange(200) * 3600.0                                          # hourly for 8 days: no hint
    assert ms_hint(_dataset({"T01_degC": np.full(200, 20.0)}, time_s=week)) is None
    record = SimpleNamespace(time_s=T * 1000.0, report={"source": "rig.csv"},
                             metadata={"import": {"time_unit_hint": hint}})
    with pytest.raises(TwinInputError, match=r"rig.csv: the record spans 2.88e\+07 s .* 4.8e\+05 steps .* ms"):
        _check_grid_size(record, 60.0)
    _check_grid_size(SimpleNamespace(time_s=T, report={}, metadata={}), 60.0)


def test_a_dead_probe_is_named_as_a_dead_channel():
    from twin.gap.measured import Record, check_scale

    values = np.column_stack([np.full(len(T), 3.0)])
    record = Record(T, ["Z"], ["displacement"], values, None, {}, None, [], {"source": "rig.csv"})
    predicted = np.linspace(0.0, 50.0, len(T))[:, None]
    with pytest.raises(TwinInputError) as err:
        check_scale(record, predicted, {"Z": "Z_um"})
    assert str(err.value) == ("rig.csv: column 'Z_um' (Z) is constant at 3 um over the record where the nominal "
                              "twin predicts a range of 50 um: a dead channel? map it to null with --column-map "
                              "'{\"Z_um\": null}'")


def test_the_column_map_names_the_time_column(tmp_path):
    path = tmp_path / "foreign.csv"
    rows = "\n".join(f"{t:g},{20 + t / 1e4:g},{t / 1e3:g}" for t in T)
    path.write_text("Time,temp ram 1,Z drift\n" + rows + "\n")
    data = Dataset.from_measured_csv(path, column_map={"Time": "time_s", "temp ram 1": "T01_degC",
                                                       "Z drift": "Z_um"})
    np.testing.assert_array_equal(data.time_s, T)
    assert data.names == ["T01", "Z"]
    hours = tmp_path / "hours.csv"
    hours.write_text("time_h,T01_degC\n" + "\n".join(f"{k},20" for k in range(9)) + "\n")
    with pytest.raises(TwinInputError, match=r"column 'time_h' is the time column \(mapped to time_s\)"):
        Dataset.from_measured_csv(hours, column_map={"time_h": "time_s"})


def test_a_record_with_air_in_fahrenheit_is_refused_by_match_record():
    """The check runs where a measured record is matched to the machine (the air sensors by the machine's kinds)."""
    from twin.gap.diagnose import _machine
    from twin.gap.measured import match_record

    machine = _machine("vmc_ram")
    columns = {"spindle_rpm": _steps([0, 6000, 0]), "T01_degC": np.full(len(T), 8.2),
               "T02_degC": np.full(len(T), 8.0), "A_top_degC": np.full(len(T), 46.4)}
    with pytest.raises(TwinInputError, match=r"rig.csv: column 'A_top_degC' starts at 46.4 degC, the surface "):
        match_record(_dataset(columns), machine)
    columns["A_top_degC"] = np.full(len(T), 8.0)
    assert match_record(_dataset(columns), machine).report["unit_suspects"] == []
