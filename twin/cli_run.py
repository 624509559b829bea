"""CLI commands ``twin run`` and ``twin mesh``."""
from __future__ import annotations

from .progress import progress_bar


def cmd_run(args):
    from .workflows import run_scenario

    out = run_scenario(args.scenario, machine=args.machine, mesh_size_m=args.mesh_size, out_dir=args.out,
                       fields=args.fields, progress=progress_bar("simulating"),
                       camera=True if args.camera else None)
    from .summary import format_summary

    print(format_summary(out.summary))
    print(f"results in {out.out_dir}/")


def cmd_mesh(args):
    from .workflows import mesh_machine

    stats, out_dir = mesh_machine(args.machine, args.mesh_size, args.out, rebuild=args.rebuild, ship=args.ship)
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


def cmd_report(args):
    import json

    from .summary import format_summary
    from .workflows import report_dataset

    column_map = json.loads(open(args.column_map).read()) if args.column_map else None
    summary, out_dir = report_dataset(args.dataset, args.out, column_map, args.nan_policy,
                                      iso_test=args.iso)
    print(format_summary(summary))
    print(f"report in {out_dir}/")


def register(sub):
    """Add the ``run`` and ``mesh`` commands."""
    run = sub.add_parser("run", help="simulate a scenario and write dataset, plots and summary")
    run.add_argument("scenario", help="scenario name or path to its TOML file")
    run.add_argument("--machine", help="machine name or TOML path (default: the scenario's)")
    run.add_argument("--mesh-size", type=float, help="target tetrahedron edge length, m")
    run.add_argument("--out", help="result folder (default runs/<scenario>)")
    run.add_argument("--fields", action="store_true", help="also write VTK temperature fields")
    run.add_argument("--camera", action="store_true", help="record the thermal-camera spots in the dataset")
    run.set_defaults(func=cmd_run)

    mesh = sub.add_parser("mesh", help="build and cache a machine's mesh; print statistics; render it")
    mesh.add_argument("machine", nargs="?", default="vmc_ram")
    mesh.add_argument("--mesh-size", type=float, help="target tetrahedron edge length, m")
    mesh.add_argument("--out", help="folder for statistics and render (default runs/mesh_<machine>)")
    mesh.add_argument("--rebuild", action="store_true", help="mesh again even if cached")
    mesh.add_argument("--ship", action="store_true",
                      help="copy the mesh and output operator into meshes/cache (for committing)")
    mesh.set_defaults(func=cmd_mesh)

    report = sub.add_parser("report", help="plots and summary of an existing (twin or measured) dataset")
    report.add_argument("dataset", help="CSV file (with or without a JSON sidecar)")
    report.add_argument("--out", help="folder (default runs/report_<name>)")
    report.add_argument("--column-map", help="JSON file mapping CSV columns to <name>_<unit>")
    report.add_argument("--nan-policy", default="error", choices=["error", "interpolate", "drop"])
    report.add_argument("--iso", choices=["spindle", "etve"], help="also report the ISO 230-3 quantities")
    report.set_defaults(func=cmd_report)


