"""The ``twin`` command line: a thin layer over functions a notebook user can call directly.

Each capability subpackage has a ``cli`` module (``twin/run/cli.py``, ``twin/gap/cli.py``, …) with a
``register(subparsers)`` function; this module only assembles them and turns user errors, missing files
and Ctrl-C into one line and a non-zero exit code.

Start-up time: the ``cli`` modules import only the standard library and
light twin modules when the parser is built; each command imports the
numerical libraries inside its handler, so ``--help`` and argument errors
answer at once (tests/test_cli_startup.py, bench/cli_startup.py).
"""
from __future__ import annotations

import argparse
import os
import shlex
import signal
import sys

from .compensation import cli as compensation_cli
from .core.interrupt import (
    cancel_delivery,
    clear_interrupt,
    deliver_again_soon,
    interrupt_requested,
    raise_if_interrupted,
    request_interrupt,
    safe_to_raise,
)
from .errors import user_errors
from .fmu import cli as fmu_cli
from .gap import cli as gap_cli
from .infra.outdir import COMMAND, JOB
from .infra.progress import close_bars
from .live import cli as live_cli
from .placement import cli as placement_cli
from .rom import cli as rom_cli
from .run import cli as run_cli

#: The command modules, in the order ``twin --help`` lists their commands.
COMMAND_MODULES = (run_cli, fmu_cli, rom_cli, compensation_cli, placement_cli, gap_cli, live_cli)
INTERRUPTED = 130          # the shell's code for a process ended by SIGINT (128 + 2)


def build_parser() -> argparse.ArgumentParser:
    """The ``twin`` parser, with every capability's commands.

    Returns
    -------
    argparse.ArgumentParser
        Each command sets ``func``, its handler.
    """
    parser = argparse.ArgumentParser(prog="twin", description="Thermal digital twin of a CNC machine tool.")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in COMMAND_MODULES:
        module.register(sub)
    return parser


def _exit_now(signum, frame):
    """Ctrl-C while nothing needs cleaning up (parsing, or a second Ctrl-C during clean-up): leave at once."""
    sys.stdout.flush()
    sys.stderr.write("twin: interrupted\n")
    sys.stderr.flush()
    os._exit(INTERRUPTED)


def _interrupt_once(signum, frame):
    """The first Ctrl-C of a command unwinds it (partial results are removed); a second one leaves at once.

    The request is recorded first, so that a KeyboardInterrupt a library swallows is raised again at the
    next progress step or before any result is written; during an import or a finaliser it is not raised
    but delivered again a moment later (:mod:`twin.core.interrupt`)."""
    request_interrupt()
    if not safe_to_raise(frame):
        deliver_again_soon()
        return
    _on_sigint(_exit_now)
    raise KeyboardInterrupt


def _on_sigint(handler):
    """Install a SIGINT handler; return the previous one (``None`` outside the main thread, where Python
    cannot set handlers)."""
    try:
        return signal.signal(signal.SIGINT, handler)
    except ValueError:
        return None


def _command_name(args):
    """``run``, or ``fmu validate`` for a command with subcommands."""
    sub = getattr(args, f"{args.command}_command", None)
    return args.command if sub is None else f"{args.command} {sub}"


def _interrupted(args):
    print(f"twin {_command_name(args)}: interrupted; no result was written", file=sys.stderr)
    return INTERRUPTED


def _file_error(exc):
    """An OSError about a named file (a missing input, a folder that cannot be read) as one line, else None."""
    if exc.filename is None:
        return None
    reason = exc.strerror or type(exc).__name__
    return f"{exc.filename}: {reason}"


def _notices_to_stderr():
    """Show the package's notices (what is built, how long it takes, bad cache files) as ``twin: …`` lines."""
    import logging

    class StderrHandler(logging.StreamHandler):
        """Writes to whatever ``sys.stderr`` is when a message comes (tests replace it)."""

        stream = property(lambda self: sys.stderr, lambda self, value: None)

    logger = logging.getLogger("thermal_twin")
    if not any(type(h).__name__ == "StderrHandler" for h in logger.handlers):
        handler = StderrHandler()
        handler.setFormatter(logging.Formatter("twin: %(message)s"))
        logger.addHandler(handler)
    logger.setLevel(logging.INFO)


def main(argv: list[str] | None = None) -> int:
    """Run one ``twin`` command; user errors, missing files and Ctrl-C become one line on stderr.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit code: 0 done, 2 error, 130 interrupted, or the code a command returns (``twin live``: 1 when it
        observed nothing).
    """
    previous = _on_sigint(_exit_now)
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    recorded = COMMAND.set(shlex.join(["twin", *argv]))       # the command line result folders record
    try:
        args = build_parser().parse_args(argv)
        JOB.set(_command_name(args))                           # which command a result folder records
        _notices_to_stderr()
        clear_interrupt()
        _on_sigint(_interrupt_once)
        try:
            try:
                code = args.func(args)
                raise_if_interrupted()
            finally:                       # the command has unwound: nothing left to clean up
                _on_sigint(_exit_now)
                cancel_delivery()
                close_bars()
        except user_errors() as exc:
            message = str(exc)
        except KeyboardInterrupt:
            return _interrupted(args)
        except OSError as exc:
            message = _file_error(exc)
            if message is None and not interrupt_requested():
                raise
        else:
            return code or 0
        if interrupt_requested():          # the error followed a Ctrl-C that a library swallowed
            return _interrupted(args)
        print(f"twin {_command_name(args)}: error: {message}", file=sys.stderr)
        return 2
    finally:
        clear_interrupt()                  # the command is over: a later one in this process starts afresh
        COMMAND.reset(recorded)
        JOB.set(None)
        if previous is not None:
            _on_sigint(previous)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
