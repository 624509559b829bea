"""A Ctrl-C that is not lost when a library swallows the KeyboardInterrupt it raised.

Python raises KeyboardInterrupt wherever the main thread is when SIGINT
arrives. Inside an import or a library call with a bare ``except:`` the
exception is gone, and a ``twin run`` interrupted while scipy was being
imported went on to simulate all its 9600 steps and exit 0. So the CLI's
handler also records the request here, and the places that long work passes
through (progress callbacks, the writing of a result) raise it again.
"""
from __future__ import annotations

import threading

_requested = threading.Event()


def request_interrupt() -> None:
    """Record a Ctrl-C (called from the SIGINT handler, beside raising KeyboardInterrupt)."""
    _requested.set()


def clear_interrupt() -> None:
    """Forget a recorded Ctrl-C (at the start of a command)."""
    _requested.clear()


def interrupt_requested() -> bool:
    """Whether a Ctrl-C was recorded since the command started."""
    return _requested.is_set()


def raise_if_interrupted() -> None:
    """Raise KeyboardInterrupt if a Ctrl-C was recorded, even one whose own exception a library swallowed.

    Raises
    ------
    KeyboardInterrupt
        A Ctrl-C was recorded.
    """
    if _requested.is_set():
        raise KeyboardInterrupt
