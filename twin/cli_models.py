"""CLI commands ``twin train``, ``twin evaluate``, ``twin study`` and ``twin place``.

A thin layer over :mod:`twin.compensation`, :mod:`twin.studies` and
:mod:`twin.placement`: parse, call, print where the results went.
"""
from __future__ import annotations

from .cli_common import add_overwrite
from .progress import progress_bar

# Handlers import the library inside them, never up here: start-up time (`twin --help` must not load scipy).


def _datasets_help():
    return ("dataset CSV (a twin dataset with its .json sidecar, or a measured CSV with <name>_<unit> columns "
            "or a --column-map), or a scenario name (simulated with its sensor noise)")


def cmd_train(args):
    from .compensation import train
    from .model_store import parse_params

    cm = train(args.datasets, args.inputs, args.target, model=args.model, params=parse_params(args.param),
               out=args.out, zero_reference=not args.no_zero_reference, reference_samples=args.reference_samples,
               column_map=_column_map(args), nan_policy=args.nan_policy, overwrite=args.overwrite)
    print(f"trained {cm.describe()}")
    print(f"on {', '.join(t['label'] for t in cm.training)}"
          f"{' (zero-referenced per dataset)' if cm.preprocessing['zero_reference'] else ''}")
    for label, s in cm.metadata["training_metrics"].items():
        print(f"  {label}: RMSE {s['rmse']:.3g}, max residual {s['max_residual']:.3g} {cm.target_unit}, "
              f"improvement {s['improvement_percent']:.1f} %")
    print(f"model saved to {args.out}")


def cmd_evaluate(args):
    from .compensation import evaluate

    ev = evaluate(args.model, args.datasets, out_dir=args.out, column_map=_column_map(args),
                  nan_policy=args.nan_policy, plots=not args.no_plots, overwrite=args.overwrite)
    print(ev.table(), end="")
    if ev.out_dir is not None:
        print(f"table and plots in {ev.out_dir}/")


def _column_map(args):
    from .compensation import read_column_map

    return read_column_map(getattr(args, "column_map", None))


def cmd_study(args):
    from . import studies
    from .compensation import split_names

    common = dict(machine=args.machine, mesh_size_m=args.mesh_size, scheduler=args.scheduler,
                  progress=progress_bar("simulating", unit="scenario"), overwrite=args.overwrite)
    inputs = split_names(args.inputs) or None
    axes = tuple(split_names(args.axes))
    if args.study == "cross-condition":
        out = args.out or "runs/study_cross_condition"
        res = studies.cross_condition_study(axes=axes, model=args.model or "mlr", inputs=inputs, k=args.k,
                                            out_dir=out, **common)
    elif args.study == "thesis":
        out = args.out or "runs/study_thesis"
        res = studies.thesis_protocol_study(axes=axes, models=tuple(split_names(args.model or "anfis,mlr")),
                                            inputs=inputs, k=args.k, out_dir=out, **common)
    else:
        out = args.out or "runs/study_hybrid"
        res = studies.hybrid_study(axes=axes, model=args.model or "anfis", inputs=inputs, k=args.k,
                                   physics_backend=args.physics, out_dir=out, **common)
    print(res.markdown)
    print(f"results in {res.out_dir}/")


def cmd_place(args):
    from .compensation import split_names
    from .placement import DEFAULT_PARTS, DEFAULT_TEST, DEFAULT_TRAIN, METHODS, placement_study

    res = placement_study(machine=args.machine, mesh_size_m=args.mesh_size,
                          parts=split_names(args.parts) or DEFAULT_PARTS, n_candidates=args.candidates,
                          camera=not args.no_camera, train=split_names(args.train) or DEFAULT_TRAIN,
                          test=split_names(args.test) or DEFAULT_TEST, methods=split_names(args.methods) or METHODS,
                          k_max=args.k_max, axes=tuple(split_names(args.axes)), record_interval_s=args.record_interval,
                          scheduler=args.scheduler, use_cache=not args.no_cache, out_dir=args.out,
                          progress=progress_bar("simulating", unit="simulation"),
                          response_horizon_s=args.response_horizon * 3600.0, overwrite=args.overwrite)
    print(res.summary)
    print(f"report, tables, candidate scores and render in {res.out_dir}/")


def _add_data_options(p):
    p.add_argument("--column-map", help="JSON file or inline JSON mapping measured CSV columns to <name>_<unit>")
    p.add_argument("--nan-policy", default="error", choices=("error", "interpolate", "drop"),
                   help="NaNs in a measured CSV (default: error)")


def _add_cluster_options(p):
    p.add_argument("--machine", default="vmc_ram", help="machine name or TOML path")
    p.add_argument("--mesh-size", type=float, help="target tetrahedron edge length, m")
    p.add_argument("--scheduler", default="local",
                   help="'local' (a local Dask cluster, default), 'serial', or tcp://HOST:8786 for an existing one")


def register(sub):
    """Add ``train``, ``evaluate``, ``study`` and ``place``."""
    from .model_names import MODEL_NAMES

    t = sub.add_parser("train", help="train a compensation model on datasets and save it (JSON, no pickle)")
    t.add_argument("datasets", nargs="+", help=_datasets_help())
    t.add_argument("--inputs", required=True, action="append", help="input channels, comma-separated")
    t.add_argument("--target", required=True, help="target channel, e.g. Z")
    t.add_argument("--model", default="anfis", help=f"model: {', '.join(sorted(MODEL_NAMES))} (default anfis = ANFIS-FCM)")
    t.add_argument("--param", action="append", metavar="NAME=VALUE", help="model hyperparameter (repeatable)")
    t.add_argument("--out", required=True, help="model file to write (.json)")
    add_overwrite(t, "file")
    t.add_argument("--no-zero-reference", action="store_true",
                   help="use raw values instead of the change since each dataset's start")
    t.add_argument("--reference-samples", type=int, default=1,
                   help="rows averaged for each dataset's reference (default 1)")
    _add_data_options(t)
    t.set_defaults(func=cmd_train)

    e = sub.add_parser("evaluate", help="score a saved model on datasets: table and measured-vs-predicted plots")
    e.add_argument("model", help="model file written by `twin train`")
    e.add_argument("datasets", nargs="+", help=_datasets_help())
    e.add_argument("--out", help="folder for the table and plots (default: print the table only)")
    e.add_argument("--no-plots", action="store_true")
    add_overwrite(e)
    _add_data_options(e)
    e.set_defaults(func=cmd_evaluate)

    s = sub.add_parser("study", help="compensation studies: cross-condition transfer, thesis protocol, hybrid")
    s.add_argument("study", choices=("cross-condition", "thesis", "hybrid"))
    s.add_argument("--model", help="model name (cross-condition: mlr; thesis: anfis,mlr; hybrid: anfis)")
    s.add_argument("--inputs", action="append", help="fixed input channels (default: chosen per training set)")
    s.add_argument("--k", type=int, default=4, help="number of inputs chosen when --inputs is not given")
    s.add_argument("--axes", default="Z,Y", help="drift axes (default Z,Y)")
    s.add_argument("--physics", default="fe", choices=("fe", "rom"), help="hybrid: physics backend")
    s.add_argument("--out", help="result folder (default runs/study_<name>)")
    add_overwrite(s)
    _add_cluster_options(s)
    s.set_defaults(func=cmd_study)

    p = sub.add_parser("place", help="sensor-placement study: candidates, selection methods, K × method table")
    p.add_argument("--parts", help="parts whose surface nodes are candidates (default: all outer parts)")
    p.add_argument("--candidates", type=int, default=2000, help="surface candidates after thinning (default 2000)")
    p.add_argument("--no-camera", action="store_true", help="leave the camera spots out of the candidates")
    p.add_argument("--train", help="training scenarios, comma-separated")
    p.add_argument("--test", help="held-out scenarios, comma-separated")
    p.add_argument("--methods", help="selection methods, comma-separated (default: all)")
    p.add_argument("--k-max", type=int, default=8)
    p.add_argument("--axes", default="Z,Y")
    p.add_argument("--record-interval", type=float, default=60.0, help="recording interval, s (default 60)")
    p.add_argument("--response-horizon", type=float, default=48.0,
                   help="greedy-physics: length of the elementary step responses, h (default 48)")
    p.add_argument("--no-cache", action="store_true", help="simulate again even if records are cached")
    p.add_argument("--out", default="runs/placement", help="result folder (default runs/placement)")
    add_overwrite(p)
    _add_cluster_options(p)
    p.set_defaults(func=cmd_place)
