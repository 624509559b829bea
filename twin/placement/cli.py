"""CLI command ``twin place``: a thin layer over :func:`twin.placement.study.placement_study`."""
from __future__ import annotations

import argparse

from ..infra.cli_common import add_cluster_options, add_overwrite, split_names
from ..infra.progress import progress_bar

# The handler imports the library inside it, never up here: start-up time (`twin --help` must not load scipy).


def _listed(value: str | None, default: tuple) -> tuple:
    """A comma-separated list option: ``default`` when the option is not given; else its names, maybe none (an
    empty list given on purpose, or by an unset shell variable, is the study's to refuse, not the default)."""
    return default if value is None else tuple(split_names(value))


def cmd_place(args: argparse.Namespace) -> None:
    """``twin place``: run the placement study, print its summary and where the report went.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    """
    from .candidates import DEFAULT_PARTS
    from .selection import METHODS
    from .study import DEFAULT_TEST, DEFAULT_TRAIN, DEFAULT_VALIDATION, placement_study

    res = placement_study(machine=args.machine, mesh_size_m=args.mesh_size, parts=_listed(args.parts, DEFAULT_PARTS),
                          n_candidates=args.candidates, camera=not args.no_camera,
                          train=_listed(args.train, DEFAULT_TRAIN),
                          validation=_listed(args.validation, DEFAULT_VALIDATION),
                          test=_listed(args.test, DEFAULT_TEST), methods=_listed(args.methods, METHODS),
                          k_max=args.k_max, axes=_listed(args.axes, ()), record_interval_s=args.record_interval,
                          scheduler=args.scheduler, use_cache=not args.no_cache, out_dir=args.out,
                          progress=progress_bar("simulating", unit="simulation"),
                          response_horizon_s=args.response_horizon * 3600.0, overwrite=args.overwrite)
    print(res.summary)
    print(f"report, tables, candidate scores and render in {res.out_dir}/")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``place``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``twin`` command.
    """
    p = sub.add_parser("place", help="sensor-placement study: candidates, selection methods, K × method table")
    p.add_argument("--parts", help="parts whose surface nodes are candidates (default: all outer parts)")
    p.add_argument("--candidates", type=int, default=2000,
                   help="surface candidates after thinning (default 2000; 0: the camera spots only)")
    p.add_argument("--no-camera", action="store_true", help="leave the camera spots out of the candidates")
    p.add_argument("--train", help="training scenarios, comma-separated")
    p.add_argument("--validation", help="validation scenarios (choose method and K), comma-separated")
    p.add_argument("--test", help="test scenarios (score the chosen sets once), comma-separated")
    p.add_argument("--methods", help="selection methods, comma-separated (default: all)")
    p.add_argument("--k-max", type=int, default=8, help="the largest number of sensors K (default 8)")
    p.add_argument("--axes", default="Z,Y", help="drift axes, comma-separated: X, Y, Z, Y_top (default Z,Y)")
    p.add_argument("--record-interval", type=float, default=60.0, help="recording interval, s (default 60)")
    p.add_argument("--response-horizon", type=float, default=48.0,
                   help="greedy-physics: length of the elementary step responses, h (default 48)")
    p.add_argument("--no-cache", action="store_true", help="simulate again even if records are cached")
    p.add_argument("--out", default="runs/placement", help="result folder (default runs/placement)")
    add_overwrite(p)
    add_cluster_options(p)
    p.set_defaults(func=cmd_place)
