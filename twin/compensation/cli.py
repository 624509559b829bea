"""CLI commands ``twin train``, ``twin evaluate`` and ``twin study``.

A thin layer over :mod:`twin.compensation.train` and :mod:`twin.compensation.studies`: parse, call, print where
the results went.
"""
from __future__ import annotations

import argparse
import sys

from ..errors import TwinInputError
from ..infra.cli_common import (
    add_cluster_options,
    add_overwrite,
    read_column_map,
    split_names,
)
from ..infra.progress import progress_bar

# Handlers import the library inside them, never up here: start-up time (`twin --help` must not load scipy).
# So twin.core.unit_hints.TYPICAL_TOP is copied here for --help (tests/test_train_input_units.py keeps it equal).
TYPICAL_TOP_RPM = 12000
TYPICAL_TOP_FEED_M_MIN = 30


def _datasets_help():
    return ("dataset CSV (a twin dataset with its .json sidecar, or a measured CSV with <name>_<unit> columns "
            "or a --column-map), or a scenario name (simulated with its sensor noise)")


def cmd_train(args: argparse.Namespace) -> None:
    """``twin train``: fit a compensation model on datasets, refuse or flag an unstable one, save it, print its fit.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    from .store import parse_params
    from .train import train

    cm = train(args.datasets, args.inputs, args.target, model=args.model, params=parse_params(args.param),
               out=args.out, zero_reference=not args.no_zero_reference, reference_samples=args.reference_samples,
               column_map=_column_map(args), nan_policy=args.nan_policy, machine=args.machine,
               overwrite=args.overwrite, select=args.select, allow_unstable=args.allow_unstable,
               observe=args.observe)
    if "selection" in cm.metadata:
        print(f"--select auto {cm.metadata['selection']['reason']}")
    if "unstable" in cm.metadata:
        print(f"WARNING: MODEL SAVED DESPITE ITS CHECK (--allow-unstable): {cm.metadata['unstable']}", file=sys.stderr)
    print(f"trained {cm.describe()}")
    print(f"on {', '.join(t['label'] for t in cm.training)}"
          f"{' (zero-referenced per dataset)' if cm.preprocessing['zero_reference'] else ''}")
    for label, s in cm.metadata["training_metrics"].items():
        print(f"  {label}: RMSE {s['rmse']:.3g}, max residual {s['max_residual']:.3g} {cm.target_unit}, "
              f"improvement {s['improvement_percent']:.1f} %")
    parameters = getattr(cm.estimator, "parameter_summary", None)   # the grey-box model's τ and b, with intervals
    if parameters is not None:
        print(f"  fitted {parameters()}")
    print(f"model saved to {args.out}")


def cmd_evaluate(args: argparse.Namespace) -> None:
    """``twin evaluate``: score a saved model on datasets, print the table, write it and the plots with ``--out``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    from .train import evaluate

    ev = evaluate(args.model, args.datasets, out_dir=args.out, column_map=_column_map(args),
                  nan_policy=args.nan_policy, machine=args.machine, plots=not args.no_plots, overwrite=args.overwrite,
                  reference=args.reference, history=args.history, gap=args.gap)
    print(ev.table(), end="")
    if ev.out_dir is not None:
        print(f"table and plots in {ev.out_dir}/")


def _column_map(args):
    return read_column_map(getattr(args, "column_map", None))


def cmd_study(args: argparse.Namespace) -> None:
    """``twin study``: run the cross-condition, thesis-protocol or hybrid study, print its Markdown report.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    if args.physics is not None and args.study != "hybrid":
        # the other studies have no physics half: a silently ignored --physics would look as if it had been used
        raise TwinInputError(f"--physics applies to the hybrid study only, not to {args.study}")
    from . import studies

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
                                   physics_backend=args.physics or "fe", out_dir=out, **common)
    print(res.markdown)
    print(f"results in {res.out_dir}/")


def _add_data_options(p):
    p.add_argument("--column-map", help="JSON file or inline JSON mapping measured CSV columns to <name>_<unit> (null leaves a column out)")
    p.add_argument("--nan-policy", default="error", choices=("error", "interpolate", "drop", "keep"),
                   help="NaNs in the channels the model reads from a measured CSV (default: error; NaNs in "
                   "other columns are kept and harm nothing); keep: missing readings of the thermometers the "
                   "model observes (--observe), left out of its fit and skipped by its filter (anywhere else "
                   "they are refused)")
    p.add_argument("--machine", help="machine name or TOML path of the records, read without a mesh: a measured "
                   "CSV's spindle and feed columns are warned about when they peak where one in krpm or Hz (feeds: "
                   "m/min) would, judged against its top speed and feed (default: a typical machining centre's "
                   f"{TYPICAL_TOP_RPM} rpm and {TYPICAL_TOP_FEED_M_MIN} m/min); a scenario named among the datasets "
                   "runs on it (default: the scenario's machine)")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``train``, ``evaluate`` and ``study``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``twin`` command.
    """
    t = sub.add_parser("train", help="train a compensation model on datasets and save it (JSON, no pickle)")
    t.add_argument("datasets", nargs="+", help=_datasets_help() + "; in any order (fitted by first time stamp, "
                   "then content); records whose clocks continue one another are one record, the others separate "
                   "records (each from rest for --model greybox)")
    t.add_argument("--inputs", required=True, action="append", help="input channels, comma-separated")
    t.add_argument("--target", required=True, help="target channel, e.g. Z")
    t.add_argument("--observe", action="append", help="thermometers the model fuses while it runs (its Kalman "
                   "observer; --model greybox), comma-separated: outputs of the model, corrected by their readings")
    t.add_argument("--model", default="anfis", help="model name, e.g. mlr, pcr, anfis, gm1n (default anfis = ANFIS-FCM); an unknown name lists "
                   "them all (the registry is read on use: `--help` must not load numpy)")
    t.add_argument("--select", choices=("auto",), help="choose the model by blocked cross-validation across the "
                   "records' speed regimes (leave one block out, rolling origin; geometric mean of the folds' RMSE), "
                   "grey-box orders 1-3 included, and print why; overrides --model")
    t.add_argument("--allow-unstable", action="store_true",
                   help="save an unstable grey fit (a < 0 or diverging on its training data), or a grey-box fit "
                        "whose slowest time constant is longer than its longest training record or on its upper "
                        "bound, instead of refusing it")
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
    e.add_argument("--reference", choices=("own", "train"), default="own",
                   help="zero reference: each record's own start (default) or the training start, for a record that "
                   "continues the training one (starts warm)")
    e.add_argument("--history", help="with --reference train: the training record (of several, the one continued), "
                   "over which time-series models run before the evaluated ones (records in time order continue one "
                   "another)")
    e.add_argument("--gap", choices=("refuse", "interpolate"), default="refuse",
                   help="with --reference train, a record that starts later than one sampling interval after the "
                   "history ends: refuse it (default), or bridge the missing rows by interpolating the inputs")
    add_overwrite(e)
    _add_data_options(e)
    e.set_defaults(func=cmd_evaluate)

    s = sub.add_parser("study", help="compensation studies: cross-condition transfer, thesis protocol, hybrid")
    s.add_argument("study", choices=("cross-condition", "thesis", "hybrid"))
    s.add_argument("--model", help="model name (cross-condition: mlr; thesis: anfis,mlr; hybrid: anfis)")
    s.add_argument("--inputs", action="append", help="fixed input channels (default: chosen per training set)")
    s.add_argument("--k", type=int, default=4, help="number of inputs chosen when --inputs is not given (1 to the "
                   "machine's installed thermometers; fewer where fewer move on the training records)")
    s.add_argument("--axes", default="Z,Y", help="drift axes (default Z,Y)")
    # default None, not "fe": a --physics given to another study is refused, so "given" must be visible
    s.add_argument("--physics", choices=("fe", "rom"), help="hybrid: physics backend (default fe)")
    s.add_argument("--out", help="result folder (default runs/study_<name>)")
    add_overwrite(s)
    add_cluster_options(s)
    s.set_defaults(func=cmd_study)
