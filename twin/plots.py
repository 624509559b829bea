"""Figures of a dataset with units on every axis: temperatures, drift, strains (PNG, matplotlib Agg)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .dataset import UNITS  # noqa: E402


def _hours(dataset):
    return dataset.time_s / 3600.0


def save_figure(fig, path):
    """Save a Matplotlib figure to ``path`` (PNG) atomically and close it; returns the path."""
    path = Path(path)
    fig.tight_layout()
    tmp = path.with_name(f".{path.stem}.partial.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)
    return path


def plot_temperatures(dataset, path, max_lines=12):
    """Surface temperatures (the ``max_lines`` that rise most) and air sensors, °C, over time in h."""
    fig, ax = plt.subplots(figsize=(9, 5))
    surface = dataset.names_of_kind("temperature")
    rise = {n: np.ptp(dataset[n]) for n in surface}
    shown = sorted(surface, key=rise.get, reverse=True)[:max_lines]
    for name in shown:
        ax.plot(_hours(dataset), dataset[name], lw=1.2, label=f"{name}")
    for name in dataset.names_of_kind("air"):
        ax.plot(_hours(dataset), dataset[name], lw=1.0, ls="--", label=f"{name} (air)")
    ax.set_xlabel("time (h)")
    ax.set_ylabel(f"temperature ({UNITS['degC']})")
    ax.set_title(f"Temperatures — {dataset.metadata.get('scenario', '')}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="best")
    return save_figure(fig, path)


def plot_drift(dataset, path):
    """Tool-centre-point drift X, Y, Z (and the upper Y probe) in µm, with spindle speed behind."""
    fig, ax = plt.subplots(figsize=(9, 5))
    for name in dataset.names_of_kind("displacement"):
        ax.plot(_hours(dataset), dataset[name], lw=1.4, label=f"{name} ({UNITS['um']})")
    ax.set_xlabel("time (h)")
    ax.set_ylabel(f"TCP drift, tool relative to table ({UNITS['um']})")
    ax.grid(alpha=0.3)
    if "spindle" in dataset and np.ptp(dataset["spindle"]) > 0:
        twin_ax = ax.twinx()
        twin_ax.fill_between(_hours(dataset), dataset["spindle"], step="pre", alpha=0.12, color="grey")
        twin_ax.set_ylabel("spindle speed (rpm)", color="grey")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"TCP drift — {dataset.metadata.get('scenario', '')}")
    return save_figure(fig, path)


def plot_strains(dataset, path):
    """FBG-like mean axial strains in µε."""
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


def plot_measured_vs_predicted(time_s, measured, predicted, unit, title, path):
    """Measured and predicted series, and their residual, over time in h."""
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
