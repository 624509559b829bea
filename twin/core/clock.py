"""Date-time stamps in measured records: seconds from a stated origin, and several records on one clock.

A logger writes ISO 8601 stamps (``2026-11-23 14:05:00``, ``2026-11-23T14:05:00.250+01:00``); the twin
counts time in s.  A record read from stamps counts from its first stamp, which its import report keeps as
``time_origin``.  Records read together (the files of one test, a day each) are put on one clock that counts
from the earliest first stamp among them, so that a file which continues another is recognised as such.

Stamps with a UTC offset are converted to UTC, so a daylight-saving change is no jump.  Stamps without one
are taken as written: a clock set back then shows as time going backwards, which the import refuses.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..errors import TwinInputError

if TYPE_CHECKING:
    from .dataset import Dataset

#: A stamp that ends in ``Z`` or an offset such as ``+01:00``, ``-0500`` or ``+01``.
_UTC_OFFSET = r"(?:Z|[+-]\d\d(?::?\d\d)?)$"
EXAMPLES = "2026-11-23 14:05:00 or 2026-11-23T14:05:00.5+01:00"


def seconds_since_first_stamp(source: str, column: str, cells: Sequence[object]) -> tuple[np.ndarray, str]:
    """A column of ISO 8601 date-times as seconds since its first stamp.

    Parameters
    ----------
    source : str
        The file, for messages.
    column : str
        The column's name, for messages.
    cells : sequence of str or None
        The column's cells; an empty one becomes NaN (the caller refuses it by row).

    Returns
    -------
    seconds : ndarray
        s since the first stamp.
    origin : str
        The first stamp, ISO 8601 (in UTC with ``+00:00`` when the stamps carry an offset).

    Raises
    ------
    TwinInputError
        A cell that is not a date-time, or stamps of which some carry a UTC offset and some do not.
    """
    import pandas as pd

    text = pd.Series(list(cells), dtype="string").str.strip()
    given = text.notna() & (text != "")
    with_offset = text.str.contains(_UTC_OFFSET, regex=True).fillna(False) & given
    if with_offset.any() and not with_offset[given].all():
        row = int(np.flatnonzero((given & ~with_offset).to_numpy())[0])
        raise TwinInputError(f"{source}: column {column!r}, data row {row + 1}: {text[row]!r} has no UTC offset "
                             "but other stamps have one; give every stamp with its offset, or none")
    stamps = pd.to_datetime(text.where(given), format="ISO8601", utc=bool(with_offset.any()), errors="coerce")
    bad = (stamps.isna() & given).to_numpy()
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise TwinInputError(f"{source}: column {column!r}, data row {row + 1}: {text[row]!r} is neither a "
                             f"number (s) nor an ISO 8601 date-time such as {EXAMPLES}")
    first = stamps[given].iloc[0] if given.any() else None
    if first is None:
        return np.full(len(text), np.nan), ""
    return (stamps - first).dt.total_seconds().to_numpy(dtype=float), first.isoformat()


def stamp(origin: str, seconds: float) -> str:
    """The date-time ``seconds`` after ``origin``, as a message shows it.

    Parameters
    ----------
    origin : str
        An ISO 8601 date-time (a record's ``time_origin``).
    seconds : float
        s after it.

    Returns
    -------
    str
        ISO 8601 with a space between date and time.
    """
    import pandas as pd

    return (pd.Timestamp(origin) + pd.Timedelta(seconds=float(seconds))).isoformat(sep=" ")


def on_one_clock(datasets: Sequence[Dataset]) -> list[Dataset]:
    """Records read from date-time stamps, counted from the earliest first stamp among them.

    Records without stamps (a ``time_s`` column, a twin record) keep their own times.

    Parameters
    ----------
    datasets : sequence of Dataset
        Records read together.

    Returns
    -------
    list of Dataset
        The same records, those with a ``time_origin`` shifted to the common one (which their import
        reports then name).

    Raises
    ------
    TwinInputError
        Some records' stamps carry a UTC offset and others' do not: they cannot be put on one clock.
    """
    import pandas as pd

    origins = [ds.metadata.get("import", {}).get("time_origin") for ds in datasets]
    stamped = [(ds, pd.Timestamp(o)) for ds, o in zip(datasets, origins) if o]
    if len(stamped) < 2:
        return list(datasets)
    kinds = {t.tzinfo is None: ds.metadata.get("source", "a record") for ds, t in stamped}
    if len(kinds) > 1:
        raise TwinInputError(f"{kinds[False]} has date-time stamps with a UTC offset and {kinds[True]} without "
                             "one: they cannot be put on one clock; give every file's stamps the same way")
    common = min(t for _, t in stamped)
    moved = []
    for ds, origin in zip(datasets, origins):
        if not origin:
            moved.append(ds)
            continue
        shift = (pd.Timestamp(origin) - common).total_seconds()
        metadata = {**ds.metadata, "import": {**ds.metadata["import"], "time_origin": common.isoformat()}}
        moved.append(type(ds)(ds.time_s + shift, ds.values, ds.channels, metadata))
    return moved
