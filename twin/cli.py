"""The ``twin`` command line: a thin layer over functions a notebook user can call directly.

Each command lives in a ``twin/cli_<topic>.py`` module with a ``register(subparsers)``
function; this module only assembles them and turns user errors into one line
and a non-zero exit code.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from .errors import USER_ERRORS

COMMAND_MODULES = ("twin.cli_run", "twin.cli_fmu", "twin.cli_models", "twin.cli_gap")


def build_parser():
    parser = argparse.ArgumentParser(prog="twin", description="Thermal digital twin of a CNC machine tool.")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in COMMAND_MODULES:
        importlib.import_module(module).register(sub)
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        args.func(args)
    except USER_ERRORS as exc:
        print(f"twin {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"twin {args.command}: interrupted; no result was written", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
