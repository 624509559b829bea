"""Figures of a dataset with units on every axis: temperatures, drift, strains (PNG, matplotlib Agg)."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..core.dataset import UNITS, Dataset  # noqa: E402

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _hours(dataset):
    return dataset.time_s / 3600.0


def save_figure(fig: Figure, path: str | Path) -> Path:
    """Save a Matplotlib figure as PNG atomically and close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or Path
        The PNG file (written atomically).

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    fig.tight_layout()
    tmp = path.with_name(f".{path.stem}.partial.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)
    return path


#: At most this many lines share one panel, so each has its own colour (the tab10 cycle has ten).
PANEL_LINES = 8


def _stem(label):
    """The group a sensor label names: ``carrier strip 1 (B1)`` → ``carrier strip 1``."""
    return label.split(" (")[0].strip()


def _chunks(names, size):
    """``names`` in the fewest runs of at most ``size``, as even in length as possible."""
    n = -(-len(names) // size)
    return [list(part) for part in np.array_split(np.array(names, dtype=object), n)] if names else []


def temperature_panels(dataset: Dataset, max_lines: int = PANEL_LINES) -> list[tuple[str, list[str]]]:
    """Panels of the temperature figure as ``(title, [channel names])``; every thermometer is in exactly one.

    Surface thermometers whose labels share a stem (``carrier strip 1 (B1)``,
    ``(B2)`` …) get panels of their own; the others share "other
    thermometers" panels; air thermometers come last.  No panel holds more
    than ``max_lines`` lines.

    Parameters
    ----------
    dataset : Dataset
        The data.
    max_lines : int
        Most lines in one panel.

    Returns
    -------
    list of tuple
        ``(panel title, channel names)``.
    """
    surface = dataset.names_of_kind("temperature")
    stems = {}
    for name in surface:
        stems.setdefault(_stem(dataset.info(name).label) or name, []).append(name)
    panels, others = [], []
    for stem, names in stems.items():
        if len(names) > 1:
            panels += [(stem, chunk) for chunk in _chunks(names, max_lines)]
        else:
            others += names
    panels += [("other thermometers", chunk) for chunk in _chunks(others, max_lines)]
    panels += [("air thermometers", chunk) for chunk in _chunks(dataset.names_of_kind("air"), max_lines)]
    return panels


def _legend_label(dataset, name, panel_title):
    label = dataset.info(name).label
    if label.startswith(panel_title + " ("):      # the panel title already says the stem
        label = label[len(panel_title) + 1:]
    return f"{name} {label}".strip()


def temperature_figure(dataset: Dataset, max_lines: int = PANEL_LINES) -> Figure | None:
    """Every surface and air thermometer (°C) over time (h), grouped in panels with a legend each.

    Parameters
    ----------
    dataset : Dataset
        The data.
    max_lines : int
        Most lines in one panel.

    Returns
    -------
    matplotlib.figure.Figure or None
        None without thermometers.
    """
    panels = temperature_panels(dataset, max_lines)
    if not panels:
        return None
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 1.0 + 2.3 * len(panels)), sharex=True, squeeze=False)
    hours = _hours(dataset)
    for ax, (title, names) in zip(axes[:, 0], panels):
        for k, name in enumerate(names):
            ax.plot(hours, dataset[name], lw=1.1, color=f"C{k}", label=_legend_label(dataset, name, title))
        ax.set_title(title, fontsize=9, loc="left")
        ax.set_ylabel(f"temperature ({UNITS['degC']})", fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    axes[-1, 0].set_xlabel("time (h)")
    fig.suptitle(f"Temperatures — {dataset.metadata.get('scenario', '')}")
    return fig


def plot_temperatures(dataset: Dataset, path: str | Path, max_lines: int = PANEL_LINES) -> Path | None:
    """:func:`temperature_figure` saved as PNG.

    Parameters
    ----------
    dataset : Dataset
        The data.
    path : str or Path
        The PNG file (written atomically).
    max_lines : int
        Most lines in one panel.

    Returns
    -------
    Path or None
        ``path``; None, and no file, without thermometers.
    """
    fig = temperature_figure(dataset, max_lines)
    return None if fig is None else save_figure(fig, path)


def _ambient_channels(dataset):
    """The room ambient (and other zones' ambients where they differ from it), else the air thermometers."""
    ambients = dataset.names_of_kind("ambient")
    if not ambients:
        return dataset.names_of_kind("air")
    room = "ambient_room" if "ambient_room" in ambients else ambients[0]
    return [room] + [n for n in ambients if n != room and not np.allclose(dataset[n], dataset[room])]


def drift_figure(dataset: Dataset) -> Figure:
    """TCP drift (µm) with the ambient temperature (°C) on a second axis, and the spindle speed (rpm) below.

    Parameters
    ----------
    dataset : Dataset
        With displacement channels.

    Returns
    -------
    matplotlib.figure.Figure
        Time in h.
    """
    speed = "spindle" in dataset and np.ptp(dataset["spindle"]) > 0
    fig, axes = plt.subplots(2 if speed else 1, 1, figsize=(9, 6.5 if speed else 5), sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": [3, 1] if speed else [1]})
    ax = axes[0, 0]
    hours = _hours(dataset)
    for name in dataset.names_of_kind("displacement"):
        ax.plot(hours, dataset[name], lw=1.4, label=f"{name} ({UNITS['um']})")
    ax.set_ylabel(f"TCP drift, tool relative to table ({UNITS['um']})")
    ax.grid(alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    ambient = _ambient_channels(dataset)
    if ambient:
        room_ax = ax.twinx()
        for k, name in enumerate(ambient):
            room_ax.plot(hours, dataset[name], lw=1.0, ls="--", color="0.35" if k == 0 else f"C{k + 5}",
                         label=f"{name} ({UNITS['degC']})")
        room_ax.set_ylabel(f"ambient temperature ({UNITS['degC']})", color="0.35")
        ax.set_zorder(room_ax.get_zorder() + 1)      # the drift and its legend in front of the ambient
        ax.patch.set_visible(False)
        more_handles, more_labels = room_ax.get_legend_handles_labels()
        handles, labels = handles + more_handles, labels + more_labels
    ax.legend(handles, labels, loc="upper left", fontsize=8)
    ax.set_title(f"TCP drift — {dataset.metadata.get('scenario', '')}")
    if speed:
        axes[1, 0].fill_between(hours, dataset["spindle"], step="pre", alpha=0.3, color="grey")
        axes[1, 0].set_ylabel("spindle speed (rpm)")
        axes[1, 0].grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (h)")
    return fig


def plot_drift(dataset: Dataset, path: str | Path) -> Path:
    """:func:`drift_figure` saved as PNG.

    Parameters
    ----------
    dataset : Dataset
        With displacement channels.
    path : str or Path
        The PNG file (written atomically).

    Returns
    -------
    Path
        ``path``.
    """
    return save_figure(drift_figure(dataset), path)


def plot_strains(dataset: Dataset, path: str | Path) -> Path | None:
    """FBG-like mean axial strains (µε) over time (h), saved as PNG.

    Parameters
    ----------
    dataset : Dataset
        The data.
    path : str or Path
        The PNG file (written atomically).

    Returns
    -------
    Path or None
        ``path``; None, and no file, without strain channels.
    """
    names = dataset.names_of_kind("strain")
    if not names:
        return None
    fig, ax = plt.subplots(figsize=(9, 4))
    for name in names:
        ax.plot(_hours(dataset), dataset[name], lw=1.2, label=name)
    ax.set_xlabel("time (h)")
    ax.set_ylabel(f"mean axial strain ({UNITS['ue']})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def plot_measured_vs_predicted(time_s: np.ndarray, measured: np.ndarray, predicted: np.ndarray, unit: str,
                               title: str, path: str | Path) -> Path:
    """Measured and predicted series, and their residual, over time in h, saved as PNG.

    Parameters
    ----------
    time_s : ndarray
        Times, s.
    measured, predicted : ndarray
        Values in ``unit``.
    unit : str
        Unit token (``um``, ``degC``, …; shown as µm, °C).
    title : str
        Figure title.
    path : str or Path
        The PNG file (written atomically).

    Returns
    -------
    Path
        ``path``.
    """
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    hours = np.asarray(time_s) / 3600.0
    top.plot(hours, measured, lw=1.3, label="measured")
    top.plot(hours, predicted, lw=1.1, ls="--", label="predicted")
    top.set_ylabel(f"value ({UNITS.get(unit, unit)})")
    top.set_title(title)
    top.grid(alpha=0.3)
    top.legend(fontsize=8)
    bottom.plot(hours, np.asarray(predicted) - np.asarray(measured), lw=1.0, color="C3")
    bottom.set_ylabel(f"residual ({UNITS.get(unit, unit)})")
    bottom.set_xlabel("time (h)")
    bottom.grid(alpha=0.3)
    return save_figure(fig, path)
