"""The dataset figures show every sensor, tell lines apart, name every unit, and put the ambient beside the drift."""
import re

import matplotlib.pyplot as plt
import numpy as np
import pytest

from twin.core.dataset import ChannelInfo, Dataset
from twin.infra import plots

HOURS = np.linspace(0.0, 6.0, 61)


def _dataset(ambient=True):
    """25 surface thermometers (two labelled strips of 7 and 11 single ones), 4 air thermometers,
    zone ambients, spindle speed and four drift channels: the shape of a default-machine run."""
    rng = np.random.default_rng(0)
    channels, columns = [], []

    def add(name, unit, kind, label="", values=None):
        channels.append(ChannelInfo(name, unit, kind, label))
        columns.append(values if values is not None else 20 + rng.normal(size=HOURS.size).cumsum() * 0.05)

    for strip in (1, 2):
        for j in range(7):
            add(f"T{7 * (strip - 1) + j + 1:02d}", "degC", "temperature", f"carrier strip {strip} (B{j + 1})")
    for j in range(11):
        add(f"T{15 + j:02d}", "degC", "temperature", f"single sensor {j}")
    for j in range(4):
        add(f"A{j}", "degC", "air", f"air {j}")
    if ambient:
        add("ambient_enclosure", "degC", "ambient", "ambient of zone enclosure (true)", 20 + 0.5 * np.sin(HOURS))
        add("ambient_room", "degC", "ambient", "ambient of zone room (true)", 20 + np.sin(HOURS))
        add("ambient_front", "degC", "ambient", "ambient of zone front (true)", 20 + np.sin(HOURS))
    add("spindle", "rpm", "spindle_speed", "spindle speed", np.where(HOURS < 3, 9000.0, 0.0))
    for axis in ("X", "Y", "Z", "Y_top"):
        add(axis, "um", "displacement", f"TCP drift {axis}")
    return Dataset(HOURS * 3600, np.column_stack(columns), channels, {"scenario": "synthetic"})


def _units_named(fig):
    for ax in fig.axes:
        for label in (ax.get_xlabel(), ax.get_ylabel()):
            if label:
                assert re.search(r"\((°C|µm|rpm|h)\)$", label), f"axis label without a unit: {label!r}"


def test_every_thermometer_is_shown_once_with_its_own_line_style():
    ds = _dataset()
    fig = plots.temperature_figure(ds)
    try:
        shown = []
        for ax in fig.axes:
            lines = ax.get_lines()
            styles = [(line.get_color(), line.get_linestyle()) for line in lines]
            assert len(set(styles)) == len(styles), f"panel {ax.get_title()!r} repeats a colour"
            legend = [t.get_text() for t in ax.get_legend().get_texts()]
            assert len(legend) == len(lines)
            shown += [text.split()[0] for text in legend]
            for line in lines:        # each line is the data of the channel its legend names
                name = line.get_label().split()[0]
                np.testing.assert_array_equal(line.get_ydata(), ds[name])
        expected = ds.names_of_kind("temperature") + ds.names_of_kind("air")
        assert sorted(shown) == sorted(expected) and len(shown) == 29
        titles = [ax.get_title(loc="left") for ax in fig.axes]
        assert titles[:2] == ["carrier strip 1", "carrier strip 2"] and titles[-1] == "air thermometers"
        _units_named(fig)
    finally:
        plt.close(fig)


@pytest.mark.parametrize("ambient", [True, False])
def test_drift_figure_has_the_ambient_on_a_second_axis_in_degrees(ambient):
    ds = _dataset(ambient)
    fig = plots.drift_figure(ds)
    try:
        celsius = [ax for ax in fig.axes if ax.get_ylabel().endswith("(°C)")]
        assert len(celsius) == 1
        traced = {line.get_label().split()[0]: line.get_ydata() for line in celsius[0].get_lines()}
        # the room zone, plus the zones that differ from it; without zone ambients, the air thermometers
        expected = ["ambient_room", "ambient_enclosure"] if ambient else ["A0", "A1", "A2", "A3"]
        assert list(traced) == expected
        for name, values in traced.items():
            np.testing.assert_array_equal(values, ds[name])
        drift = [ax for ax in fig.axes if ax.get_ylabel().endswith("(µm)")]
        assert len(drift) == 1 and len(drift[0].get_lines()) == 4
        assert any(ax.get_ylabel() == "spindle speed (rpm)" for ax in fig.axes)
        _units_named(fig)
    finally:
        plt.close(fig)
