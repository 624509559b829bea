"""Run one independent, expensive computation in a forked worker process while the caller goes on.

``start(fn, *args)`` returns a :class:`Background` handle: ``done()`` polls
without blocking, ``result()`` waits and returns ``fn(*args)`` or re-raises
its exception.  The worker is a ``fork`` of the caller, so ``fn`` and its
arguments are inherited, not pickled (only the result travels back through
a pipe): large meshes and operators cost nothing to hand over.

Where ``fork`` is not available (Windows), or with ``serial=True``, the
call runs at once in the caller and the handle is simply complete, so code
written against this module runs unchanged, just without the overlap.

The worker limits its BLAS/OpenMP pools to one thread (through threadpoolctl
when it is installed), so that it and the caller share two cores instead of
oversubscribing them.  The caller's own pools are left alone.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import resource
import traceback
import warnings
from collections.abc import Callable


def fork_available() -> bool:
    """Whether worker processes can be started by ``fork`` on this platform.

    Returns
    -------
    bool
        False on Windows.
    """
    return "fork" in mp.get_all_start_methods()


def _limit_threads(n):
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional: without it the pools keep their size
        return None
    return threadpool_limits(limits=n)


def _peak_rss_bytes():
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss if os.uname().sysname == "Darwin" else rss * 1024


def _child(conn, fn, args, kwargs, threads):
    try:
        if threads is not None:
            _limit_threads(threads)
        payload = ("ok", fn(*args, **kwargs), _peak_rss_bytes())
    except BaseException as exc:  # noqa: BLE001 - every failure is reported to the parent
        payload = ("error", exc, traceback.format_exc())
    try:
        conn.send(payload)
    except Exception as exc:  # noqa: BLE001 - pickling runs the result's own __reduce__, which may raise anything;
        # the parent must still receive an error rather than wait for a result that never comes.
        conn.send(("error", RuntimeError(f"background result could not be sent: {exc!r}"),
                   traceback.format_exc()))
    conn.close()


class _RemoteTraceback(Exception):
    def __init__(self, text):
        super().__init__(text)

    def __str__(self):
        return f"\n(in the background worker)\n{self.args[0]}"


class Background:
    """Handle on ``fn(*args, **kwargs)`` running in a forked worker (or already run in the caller).

    Parameters
    ----------
    fn : callable
        The work; its result (or exception) must be picklable.
    args : tuple
        Its positional arguments.
    kwargs : dict, optional
        Its keyword arguments.
    serial : bool
        Run it here and now instead (also when ``fork`` is not available).
    worker_threads : int
        BLAS threads of the worker.
    """

    def __init__(self, fn: Callable, args: tuple = (), kwargs: dict | None = None, serial: bool = False,
                 worker_threads: int = 1) -> None:
        kwargs = kwargs or {}
        self._state = None          # ("ok", value, peak_rss) or ("error", exc, text)
        self._process = self._conn = None
        self.forked = not serial and fork_available()
        if not self.forked:
            try:
                self._state = ("ok", fn(*args, **kwargs), None)
            except Exception as exc:  # noqa: BLE001 - not swallowed: result() re-raises it, as in the forked worker
                self._state = ("error", exc, None)
            return
        ctx = mp.get_context("fork")
        receive, send = ctx.Pipe(duplex=False)
        self._process = ctx.Process(target=_child, args=(send, fn, args, kwargs, worker_threads),
                                    daemon=True, name=f"fea-background-{getattr(fn, '__name__', 'job')}")
        with warnings.catch_warnings():
            # Python ≥ 3.12 warns about fork() in a process with threads (BLAS pools); the worker only
            # computes with numpy/scipy and returns through a pipe, which is safe here.
            warnings.filterwarnings("ignore", category=DeprecationWarning, message=r".*fork\(\).*")
            self._process.start()
        send.close()
        self._conn = receive

    def _receive(self):
        try:
            self._state = self._conn.recv()
        except EOFError:
            self._process.join()
            self._state = ("error", RuntimeError(
                f"the background worker died without a result (exit code {self._process.exitcode})"), None)
        self._conn.close()
        self._process.join()

    def done(self) -> bool:
        """Whether the result (or the error) is available; never blocks.

        Returns
        -------
        bool
            True once it is.
        """
        if self._state is None and self._conn.poll():
            self._receive()
        return self._state is not None

    def result(self) -> object:
        """Wait for the worker.

        Returns
        -------
        object
            The value of ``fn``; its exception is re-raised, with the worker's traceback as the cause.
        """
        if self._state is None:
            self._receive()
        kind, value, extra = self._state
        if kind == "error":
            if isinstance(extra, str):     # the worker's traceback, shown as the cause
                raise value from _RemoteTraceback(extra)
            raise value
        return value

    @property
    def worker_peak_rss_bytes(self) -> int | None:
        """Peak resident memory of the worker process (None when it ran in the caller or has not ended)."""
        if self._state is not None and self._state[0] == "ok":
            return self._state[2]
        return None

    def __del__(self):
        try:
            self.cancel()
        except Exception:  # noqa: BLE001, S110 - __del__ must not raise; at shutdown any module global may be gone
            pass

    def cancel(self) -> None:
        """Stop the worker if it is still running."""
        if self._state is None and self._process is not None:
            self._process.terminate()
            self._process.join()
            self._conn.close()
            self._state = ("error", RuntimeError("the background computation was cancelled"), None)


def start(fn: Callable, *args: object, serial: bool = False, **kwargs: object) -> Background:
    """Start ``fn(*args, **kwargs)`` in a forked worker.

    Parameters
    ----------
    fn : callable
        The work.
    *args, **kwargs
        Its arguments.
    serial : bool
        Run it here and now instead.

    Returns
    -------
    Background
        The handle.
    """
    return Background(fn, args, kwargs, serial=serial)
