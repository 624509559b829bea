"""A Ctrl-C that is neither lost nor raised where it does harm.

Python raises KeyboardInterrupt wherever the main thread is when SIGINT
arrives. In a finaliser (``__del__``, a weakref callback) Python drops the
exception with an "Exception ignored" traceback; inside a library's bare
``except:`` it is gone; inside the import of a C extension it can crash the
process. A ``twin run`` interrupted while it imported its libraries went on
to simulate all 9600 steps of etve_160h and exit 0, printed that traceback,
or died of a segmentation fault (tests/test_cli_interrupt.py sweeps the moment).

So the CLI's handler records the request here; it raises at once only where
that is safe (:func:`safe_to_raise`), and otherwise sends the signal again a
moment later. The places that long work passes through (progress callbacks,
the writing of a result) raise a recorded request too.
"""
from __future__ import annotations

import signal
import threading
from types import FrameType

#: How soon a Ctrl-C that came during an import or a finaliser is delivered again, s.
RETRY_S = 0.05

_requested = threading.Event()
_retry_lock = threading.Lock()
_retry: threading.Timer | None = None


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


def safe_to_raise(frame: FrameType | None) -> bool:
    """Whether a KeyboardInterrupt raised in ``frame`` reaches the command: not during an import (a C
    extension's initialisation, a library's guarded import) nor in a finaliser, where it is dropped.

    Parameters
    ----------
    frame : frame or None
        The frame the signal interrupted (the handler's second argument).

    Returns
    -------
    bool
        False if ``frame`` or a frame that called it is importing a module or finalising an object.
    """
    while frame is not None:
        code = frame.f_code
        if code.co_filename.startswith("<frozen importlib") or code.co_name == "__del__" \
                or code.co_filename.endswith(("weakref.py", "_weakrefset.py")):
            return False
        frame = frame.f_back
    return True


def deliver_again_soon() -> None:
    """Send this process SIGINT again after :data:`RETRY_S`, from a daemon thread (the handler runs in the
    main thread, once that is back in Python code); :func:`cancel_delivery` stops it."""
    global _retry
    with _retry_lock:
        _retry = threading.Timer(RETRY_S, _deliver)
        _retry.daemon = True
        _retry.start()


def cancel_delivery() -> None:
    """Stop a SIGINT that :func:`deliver_again_soon` has not sent yet (when the command ends: the signal would
    meet the handler the command restored, and a traceback)."""
    global _retry
    with _retry_lock:
        if _retry is not None:
            _retry.cancel()
        _retry = None


def _deliver():
    with _retry_lock:
        if threading.current_thread() is _retry:     # not cancelled, nor replaced by a newer delivery
            if hasattr(signal, "pthread_kill"):    # to the main thread, so that a sleep or a wait there ends now
                signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
            else:  # pragma: no cover - Windows
                signal.raise_signal(signal.SIGINT)
