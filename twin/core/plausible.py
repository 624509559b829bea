"""Plausible sensor values: a value outside them is a unit error (kelvin under ``_degC``, nm under ``_um``) or a
broken channel, never data.  Measured imports and the gap diagnosis check every sensor channel against them."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..errors import TwinInputError

if TYPE_CHECKING:   # the dataset module imports this one for its measured import
    from .dataset import ChannelInfo, Dataset

#: Plausible values per channel kind in its edge unit (°C, °C, µm, µε): a machine tool in a workshop.
PLAUSIBLE = {"temperature": (-40.0, 150.0), "air": (-40.0, 80.0), "displacement": (-5000.0, 5000.0),
             "strain": (-5000.0, 5000.0)}


def _hint(kind, value):
    if kind in ("temperature", "air") and 230.0 <= value <= 430.0:
        return f"; it looks like kelvin ({value - 273.15:.2f} °C)"
    if kind in ("displacement", "strain") and abs(value) > PLAUSIBLE[kind][1]:
        return "; it looks like nm or a raw count"
    return ""


def check_plausible(dataset: Dataset, channel: ChannelInfo, kind: str, values: np.ndarray) -> None:
    """Stop with a clear error when a sensor's values lie outside :data:`PLAUSIBLE` for its kind.

    Parameters
    ----------
    dataset : Dataset
        The record (its source and times name the bad value).
    channel : ChannelInfo
        The record's channel.
    kind : str
        The sensor's kind: ``temperature``, ``air``, ``displacement`` or ``strain``.
    values : ndarray, shape (n_times,)
        The channel's values in its unit (°C, µm, µε), NaN where missing (ignored).

    Raises
    ------
    TwinInputError
        At the first implausible value, with a hint when it looks like kelvin or nm.
    """
    lo, hi = PLAUSIBLE[kind]
    bad = np.flatnonzero(np.isfinite(values) & ((values < lo) | (values > hi)))
    if bad.size:
        k = bad[0]
        source = dataset.metadata.get("source", "the data")
        article = "an" if kind[0] in "aeiou" else "a"
        raise TwinInputError(
            f"{source}: column {channel.column!r} has value {values[k]:g} at "
            f"t = {dataset.time_s[k]:g} s, outside the plausible {lo:g} … {hi:g} {channel.unit} of {article} {kind} "
            f"sensor{_hint(kind, float(values[k]))} (a spare or broken channel: map its column to null to leave "
            "it out)")
