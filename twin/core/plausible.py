"""Plausible sensor values: a value outside them is a unit error (kelvin under ``_degC``, nm under ``_um``) or a
broken channel, never data.  Measured imports and the gap diagnosis check every sensor channel against them."""
from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..errors import TwinInputError

if TYPE_CHECKING:   # the dataset module imports this one for its measured import
    from .dataset import ChannelInfo, Dataset

#: Plausible values per channel kind in its edge unit (°C, °C, µm, µε): a machine tool in a workshop; outside
#: them a channel is broken or in another unit.
PLAUSIBLE = {"temperature": (-40.0, 150.0), "air": (-40.0, 80.0), "displacement": (-5000.0, 5000.0),
             "strain": (-5000.0, 5000.0)}
#: Warmest shop air (°C) an air sensor may read: a hot summer hall reaches 35–40 °C, and no one machines in
#: air above 50 °C; 68, an air sensor's 20 °C in Fahrenheit, lies above it and is refused as °F.  A surface may
#: be hotter (a spindle housing, a motor), up to :data:`PLAUSIBLE`'s 150 °C.
SHOP_AIR_MAX_C = 50.0
#: An air sensor whose start (median of the first :data:`START_ROWS` values) differs from the surface
#: thermometers' (the median of theirs) by more than this (K) is a unit error: a machine at rest in its hall is
#: within a few kelvin of the air, a warm one within about 10 K, while 20 °C in °F reads 68 (48 K off) and 8 °C
#: reads 46.
AIR_SURFACE_MARGIN_K = 15.0
START_ROWS = 10


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
        At the first implausible value, with a hint when it looks like kelvin or nm; at an air reading above
        :data:`SHOP_AIR_MAX_C` (°F?).
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
    if kind == "air":
        _check_shop_air(dataset, channel, values)


def _check_shop_air(dataset, channel, values):
    """Stop at an air reading above :data:`SHOP_AIR_MAX_C` (°C): Fahrenheit under ``_degC``."""
    hot = np.flatnonzero(np.isfinite(values) & (values > SHOP_AIR_MAX_C))
    if hot.size:
        k = hot[0]
        raise TwinInputError(
            f"{dataset.metadata.get('source', 'the data')}: column {channel.column!r} has value {values[k]:g} at "
            f"t = {dataset.time_s[k]:g} s, above the {SHOP_AIR_MAX_C:g} degC of shop air: °F? (°F − 32)/1.8 = "
            f"{(values[k] - 32.0) / 1.8:.2f} °C; write the column in °C")


def _start(values):
    """Median of a column's first :data:`START_ROWS` finite values (°C), NaN when it has none."""
    finite = values[np.isfinite(values)][:START_ROWS]
    return float(np.median(finite)) if finite.size else float("nan")


def check_air_against_surfaces(source: str, air: Sequence[tuple[str, np.ndarray]],
                               surfaces: Sequence[np.ndarray]) -> None:
    """Stop when an air sensor starts more than :data:`AIR_SURFACE_MARGIN_K` away from the surface thermometers
    (one of the two in °F under ``_degC``), or, without an air sensor, when the thermometers start above shop
    air (:func:`_check_surfaces_without_air`: the whole record in °F).

    Parameters
    ----------
    source : str
        The record's file, for the message.
    air : sequence of (str, ndarray)
        Each air sensor's CSV column and values (°C, shape (n_times,), NaN where missing).
    surfaces : sequence of ndarray
        The surface thermometers' values (°C, each shape (n_times,), NaN where missing); none: nothing to check.

    Raises
    ------
    TwinInputError
        Naming the column, its start, the thermometers' and both readings in °F converted; without air, naming
        the thermometers' start and it converted.
    """
    starts = [s for s in map(_start, surfaces) if np.isfinite(s)]
    if not starts:
        return
    if not air:
        _check_surfaces_without_air(source, starts)
        return
    surface = float(np.median(starts))
    for column, values in air:
        start = _start(values)
        if np.isfinite(start) and abs(start - surface) > AIR_SURFACE_MARGIN_K:
            raise TwinInputError(
                f"{source}: column {column!r} starts at {start:g} degC, the surface thermometers at {surface:g} "
                f"degC: {start - surface:+.3g} K, more than the {AIR_SURFACE_MARGIN_K:g} K air and machine differ "
                f"by; °F? (°F − 32)/1.8 = {(start - 32.0) / 1.8:.2f} °C for the air "
                f"({(surface - 32.0) / 1.8:.2f} °C for the thermometers)")


def _check_surfaces_without_air(source, starts):
    """Stop when a record without an air sensor has at least two surface thermometers and most of them start
    (:func:`_start`, °C) above :data:`SHOP_AIR_MAX_C`: a whole record in °F (20 °C reads 68), which no air sensor
    gives away.  The lower median of the starts decides (above it: a majority), so one hot thermometer (a spindle
    housing at 70 °C can be real) never does, nor a lone thermometer."""
    if len(starts) < 2:
        return
    lower_median = float(np.sort(starts)[(len(starts) - 1) // 2])
    if lower_median > SHOP_AIR_MAX_C:
        raise TwinInputError(
            f"{source}: the {len(starts)} surface thermometers start at a median of {lower_median:g} degC, above the "
            f"{SHOP_AIR_MAX_C:g} degC of shop air, and the record has no air sensor to compare them with: the whole "
            f"record in °F? (°F − 32)/1.8 = {(lower_median - 32.0) / 1.8:.2f} °C; write the columns in °C")
