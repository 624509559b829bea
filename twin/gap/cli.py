"""CLI commands ``twin gap diagnose``, ``truth`` and ``benchmark``: a thin layer over :mod:`twin.gap`."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..errors import TwinInputError
from ..infra.cli_common import add_overwrite, mesh_size, read_column_map
from ..infra.outdir import check_output_file, check_output_folder
from ..infra.progress import progress_bar

# Handlers import the library inside them, never up here: start-up time (`twin --help` must not load scipy).
# So twin.gap.benchmark's truth-run defaults are copied here (tests/test_cli_startup.py keeps them equal).
SCENARIO = "gap_blind_24h"
INDEPENDENT_SCENARIO = "gap_independent_24h"
TRUTH_MESH_SIZE_M = 0.035


def cmd_diagnose(args: argparse.Namespace) -> None:
    """``twin gap diagnose``: diagnose a measured record, write the report folder, print the verdict and ranking.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line: ``measured``, ``machine``, ``scenario``, ``column_map``, ``holdout``
        (fraction), ``effects``, ``pairs``, ``backend``, ``step`` (s), ``no_render``, ``out``, ``overwrite``.
    """
    from ..core.dataset import sidecar_path
    from .diagnose import diagnose
    from .report import write_report
    from .verdict import role

    given = (args.measured, sidecar_path(args.measured), args.column_map, args.scenario, args.machine)
    check_output_folder(args.out, args.overwrite, inputs=given)
    d = diagnose(args.measured, machine=args.machine, scenario=args.scenario,
                 column_map=read_column_map(args.column_map), holdout_fraction=args.holdout,
                 effects=args.effects, n_pairs=args.pairs, backend=args.backend,
                 step_s=args.step, progress=progress_bar("fitting effects", unit="fit"))
    out = write_report(d, args.out, render=not args.no_render, overwrite=args.overwrite)
    for warning in d.record.report["warnings"]:
        print(f"twin gap diagnose: warning: {warning}", file=sys.stderr)
    print(d.verdict)
    for r in d.ranking[:5]:
        named = f"  ← {role(d, r)}" if role(d, r) else ""
        print(f"  {r.name:42s} ΔBIC {r.delta_bic:9.1f}{named}")
    if d.winner is not None and d.ranking[0] is not d.winner:
        print("  (a model ranked above the named one adds an effect to it that the decision rules do not accept: "
              "the named effect leaves no significant gap, or the addition is not material; see report.md)")
    print(f"report in {out}/report.md ({d.timings['total_s']:.0f} s)")


def cmd_benchmark(args: argparse.Namespace) -> None:
    """``twin gap benchmark``: run the blind (or, with ``--independent``, the independent) benchmark; print its report.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line: ``cases``, ``independent``, ``scenario``, ``truth_mesh_size`` (m; ≤ 0: the
        nominal mesh), ``holdout`` (fraction), ``scheduler``, ``workers``, ``out``, ``overwrite``.
    """
    from .benchmark import benchmark, independent_benchmark

    if args.independent:
        given = [flag for flag, value in (("--holdout", args.holdout), ("--truth-mesh-size", args.truth_mesh_size))
                 if value is not None]
        if given:
            raise TwinInputError(f"twin gap benchmark --independent: {' and '.join(given)} do(es) not apply; each "
                                 "independent case fixes its own truth mesh and hold-out (docs/gap_benchmark.md)")
        res = independent_benchmark(args.independent, scheduler=args.scheduler, out_dir=args.out,
                                    scenario=args.scenario or INDEPENDENT_SCENARIO,
                                    progress=progress_bar("independent cases", unit="case"), n_workers=args.workers,
                                    overwrite=args.overwrite)
        print(res.markdown)
        print(f"results in {res.out_dir}/")
        return
    mesh_size = TRUTH_MESH_SIZE_M if args.truth_mesh_size is None else args.truth_mesh_size
    res = benchmark(args.cases, scheduler=args.scheduler, out_dir=args.out, scenario=args.scenario or SCENARIO,
                    truth_mesh_size_m=None if mesh_size <= 0 else mesh_size,
                    holdout_fraction=0.3 if args.holdout is None else args.holdout,
                    progress=progress_bar("blind cases", unit="case"), n_workers=args.workers, overwrite=args.overwrite)
    print(res.markdown)
    print(f"results in {res.out_dir}/")


def cmd_truth(args: argparse.Namespace) -> None:
    """``twin gap truth``: write a benchmark case's "measured" CSV, its hidden truth in ``<stem>.truth.json`` beside it.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line: ``effect`` (one effect, an ``a+b`` pair or ``none``), ``scenario``, ``machine``,
        ``truth_mesh_size`` (m; ≤ 0: the nominal mesh), ``out``, ``overwrite``.
    """
    from ..core.dataset import sidecar_path
    from .benchmark import case_record, cases

    if "," in args.effect or args.effect in ("all", "singles", "pairs"):
        raise TwinInputError(f"--effect takes one effect, one a+b pair or 'none', got {args.effect!r}")
    out = Path(args.out)
    truth = out.with_name(out.stem + ".truth.json")
    for path in (out, sidecar_path(out), truth):
        check_output_file(path, args.overwrite)
    case = cases(args.effect)[0]
    out.parent.mkdir(parents=True, exist_ok=True)
    data = case_record(case, args.scenario, args.machine,
                       None if args.truth_mesh_size <= 0 else args.truth_mesh_size)
    data.write(out)
    # the truth goes beside the CSV, not into its sidecar: the diagnosis must not see it
    sidecar_path(out).replace(truth)
    print(f"measured record {out} ({len(data)} rows, {len(data.channels)} channels); "
          f"hidden truth in {truth.name}: {json.dumps(data.metadata['effects'])}")


def _truth_mesh_size(text: str) -> float:
    """``--truth-mesh-size``: 0 (the nominal mesh) or a mesh size, m (argparse ``type``)."""
    return 0.0 if text.strip() in ("0", "0.0") else mesh_size(text)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``gap`` command with its ``diagnose``, ``truth`` and ``benchmark`` subcommands.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``twin`` command line.
    """
    gap = sub.add_parser("gap", help="sim-to-real gap diagnosis of the twin against measured data")
    gsub = gap.add_subparsers(dest="gap_command", required=True)
    d = gsub.add_parser("diagnose", help="where the twin misses, which effect explains it, how far it shrinks")
    d.add_argument("--measured", required=True,
                   help="measured CSV (<name>_<unit> columns, or with --column-map) or a twin dataset CSV")
    d.add_argument("--machine", default="vmc_ram", help="machine name or TOML path (default vmc_ram)")
    d.add_argument("--scenario", help="scenario for missing inputs: the spindle speed and feeds when the data has "
                                      "none, the room zone's ambient when no air sensor is in the room zone; "
                                      "other zones without an air sensor follow the room air, not the scenario")
    d.add_argument("--column-map", help='JSON file or inline JSON mapping CSV columns, e.g. {"t1": "T01_degC", "spare": null} (null leaves a column out)')
    d.add_argument("--holdout", type=float, default=0.3, help="held-out last fraction of the record (default 0.3)")
    d.add_argument("--effects", help="comma list of candidate effects (default: the whole library)")
    d.add_argument("--pairs", type=int, default=3, help="pairs: the leading effect with every other, and pairs of the top N (default 3; 0 none)")
    d.add_argument("--backend", choices=("rom", "fe"), default="rom",
                   help="parametric reduced model (default) or full finite elements (slow)")
    d.add_argument("--step", type=float, default=60.0, help="the twin's time step, s (default 60)")
    d.add_argument("--no-render", action="store_true", help="skip the 3-D renders")
    d.add_argument("--out", required=True, help="result folder (report.md, diagnosis.json, figures)")
    add_overwrite(d)
    d.set_defaults(func=cmd_diagnose)

    t = gsub.add_parser("truth", help="a synthetic 'measured' CSV with an effect of the library switched on "
                                      "(the benchmark's truth run), to try the diagnosis on")
    t.add_argument("--effect", required=True,
                   help="effect of the library at its benchmark value, an a+b pair, or 'none'")
    t.add_argument("--scenario", default=SCENARIO, help=f"truth scenario (default {SCENARIO})")
    t.add_argument("--machine", default="vmc_ram")
    t.add_argument("--truth-mesh-size", type=_truth_mesh_size, default=TRUTH_MESH_SIZE_M,
                   help=f"truth mesh size, m (default {TRUTH_MESH_SIZE_M}; 0 = the nominal mesh)")
    t.add_argument("--out", required=True, help="CSV to write (the truth goes to <stem>.truth.json beside it)")
    add_overwrite(t, "file")
    t.set_defaults(func=cmd_truth)

    b = gsub.add_parser("benchmark", help="blind check: effects switched on in a finer, noisy truth, then diagnosed")
    b.add_argument("--cases", default="all",
                   help="all | singles | pairs | none | comma list of effects or a+b pairs (default all)")
    b.add_argument("--independent", metavar="CASES",
                   help="run the independent benchmark instead (truth: changed physics in the full FE, sensor "
                        "errors and sampling written apart from the library): library | outside | pairs | controls "
                        "| checks | all | comma list of case names")
    b.add_argument("--scenario", help=f"truth scenario (default {SCENARIO}; with --independent "
                                      f"{INDEPENDENT_SCENARIO})")
    b.add_argument("--truth-mesh-size", type=_truth_mesh_size,
                   help=f"truth mesh size, m (default {TRUTH_MESH_SIZE_M}; 0 = the nominal mesh; not with "
                        "--independent)")
    b.add_argument("--holdout", type=float, help="held-out last fraction (default 0.3; not with --independent)")
    b.add_argument("--scheduler", default="local", help="local (default), serial, or tcp://HOST:8786")
    b.add_argument("--workers", type=int, help="local Dask workers (default: one per core)")
    b.add_argument("--out", default="runs/gap_benchmark", help="result folder (default runs/gap_benchmark)")
    add_overwrite(b)
    b.set_defaults(func=cmd_benchmark)
