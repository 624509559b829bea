"""CLI commands ``twin fmu export|validate|simulate`` and ``twin rom build|report``."""
from __future__ import annotations

from pathlib import Path

from .cli_common import add_overwrite, existing_fmu
from .errors import TwinInputError

# Handlers import the library inside them, never up here: start-up time (`twin --help` must not load scipy).
# So twin.rom's default order is copied here (tests/test_cli_startup.py keeps the two equal).
DEFAULT_ORDER = 80


def _orders(text):
    try:
        values = [int(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise TwinInputError(f"--orders must be comma-separated integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise TwinInputError(f"--orders must be positive integers, got {text!r}")
    return values


def _rom(args):
    from .machine import build_machine
    from .rom import cached_rom

    machine = build_machine(args.machine, args.mesh_size)
    return machine, cached_rom(machine, args.order, args.method, rebuild=getattr(args, "rebuild", False))


def _check_out(args, inputs=()):
    """Check ``--out`` (a file) before any work."""
    from .outdir import check_output_file

    if args.out is not None:
        check_output_file(args.out, args.overwrite, inputs)


def cmd_fmu_export(args):
    from .fmu import export_fmu, validate

    _check_out(args)
    machine, rom = _rom(args)
    outputs = args.outputs.split(",") if args.outputs else None
    fe = dict(machine=args.machine, mesh_size_m=args.mesh_size) if args.engine == "fe" else None
    path = export_fmu(rom, args.out, kind=args.kind, engine=args.engine, outputs=outputs,
                      default_temperature_C=args.initial_temperature, step_s=args.step, fe_options=fe,
                      compiler=args.compiler, fmi_version=args.fmi_version)
    problems = validate(path)
    print(f"{path}: FMI {args.fmi_version}.0 Co-Simulation, {args.kind} FMU, engine {args.engine} "
          f"({rom.method} ROM of order {rom.order}, {rom.n_outputs if outputs is None else len(outputs)} outputs)")
    if problems:
        for p in problems:
            print(f"  problem: {p}")
        raise TwinInputError(f"{path}: fmpy found {len(problems)} problem(s) in the FMU")
    print("fmpy.validate_fmu: no problems")


def cmd_fmu_validate(args):
    from .fmu import validate

    problems = validate(existing_fmu(args.fmu))
    for p in problems:
        print(f"  problem: {p}")
    if problems:
        raise TwinInputError(f"{args.fmu}: {len(problems)} problem(s)")
    print(f"{args.fmu}: no problems")


def cmd_fmu_simulate(args):
    """Run an FMU through a scenario in fmpy, compare it with the in-process ROM, write a CSV."""
    import numpy as np

    from .fmu import input_table, scenario_start, simulate, simulate_table
    from .scenario import load_scenario

    existing_fmu(args.fmu)
    scenario = load_scenario(args.scenario)
    args.out = args.out or f"runs/fmu_{scenario.name}.csv"
    _check_out(args, inputs=(args.fmu, scenario.source))
    machine, rom = _rom(args)
    T0, steady = scenario_start(rom, scenario)
    table = input_table(rom, scenario)
    result = simulate(args.fmu, table, T_initial=T0, steady_start=steady)
    names = [n for n in result.dtype.names if n != "time"]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(out, np.column_stack([result[n] for n in result.dtype.names]), delimiter=",",
               header=",".join(result.dtype.names), comments="", fmt="%.17g")
    print(f"{args.fmu}: {len(result)} samples of {scenario.name} in {out}")
    ref = simulate_table(rom, table, T0, steady)
    worst = 0.0
    for n in names:
        if n in rom.output_names:
            j = rom.output_index(n)
            scale = max(float(np.abs(ref[:, j]).max()), 1e-30)
            worst = max(worst, float(np.abs(result[n] - ref[:, j]).max()) / scale)
    print(f"largest relative difference from the in-process ROM: {worst:.2e}")


def cmd_rom_build(args):
    _check_out(args)
    machine, rom = _rom(args)
    i = rom.info
    where = f"read from {i['from_cache']}" if i.get("from_cache") else f"built in {i['build_seconds']:.1f} s"
    print(f"{rom}: {where}")
    print(f"  {i['n_nodes']} thermal unknowns → {rom.order} states; time constants "
          f"{i['fastest_time_constant_s']:.3g} s … {i['slowest_time_constant_s'] / 3600:.3g} h")
    if args.out:
        print(f"  saved to {rom.save(args.out)}")


def cmd_rom_report(args):
    from .machine import build_machine
    from .rom_report import error_report, format_markdown, format_summary

    _check_out(args)
    machine = build_machine(args.machine, args.mesh_size)
    scenarios = args.scenarios.split(",") if args.scenarios else None
    report = error_report(machine, _orders(args.orders), args.methods.split(","), scenarios, progress=print)
    text = format_summary(report) + "\n\n" + format_markdown(report)
    print()
    print(text)
    best = report.passes("krylov") if "krylov" in args.methods else None
    print(f"\nsmallest Krylov order meeting TCP ≤ 0.05 µm and T ≤ 0.01 K on every scenario: {best}")
    if args.out:
        Path(args.out).write_text(text + "\n", encoding="utf-8")
        print(f"table written to {args.out}")


def register(sub):
    """Add the ``fmu`` and ``rom`` commands."""
    def common(p):
        p.add_argument("--machine", default="vmc_ram", help="machine name or TOML path (default vmc_ram)")
        p.add_argument("--mesh-size", type=float, help="target tetrahedron edge length, m")
        p.add_argument("--order", type=int, default=DEFAULT_ORDER, help=f"ROM order (default {DEFAULT_ORDER})")
        p.add_argument("--method", choices=("krylov", "modal"), default="krylov", help="reduction method")

    fmu = sub.add_parser("fmu", help="export, validate and run FMI 2.0 co-simulation FMUs of the twin")
    fsub = fmu.add_subparsers(dest="fmu_command", required=True)
    export = fsub.add_parser("export", help="write an FMU (ROM engine) and validate it with fmpy")
    common(export)
    export.add_argument("--kind", choices=("python", "native"), default="python",
                        help="python: PythonFMU (needs Python + numpy); native: compiled C, no dependency")
    export.add_argument("--engine", choices=("rom", "fe"), default="rom",
                        help="rom (default) or fe: the full FE model inside a Python FMU (slow)")
    export.add_argument("--out", default="twin.fmu", help="FMU file (default twin.fmu)")
    add_overwrite(export, "file")
    export.add_argument("--outputs", help="comma-separated output names (default: all but camera spots)")
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
    common(run)
    run.add_argument("--out", help="CSV of the FMU outputs (default runs/fmu_<scenario>.csv)")
    add_overwrite(run, "file")
    run.set_defaults(func=cmd_fmu_simulate)

    rom = sub.add_parser("rom", help="build reduced-order models and report their error against the FE")
    rsub = rom.add_subparsers(dest="rom_command", required=True)
    build = rsub.add_parser("build", help="build (or read from cache) a machine's ROM")
    common(build)
    build.add_argument("--rebuild", action="store_true", help="build even if cached")
    build.add_argument("--out", help="also save it to this .npz")
    add_overwrite(build, "file")
    build.set_defaults(func=cmd_rom_build)

    report = rsub.add_parser("report", help="error vs order against the full FE over scenarios (slow)")
    report.add_argument("--machine", default="vmc_ram")
    report.add_argument("--mesh-size", type=float)
    report.add_argument("--orders", default="10,20,30,40,60,80,100", help="comma-separated orders")
    report.add_argument("--methods", default="krylov,modal", help="comma-separated: krylov,modal")
    report.add_argument("--scenarios", help="comma-separated scenarios (default: all shipped)")
    report.add_argument("--out", help="write the Markdown table here")
    add_overwrite(report, "file")
    report.set_defaults(func=cmd_rom_report)
