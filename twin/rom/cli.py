"""CLI commands ``twin rom build`` and ``twin rom report``: a thin layer over :mod:`twin.rom`."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from ..core.files import write_text_atomic
from ..errors import TwinInputError
from ..infra.cli_common import add_overwrite, check_out_file, mesh_size, split_names

if TYPE_CHECKING:
    from ..core.machine import Machine
    from .reduction import ReducedModel

# Handlers import the library inside them, never up here: start-up time (`twin --help` must not load scipy).
# So twin.rom.reduction's default order is copied here (tests/test_cli_startup.py keeps the two equal).
DEFAULT_ORDER = 80


def _orders(text):
    try:
        values = [int(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise TwinInputError(f"--orders must be comma-separated integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise TwinInputError(f"--orders must be positive integers, got {text!r}")
    return values


def machine_and_rom(args: argparse.Namespace) -> tuple[Machine, ReducedModel]:
    """The machine and its (cached) ROM named by ``--machine``, ``--mesh-size``, ``--order`` and ``--method``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (``--rebuild``, if it has it, builds the ROM even if cached).

    Returns
    -------
    machine : Machine
    rom : ReducedModel
    """
    from ..core.machine import build_machine
    from .reduction import cached_rom

    machine = build_machine(args.machine, args.mesh_size)
    return machine, cached_rom(machine, args.order, args.method, rebuild=getattr(args, "rebuild", False))


def add_rom_options(p: argparse.ArgumentParser, defaults_from: str | None = None) -> None:
    """Add the options that choose the machine and its ROM (``rom build``, ``fmu export``, ``fmu simulate``).

    Parameters
    ----------
    p : argparse.ArgumentParser
        The command's parser.
    defaults_from : str, optional
        What the machine, order and method default to, if not to vmc_ram, order
        :data:`DEFAULT_ORDER` and krylov (e.g. "the FMU's": they are then None until the command fills them).
    """
    def default(value, shown):
        return (None, f"default {defaults_from}") if defaults_from else (value, f"default {shown}")

    value, shown = default("vmc_ram", "vmc_ram")
    p.add_argument("--machine", default=value, help=f"machine name or TOML path ({shown})")
    p.add_argument("--mesh-size", type=mesh_size, help="target tetrahedron edge length, m")
    value, shown = default(DEFAULT_ORDER, DEFAULT_ORDER)
    p.add_argument("--order", type=int, default=value, help=f"ROM order ({shown})")
    value, shown = default("krylov", "krylov")
    p.add_argument("--method", choices=("krylov", "modal"), default=value, help=f"reduction method ({shown})")


def cmd_rom_build(args: argparse.Namespace) -> None:
    """``twin rom build``: build (or read from the cache) a machine's ROM, print its size and time constants.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    check_out_file(args, suffix=".npz")
    machine, rom = machine_and_rom(args)
    i = rom.info
    where = f"read from {i['from_cache']}" if i.get("from_cache") else f"built in {i['build_seconds']:.1f} s"
    print(f"{rom}: {where}")
    slowest = f"{i['slowest_time_constant_s'] / 3600:.3g} h"
    times = (f"time constant {slowest}" if rom.order == 1
             else f"time constants {i['fastest_time_constant_s']:.3g} s … {slowest}")
    print(f"  {i['n_nodes']} thermal unknowns → {rom.order} states; {times}")
    if args.out:
        print(f"  saved to {rom.save(args.out)}")


def cmd_rom_report(args: argparse.Namespace) -> None:
    """``twin rom report``: the ROM's error against the full FE over orders, methods and scenarios.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    from ..core.machine import build_machine
    from .report import (
        check_report_options,
        error_report,
        format_markdown,
        format_summary,
    )

    check_out_file(args)
    # orders and methods before the machine is built; error_report checks the named scenarios against the
    # machine before its FE runs (minutes)
    orders, methods = check_report_options(_orders(args.orders), split_names(args.methods))
    machine = build_machine(args.machine, args.mesh_size)
    report = error_report(machine, orders, methods, split_names(args.scenarios) or None, progress=print)
    text = format_summary(report) + "\n\n" + format_markdown(report)
    print()
    print(text)
    best = report.passes("krylov") if "krylov" in methods else None
    print(f"\nsmallest Krylov order meeting TCP ≤ 0.05 µm and T ≤ 0.01 K on every scenario: {best}")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(args.out, text + "\n")
        print(f"table written to {args.out}")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``rom`` command with its ``build`` and ``report`` subcommands.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``twin`` command.
    """
    rom = sub.add_parser("rom", help="build reduced-order models and report their error against the FE")
    rsub = rom.add_subparsers(dest="rom_command", required=True)
    build = rsub.add_parser("build", help="build (or read from cache) a machine's ROM")
    add_rom_options(build)
    build.add_argument("--rebuild", action="store_true", help="build even if cached")
    build.add_argument("--out", help="also save it to this .npz")
    add_overwrite(build, "file")
    build.set_defaults(func=cmd_rom_build)

    report = rsub.add_parser("report", help="error vs order against the full FE over scenarios (slow)")
    report.add_argument("--machine", default="vmc_ram")
    report.add_argument("--mesh-size", type=mesh_size, help="target tetrahedron edge length, m")
    report.add_argument("--orders", default="10,20,30,40,60,80,100", help="comma-separated orders, none twice")
    report.add_argument("--methods", default="krylov,modal", help="comma-separated: krylov,modal, none twice")
    report.add_argument("--scenarios", help="comma-separated scenarios of the machine, none twice (default: all "
                        "shipped; those of another machine are left out)")
    report.add_argument("--out", help="write the Markdown table here")
    add_overwrite(report, "file")
    report.set_defaults(func=cmd_rom_report)
