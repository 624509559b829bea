"""A tqdm progress bar behind the ``progress(done, total)`` callbacks of long work."""
from __future__ import annotations

import weakref
from collections.abc import Callable

from ..core.interrupt import raise_if_interrupted

_open_bars = weakref.WeakSet()


def progress_bar(description: str, unit: str) -> Callable[[int, int], None]:
    """A ``progress(done, total)`` callback drawing a tqdm bar; it raises KeyboardInterrupt after a Ctrl-C.

    The unit is required: the rate shown (e.g. ``scenario/s``) is only right if it names what is counted.

    Parameters
    ----------
    description : str
        Text before the bar.
    unit : str
        What is counted (``"step"``, ``"scenario"``, …).

    Returns
    -------
    callable
        ``progress(done, total)``; the bar closes when ``done == total``.
    """
    from tqdm import tqdm

    bar = {"tqdm": None}

    def update(done, total):
        raise_if_interrupted()          # a Ctrl-C whose KeyboardInterrupt a library swallowed stops the work here
        if bar["tqdm"] is None:
            # delay > 0: the constructor draws nothing, so the bar is known to close_bars before its first
            # line reaches stderr (a Ctrl-C between the two left the line open, and the message joined it)
            bar["tqdm"] = tqdm(total=total, desc=description, unit=unit, leave=False, mininterval=0.5, delay=1e-9)
            _open_bars.add(bar["tqdm"])
        bar["tqdm"].n = done
        bar["tqdm"].refresh() if done == total else bar["tqdm"].update(0)
        if done == total:
            bar["tqdm"].close()

    return update


def close_bars() -> None:
    """Close (and so clear) the bars that work stopped by an error or Ctrl-C left open, so that the
    message that follows starts on a line of its own."""
    for bar in list(_open_bars):
        bar.close()
