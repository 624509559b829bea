"""CLI commands ``twin fmu export|validate|simulate``: a thin layer over :mod:`twin.fmu`."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import TwinInputError
from ..infra.cli_common import (
    add_overwrite,
    check_distinct,
    check_out_file,
    existing_fmu,
    split_names,
)
from ..rom.cli import add_rom_options, machine_and_rom

# Handlers import the library inside them, never up here: start-up time (`twin --help` must not load scipy).


def cmd_fmu_export(args: argparse.Namespace) -> None:
    """``twin fmu export``: write an FMU of the machine's ROM (or FE), validated with fmpy, and print what it is.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    from .export import export_fmu, model_name

    check_out_file(args)
    outputs = _output_names(args.outputs)
    machine, rom = machine_and_rom(args)
    fe = dict(machine=args.machine, mesh_size_m=args.mesh_size) if args.engine == "fe" else None
    path = export_fmu(rom, args.out, kind=args.kind, engine=args.engine, outputs=outputs,
                      default_temperature_C=args.initial_temperature, step_s=args.step, fe_options=fe,
                      compiler=args.compiler, fmi_version=args.fmi_version)
    print(f"{path}: FMI {args.fmi_version}.0 Co-Simulation, {args.kind} FMU, engine {args.engine} "
          f"({model_name(rom, args.engine)}, {rom.n_outputs if outputs is None else len(outputs)} outputs)")
    print("fmpy.validate_fmu: no problems")


def _output_names(text):
    """``--outputs``: the names, or None (all but the camera spots) when the option is not given.

    Refused before any work when it names no output (``--outputs ""`` is not "all") or one twice.
    """
    if text is None:
        return None
    names = split_names(text)
    check_distinct("--outputs", names, "output")
    return names


def cmd_fmu_validate(args: argparse.Namespace) -> None:
    """``twin fmu validate``: check an FMU with ``fmpy.validate_fmu``; problems are an error.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    from .export import validate

    problems = validate(existing_fmu(args.fmu))   # fmpy's checks, then the files it needs to run here
    for p in problems:
        print(f"  problem: {p}")
    if problems:
        raise TwinInputError(f"{args.fmu}: {len(problems)} problem(s)")
    print(f"{args.fmu}: no problems")


def cmd_fmu_simulate(args: argparse.Namespace) -> None:
    """Run an FMU through a scenario in fmpy, compare it with the in-process ROM, write a CSV.

    The machine, ROM order and method default to the FMU's own (the mesh size to the machine's default);
    options that contradict it and a scenario written for another machine (unless ``--machine`` names the
    FMU's) are refused before anything is built, a machine of another digest (mesh, materials, sources)
    before the ROM is built: the comparison would measure the difference of two models, not the FMU's
    fidelity.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    import io

    import numpy as np

    from ..core.files import write_text_atomic
    from ..core.machine import build_machine
    from ..core.scenario import load_scenario
    from ..rom.reduction import cached_rom, machine_digest
    from .export import (
        fmu_identity,
        input_table,
        missing_parts,
        scenario_start,
        simulate,
        simulate_table,
    )

    existing_fmu(args.fmu)
    identity = fmu_identity(args.fmu)
    missing = missing_parts(args.fmu)
    if missing:
        raise TwinInputError(f"{args.fmu}: cannot run here: " + "; ".join(missing))
    scenario = load_scenario(args.scenario)
    args.out = args.out or f"runs/fmu_{scenario.name}.csv"
    check_out_file(args, inputs=(args.fmu, scenario.source))
    _check_options(args, identity, scenario)
    machine = build_machine(args.machine, args.mesh_size)
    scenario.check_machine(machine.definition)
    digest = machine_digest(machine)
    if digest != identity.digest:
        raise TwinInputError(f"{args.fmu} runs {identity}; machine {args.machine} (mesh size "
                             f"{args.mesh_size or 'its default'}) has digest {digest}: another "
                             "mesh, material, source or sensor. Pass the --machine and --mesh-size it was exported "
                             "with")
    rom = cached_rom(machine, args.order, args.method)
    T0, steady = scenario_start(rom, scenario)
    table = input_table(rom, scenario)
    result = simulate(args.fmu, table, T_initial=T0, steady_start=steady)
    names = [n for n in result.dtype.names if n != "time"]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    text = io.StringIO()
    header = ["time_s"] + [f"{n}_{rom.output_units[rom.output_index(n)]}" for n in names]   # as datasets name them
    np.savetxt(text, np.column_stack([result[n] for n in result.dtype.names]), delimiter=",",
               header=",".join(header), comments="", fmt="%.17g")
    write_text_atomic(out, text.getvalue())
    print(f"{args.fmu} (it runs {identity}): {len(result)} samples of {scenario.name} in {out}")
    ref = simulate_table(rom, table, T0, steady)
    worst = 0.0
    for n in names:
        j = rom.output_index(n)
        scale = max(float(np.abs(ref[:, j]).max()), 1e-30)
        worst = max(worst, float(np.abs(result[n] - ref[:, j]).max()) / scale)
    print(f"largest relative difference from the in-process {rom.method} ROM of order {rom.order}: {worst:.2e}")


def _check_options(args, identity, scenario):
    """Fill the machine, order and method the options leave out with the FMU's; refuse any that contradict it,
    and a scenario written for another machine unless ``--machine`` names the FMU's (as ``twin run --machine``
    runs a scenario on another machine). An FE-engine FMU is compared with its machine's default ROM."""
    from ..core.machine_definition import load_machine
    from ..rom.reduction import DEFAULT_ORDER

    named = (load_machine(args.machine) if args.machine else scenario.machine_definition()).name   # no build yet
    if named != identity.machine:
        which = (f"--machine {args.machine} is machine {named!r}" if args.machine else
                 f"{scenario.source}: scenario {scenario.name!r} is written for machine {named!r}")
        raise TwinInputError(f"{which}; {args.fmu} runs {identity}. Pass --machine {identity.machine} to run the "
                             "scenario on the FMU's machine")
    args.machine = args.machine or identity.machine
    own_order, own_method = (DEFAULT_ORDER, "krylov") if identity.order is None else (identity.order, identity.method)
    args.order = own_order if args.order is None else args.order
    args.method = own_method if args.method is None else args.method
    if args.order < 1:
        raise TwinInputError(f"--order {args.order}: a ROM's order is at least 1")
    if identity.order is not None and (args.order, args.method) != (identity.order, identity.method):
        raise TwinInputError(f"--order {args.order} --method {args.method}: {args.fmu} runs {identity}; leave "
                             "the options out to compare it with its own ROM")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``fmu`` command with its ``export``, ``validate`` and ``simulate`` subcommands.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``twin`` command.
    """
    fmu = sub.add_parser("fmu", help="export, validate and run FMI 2.0 co-simulation FMUs of the twin")
    fsub = fmu.add_subparsers(dest="fmu_command", required=True)
    export = fsub.add_parser("export", help="write an FMU (ROM engine) and validate it with fmpy")
    add_rom_options(export)
    export.add_argument("--kind", choices=("python", "native"), default="python",
                        help="python: PythonFMU (needs Python + numpy); native: compiled C, no dependency")
    export.add_argument("--engine", choices=("rom", "fe"), default="rom",
                        help="rom (default) or fe: the full FE model inside a Python FMU (slow)")
    export.add_argument("--out", default="twin.fmu", help="FMU file (default twin.fmu)")
    add_overwrite(export, "file")
    export.add_argument("--outputs", help="comma-separated output names, each once (default: all but camera spots)")
    export.add_argument("--initial-temperature", type=float, default=20.0, help="start value of T_initial, °C")
    export.add_argument("--step", type=float, default=10.0, help="default experiment step size, s")
    export.add_argument("--compiler", default="cc", help="C compiler for --kind native (default cc)")
    export.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                        help="FMI version: 2 (default) or 3 (native kind only)")
    export.set_defaults(func=cmd_fmu_export)

    val = fsub.add_parser("validate", help="check an FMU with fmpy.validate_fmu")
    val.add_argument("fmu")
    val.set_defaults(func=cmd_fmu_validate)

    run = fsub.add_parser("simulate", help="run an FMU through a scenario in fmpy and compare with the ROM")
    run.add_argument("fmu")
    run.add_argument("scenario")
    add_rom_options(run, defaults_from="the FMU's")
    run.add_argument("--out", help="CSV of the FMU outputs (default runs/fmu_<scenario>.csv)")
    add_overwrite(run, "file")
    run.set_defaults(func=cmd_fmu_simulate)
