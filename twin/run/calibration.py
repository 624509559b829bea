"""The calibration targets of the default machine (thesis ranges) and how the twin meets them.

Each target is a scenario, a quantity computed from its noise-free dataset,
and the range the thesis reports for Machine A:

- 2 h at 9000 rpm (``heat_cool_9000`` at t = 2 h): Z drift 25–45 µm, Y drift 15–30 µm;
- an ETVE with a 5 °C day/night swing (``etve_5K``, after the first day): Z drift range ≥ 15 µm;
- a door opening, −9 °C over 30 min (``door_opening``): a visible Z response (≥ 5 µm).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.dataset import Dataset
from ..core.machine import Machine
from ..core.simulate import simulate
from ..infra.tables import markdown_table


@dataclass(frozen=True)
class Target:
    """A calibration target: a scenario, a drift quantity of its dataset, and the thesis range (µm)."""

    name: str
    scenario: str
    quantity: str
    low: float
    high: float

    def measure(self, dataset: Dataset) -> float:
        """The target's quantity in a noise-free dataset of its scenario.

        Parameters
        ----------
        dataset : Dataset
            With the ``Y`` and ``Z`` drift channels (µm).

        Returns
        -------
        float
            The quantity, µm.
        """
        t = dataset.time_s
        if self.quantity == "|Z| at 2 h":
            return float(abs(dataset["Z"][np.argmin(abs(t - 7200.0))]))
        if self.quantity == "|Y| at 2 h":
            return float(abs(dataset["Y"][np.argmin(abs(t - 7200.0))]))
        if self.quantity == "Z range after 24 h":
            return float(np.ptp(dataset["Z"][t >= 24 * 3600.0]))
        if self.quantity == "max |Z| change":
            return float(np.abs(dataset["Z"] - dataset["Z"][0]).max())
        raise ValueError(f"unknown quantity {self.quantity!r}")


TARGETS = (
    Target("spindle 2 h at 9000 rpm: Z", "heat_cool_9000", "|Z| at 2 h", 25.0, 45.0),
    Target("spindle 2 h at 9000 rpm: Y", "heat_cool_9000", "|Y| at 2 h", 15.0, 30.0),
    Target("ETVE, 5 °C day/night swing: Z", "etve_5K", "Z range after 24 h", 15.0, np.inf),
    Target("door opening, −9 °C over 30 min: Z", "door_opening", "max |Z| change", 5.0, np.inf),
)


def calibration_table(machine: Machine) -> list[tuple[Target, float, bool]]:
    """How the machine meets the calibration targets, from noise-free runs.

    Parameters
    ----------
    machine : Machine
        The built machine.

    Returns
    -------
    list of tuple
        ``(target, simulated value in µm, within the target's range)`` per target.
    """
    datasets = {}
    rows = []
    for target in TARGETS:
        if target.scenario not in datasets:
            datasets[target.scenario] = simulate(target.scenario, machine, noise=False).dataset
        value = target.measure(datasets[target.scenario])
        rows.append((target, value, target.low <= value <= target.high))
    return rows


def format_table(rows: list[tuple[Target, float, bool]]) -> str:
    """The rows of :func:`calibration_table` as a Markdown table (as in docs/calibration.md).

    Parameters
    ----------
    rows : list of tuple
        From :func:`calibration_table`.

    Returns
    -------
    str
        The table, values in µm.
    """
    cells = [(target.name, f"{target.low:g}–{target.high:g}" if np.isfinite(target.high) else f"≥ {target.low:g}",
              value, "yes" if ok else "NO", f"`twin run {target.scenario}`") for target, value, ok in rows]
    return markdown_table(cells, ["target", "thesis range (µm)", "simulated (µm)", "met", "command"],
                          formats=[None, None, ".1f", None, None])
