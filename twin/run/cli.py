"""CLI commands ``twin run``, ``twin mesh`` and ``twin report``: a thin layer over :mod:`twin.run.workflows`."""
from __future__ import annotations

import argparse
import sys

from ..infra.cli_common import add_overwrite, mesh_size, read_column_map
from ..infra.progress import progress_bar

# Handlers import the library inside them, never up here: start-up time (`twin --help` must not load scipy).


def cmd_run(args: argparse.Namespace) -> int:
    """``twin run``: simulate a scenario, write the result folder, print the summary.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        0, or 1 when the run's energy balance failed (its results are written and marked, but a script must
        not take them for good ones).
    """
    from .workflows import run_scenario

    out = run_scenario(args.scenario, machine=args.machine, mesh_size_m=args.mesh_size, out_dir=args.out,
                       fields=args.fields, progress=progress_bar("simulating", unit="step"),
                       camera=True if args.camera else None, overwrite=args.overwrite, views=not args.no_views)
    from .summary import format_summary

    print(format_summary(out.summary))
    print(f"results in {out.out_dir}/")
    if out.summary.get("energy_balance", {}).get("ok", True):
        return 0
    print("twin run: the energy balance FAILED (see summary.md): heat was lost or created", file=sys.stderr)
    return 1


def cmd_mesh(args: argparse.Namespace) -> None:
    """``twin mesh``: mesh a machine (or read its cached mesh), print its statistics.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    from .workflows import mesh_machine

    stats, out_dir = mesh_machine(args.machine, args.mesh_size, args.out, rebuild=args.rebuild, ship=args.ship,
                                  overwrite=args.overwrite)
    print(f"machine {args.machine}: {stats['nodes']} nodes, {stats['tetrahedra']} tetrahedra, "
          f"{stats['thermal_nodes']} thermal nodes (joints split)")
    print(f"volume {stats['volume_m3']:.4f} m³; edge length mean {stats['edge_length_m']['mean'] * 1e3:.1f} mm; "
          f"radius ratio min {stats['radius_ratio']['min']:.3f}, 1st percentile "
          f"{stats['radius_ratio']['p01']:.3f}")
    for name, vol in stats["part_volume_m3"].items():
        print(f"  part {name:15s} {vol:.5f} m³")
    for g in stats["convection_groups"]:
        print(f"  convection {g['name']:13s} {g['area_m2']:.3f} m²  h = {g['coefficient_W_m2K']:g} W/(m² K)  "
              f"zone {g['zone']}")
    print(f"  adiabatic remainder {stats['adiabatic_area_m2']:.3f} m²")
    print(f"mesh {'read from cache' if stats['from_cache'] else 'built'} in {stats['seconds']} s: "
          f"{stats['cache_file']}")
    if stats.get("shipped"):
        print(f"copied into meshes/cache: {', '.join(stats['shipped'])}")
    print(f"statistics and render in {out_dir}/")


def cmd_report(args: argparse.Namespace) -> None:
    """``twin report``: plots and summary of an existing dataset.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    from .summary import format_summary
    from .workflows import report_dataset

    column_map = read_column_map(args.column_map)
    summary, out_dir = report_dataset(args.dataset, args.out, column_map, args.nan_policy,
                                      iso_test=args.iso, overwrite=args.overwrite)
    print(format_summary(summary))
    print(f"report in {out_dir}/")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``run``, ``mesh`` and ``report`` commands.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The ``twin`` parser's subparsers.
    """
    run = sub.add_parser("run", help="simulate a scenario and write dataset, plots and summary")
    run.add_argument("scenario", help="scenario name or path to its TOML file")
    run.add_argument("--machine", help="machine name or TOML path (default: the scenario's)")
    run.add_argument("--mesh-size", type=mesh_size, help="target tetrahedron edge length, m")
    run.add_argument("--out", help="result folder (default runs/<scenario>)")
    run.add_argument("--fields", action="store_true", help="also write VTK temperature fields")
    run.add_argument("--camera", action="store_true", help="record the thermal-camera spots in the dataset")
    run.add_argument("--no-views", action="store_true",
                     help="skip the 3-D temperature and deformed-shape views (and their elastic solves)")
    add_overwrite(run)
    run.set_defaults(func=cmd_run)

    mesh = sub.add_parser("mesh", help="build and cache a machine's mesh; print statistics; render it")
    mesh.add_argument("machine", nargs="?", default="vmc_ram")
    mesh.add_argument("--mesh-size", type=mesh_size, help="target tetrahedron edge length, m")
    mesh.add_argument("--out", help="folder for statistics and render (default runs/mesh_<machine>)")
    mesh.add_argument("--rebuild", action="store_true", help="mesh again even if cached")
    mesh.add_argument("--ship", action="store_true",
                      help="copy the mesh and output operator into meshes/cache (for committing)")
    add_overwrite(mesh)
    mesh.set_defaults(func=cmd_mesh)

    report = sub.add_parser("report", help="plots and summary of an existing (twin or measured) dataset")
    report.add_argument("dataset", help="CSV file (with or without a JSON sidecar)")
    report.add_argument("--out", help="folder (default runs/report_<name>)")
    report.add_argument("--column-map", help="JSON file or inline JSON mapping CSV columns to <name>_<unit> (null leaves a column out)")
    report.add_argument("--nan-policy", default="error", choices=["error", "interpolate", "drop"])
    report.add_argument("--iso", choices=["spindle", "etve"], help="also report the ISO 230-3 quantities")
    add_overwrite(report)
    report.set_defaults(func=cmd_report)


