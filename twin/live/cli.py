"""``twin live``: the observer beside a running machine over OPC UA, or against a replayed dataset.

    twin live --endpoint opc.tcp://HOST:4840/ --node-map machine.toml --log drift.csv
    twin live --replay DATASET.csv --speed 600 --log drift.csv
"""
from __future__ import annotations

import sys
from contextlib import contextmanager
from typing import TYPE_CHECKING

from ..errors import TwinInputError
from ..infra.cli_common import add_overwrite, check_distinct, split_names
from ..rom.cli import DEFAULT_ORDER

if TYPE_CHECKING:
    import argparse

    from ..core.dataset import Dataset
    from .client import LiveStats
    from .observer import RecordRunner

#: The observer's thermometers unless told: :func:`twin.live.observer.choose_thermometers` for vmc_ram
#: (order 80, Z axis, k = 6; model-based, no record used).
DEFAULT_THERMOMETERS = ("T18", "T26", "T23", "T22", "T16", "T09")
DEFAULT_SPEED = 600.0
#: Exit code of a session that fused no sample, ended without a connection to the server, or stopped on an
#: estimate that is not finite.
EXIT_NOT_OBSERVED = 1
#: Exit code of a session ended by Ctrl-C: the shell's code for a process ended by SIGINT (128 + 2), as ``twin``'s.
EXIT_INTERRUPTED = 130
#: Which bands the calibration checked (docs/live.md, "Calibration protocol"), said in every summary.
BANDS_NOTE = ("bands: the Z band is calibrated on training FE records (92.1 % held-out coverage); the X band × 5 "
              "and the Y band × 1.25, factors chosen on the same training records, held 82.0 % and 97.8 % on the "
              "held-out records, X below the 90–99 % aimed at (docs/live.md, \"Which bands are calibrated\")")
#: The dataset channel kinds a replay option can name (a measured CSV's °C columns are all "temperature";
#: a thermometer may be a camera spot).
OPTION_KINDS = {"--spindle": ("spindle_speed",), "--room-air": ("air", "ambient", "temperature"),
                "thermometer": ("temperature", "air", "camera")}


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nothing listens on now (the OS picks it).

    Parameters
    ----------
    host : str
        The address the port is for.

    Returns
    -------
    int
        The port number.
    """
    import socket

    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def _observer(args, default):
    """``(observer, thermometers)``: the ROM's observer reading ``--thermometers``, else the placement's chosen
    set (``--thermometers-from``), else ``default``."""
    from ..core.machine import build_machine
    from ..rom.reduction import cached_rom
    from .multiple_model import live_observer
    from .placement import placement_rom, read_placement

    machine = build_machine(args.machine)
    if args.thermometers_from:
        placed = read_placement(args.thermometers_from, args.placement_axis)
        rom = placement_rom(cached_rom(machine, args.order, keep_basis=True), machine, placed)
        thermometers = split_names(args.thermometers) or placed.names
        return live_observer(rom, thermometers, placed.sensors, at_rest=args.at_rest), thermometers
    thermometers = split_names(args.thermometers) or list(default)
    return live_observer(cached_rom(machine, args.order), thermometers, at_rest=args.at_rest), thermometers


@contextmanager
def _kept(args, observer):
    """``observer`` kept in ``--state`` (:class:`~twin.live.resume.KeptObserver`: resumed from it, saved to it, last
    when the session ends, however it ends), or as it is without ``--state``."""
    if not args.state:
        yield observer
        return
    from .resume import KeptObserver

    kept = KeptObserver(observer, args.state)
    try:
        yield kept
    finally:
        kept.save()


def _channels_of(dataset, kinds):
    """The channels of ``kinds`` as a short text: camera spots only counted (a camera has hundreds)."""
    named = dataset.names_of_kind(*(k for k in kinds if k != "camera"))
    spots = dataset.names_of_kind("camera") if "camera" in kinds else []
    text = ", ".join(named) or "none"
    return text + (f" and {len(spots)} camera spots ({spots[0]} … {spots[-1]})" if spots else "")


def check_replay_channels(dataset: Dataset, path: str, channels: dict[str, list[str]]) -> None:
    """Check that the dataset has the channels the replay options name, of the kinds they take, each named once.

    Parameters
    ----------
    dataset : Dataset
        The record replayed.
    path : str
        Its file, named in errors.
    channels : dict
        Option (a key of :data:`OPTION_KINDS`) → the channels it names.

    Raises
    ------
    TwinInputError
        A channel missing or of another kind (a thermometer as ``--spindle``: its kind and unit are known from
        the sidecar or the column's unit), naming the option, the channel and the file, and listing the channels
        of the kinds the option takes; a channel two options name, or one names twice.
    """
    for option, names in channels.items():
        *others, last = kinds = OPTION_KINDS[option]
        for name in names:
            if name not in dataset or dataset.info(name).kind not in kinds:
                raise TwinInputError(f"{option} {name!r}: {_what_channel(dataset, name)} in {path}; its "
                                     f"{', '.join(others)}{' or ' if others else ''}{last} channels: "
                                     f"{_channels_of(dataset, kinds)}")
    _check_own_channels(channels)


def _what_channel(dataset, name):
    """What ``name`` is in ``dataset``, for an error: "no such channel" or "a temperature channel (degC)"."""
    if name not in dataset:
        return "no such channel"
    channel = dataset.info(name)
    return f"a {channel.kind} channel ({channel.unit})"


def _check_own_channels(channels):
    """Refuse a channel two replay options name (or one names twice): the replay server has one node per channel,
    and one reading would be taken for two sensors (option → channels, as :func:`check_replay_channels`)."""
    owner = {}
    for option, names in channels.items():
        for name in names:
            if name in owner:
                whose = "named twice" if owner[name] == option else f"the channel of {owner[name]} too"
                raise TwinInputError(f"{option} {name!r}: {whose}; the spindle speed, the room air and every "
                                     "thermometer need a channel of their own")
            owner[name] = option


async def replay_session(dataset: Dataset, thermometers: list[str], observer: RecordRunner, speed: float,
                         room_air: str = "T15", spindle: str = "spindle", port: int | None = None,
                         log_path: str | None = None, host: str = "127.0.0.1",
                         source: str = "dataset", late_after_s: float = 1.0,
                         duration_s: float | None = None) -> tuple[LiveStats, float]:
    """Serve ``dataset`` on a local replay server and run the live client against it.

    Parameters
    ----------
    dataset : Dataset
        The record replayed (its channels ``spindle`` (rpm), ``room_air`` (°C) and the thermometers (°C)).
    thermometers : list of str
        The observer's thermometers, channels of ``dataset``.
    observer : DriftObserver or MultipleModelObserver
        The observer the client runs.
    speed : float
        Replay speed, machine s per wall s.
    room_air, spindle : str
        The dataset channels of the room air and the spindle speed.
    port : int, optional
        Server port (default: a free one).
    log_path : str, optional
        The client's CSV log.
    host : str
        Address of the server.
    source : str
        The dataset's file, named in errors.
    late_after_s : float
        Wall seconds the client waits for a sample's missing readings before fusing it.
    duration_s : float, optional
        Wall seconds after which the client stops (``--duration``), the replay's end not reached; default: the
        replay's end.

    Returns
    -------
    tuple
        The client's :class:`~twin.live.client.LiveStats` and the wall seconds the replay ran (until the client
        stopped, if it stopped first).
    """
    import asyncio

    import numpy as np

    from .client import LiveClient
    from .replay import ReplayServer, default_node_map

    check_replay_channels(dataset, source, {"--spindle": [spindle], "--room-air": [room_air],
                                            "thermometer": thermometers})
    names = [spindle, room_air, *thermometers]
    values = dataset.matrix(names)
    async with ReplayServer(names, host, port or free_port(host)) as server:
        node_map = default_node_map(thermometers, room_air, spindle, server.index)
        client = LiveClient(server.endpoint, node_map, observer, log_path, late_after_s)
        until = float(dataset.time_s[-1])
        # a replay that has not ended in 5× its time (+ 30 s to connect) never will: its client is stuck
        max_wall_s = min(30.0 + until / speed * 5, duration_s or np.inf)
        task = asyncio.create_task(client.run(until_time_s=until, max_wall_s=max_wall_s))
        try:
            return await _replay_to(client, task, server, dataset.time_s, values, speed)
        finally:
            if not task.done():       # Ctrl-C: the server must outlive its client's disconnect
                task.cancel()
                await asyncio.gather(task, return_exceptions=True)


async def _replay_to(client, task, server, times, values, speed):
    """Replay once ``client`` has subscribed; ``(its stats, the replay's wall s)``."""
    import asyncio
    import time

    while not client._subscribed and not task.done():
        await asyncio.sleep(0.01)
    if task.done():
        return task.result(), 0.0
    start = time.perf_counter()
    replay = asyncio.create_task(server.replay(times, values, speed))
    await asyncio.wait([replay, task], return_when=asyncio.FIRST_COMPLETED)
    if not replay.done():         # the client stopped first (--duration, interrupted, failed): nobody is listening
        replay.cancel()
        return await task, time.perf_counter() - start
    return await task, replay.result()


def _run_replay(args):
    """Serve ``--replay`` on a local server and observe it: ``(stats, thermometers, dataset)``."""
    import asyncio

    import numpy as np

    from ..core.dataset import Dataset

    if args.endpoint or args.node_map:
        raise TwinInputError("twin live: give either --replay DATASET or --endpoint with --node-map, not both")
    if args.speed <= 0 or not np.isfinite(args.speed):
        raise TwinInputError(f"--speed must be a positive number, got {args.speed}")
    dataset = Dataset.read(args.replay)
    # before the observer is built (seconds); the thermometers are checked once it has chosen them
    check_replay_channels(dataset, args.replay, {"--spindle": [args.spindle], "--room-air": [args.room_air]})
    observer, thermometers = _observer(args, DEFAULT_THERMOMETERS)
    with _kept(args, observer) as observer:
        stats, wall = asyncio.run(replay_session(dataset, thermometers, observer, args.speed, args.room_air,
                                                 args.spindle, args.port, args.log, source=args.replay,
                                                 late_after_s=args.late_after, duration_s=args.duration))
    print(_replayed(args, dataset, stats, wall))
    return stats, thermometers, dataset


def _replayed(args, dataset, stats, wall):
    """The summary's replay line: the samples replayed, and how far (machine s) a replay stopped early got."""
    from pathlib import Path

    import numpy as np

    name, end = Path(args.replay).name, float(dataset.time_s[-1])
    reached = stats.last.time_s if stats.last is not None else None
    if reached is not None and reached >= end:
        return f"replayed {len(dataset)} samples of {name} at {args.speed:g}× in {wall:.1f} s"
    why = f" (--duration {args.duration:g} s)" if args.duration else ""
    where = "" if reached is None else (f", at machine time {reached:g} s of {end:g} s "
                                        f"({np.sum(dataset.time_s <= reached)} of {len(dataset)} samples)")
    return f"replay of {name} at {args.speed:g}× stopped after {wall:.1f} s{why}{where}"


def _check_endpoint(url):
    """Refuse an ``--endpoint`` that is not an OPC UA TCP address (asyncua would only retry it, unreachable)."""
    from urllib.parse import urlsplit

    try:
        parts = urlsplit(url)
        well_formed = parts.scheme == "opc.tcp" and bool(parts.hostname) and parts.port != 0
    except ValueError:                          # a port that is no number, an unclosed [IPv6 address
        well_formed = False
    if not well_formed:
        raise TwinInputError(f"--endpoint {url!r}: not an OPC UA address; use opc.tcp://HOST:PORT/…")


def _run_endpoint(args):
    """Observe a running machine at ``--endpoint`` through ``--node-map``: ``(stats, thermometers, None)``."""
    import asyncio

    import numpy as np

    from .client import LiveClient
    from .nodemap import load_node_map

    if not (args.endpoint and args.node_map):
        raise TwinInputError("twin live: give --endpoint opc.tcp://… with --node-map FILE.toml (or --replay DATASET)")
    _check_endpoint(args.endpoint)
    node_map = load_node_map(args.node_map)
    try:
        observer, thermometers = _observer(args, node_map.thermometers)
    except TwinInputError as exc:
        raise TwinInputError(f"{args.node_map}: {exc}") from None
    with _kept(args, observer) as observer:
        client = LiveClient(args.endpoint, node_map, observer, args.log, late_after_s=args.late_after)
        return asyncio.run(client.run(max_wall_s=args.duration or np.inf)), thermometers, None


def _print_summary(stats, thermometers, dataset):
    """What was fused, the last estimate with its band, and (replay) the error against the dataset's Z."""
    import numpy as np

    from .observer import AXES

    rate = stats.samples / stats.wall_s if stats.wall_s else 0.0
    print(f"fused {stats.samples} samples in {stats.wall_s:.1f} s ({rate:.0f} samples/s) from "
          f"{', '.join(thermometers)} + spindle speed + room air; late {stats.late}, missing readings "
          f"{stats.missing}, reconnects {stats.reconnects}, failed connection attempts {stats.failed_attempts}")
    if stats.rejected:
        print(f"readings left out: {stats.rejected}")
    if stats.last is not None:
        e = stats.last
        print(f"at t = {e.time_s:g} s: " + ", ".join(f"{a} {e.drift_um[j]:.2f} ± {e.band_um[j]:.2f} µm"
                                                     for j, a in enumerate(AXES)) + " (95 %)")
        print(BANDS_NOTE)
    if dataset is not None and "Z" in dataset and stats.history:
        t = np.array([h[0] for h in stats.history])
        z = np.array([h[1][2] for h in stats.history])
        truth = np.interp(t, dataset.time_s, dataset["Z"])
        print(f"Z against the dataset's Z: RMS {np.sqrt(np.mean((z - truth) ** 2)):.2f} µm, "
              f"max {np.abs(z - truth).max():.2f} µm")


def _input_files(args):
    """The files ``twin live`` reads, which its ``--log`` must not replace: the replayed dataset and its sidecar,
    the node map, the placement's chosen set and the machine's TOML (names that are no file are skipped)."""
    from pathlib import Path

    from ..core.dataset import sidecar_path
    from .placement import CHOSEN_FILE

    files = [args.node_map, args.thermometers_from, args.machine]
    if args.replay:
        files += [args.replay, sidecar_path(args.replay)]
    if args.thermometers_from:
        files.append(Path(args.thermometers_from) / CHOSEN_FILE)
    return tuple(f for f in files if f is not None)


def _check_state_file(args):
    """Refuse a ``--state`` that is a folder, one of the command's input files, or its log (or the log's ``.part``):
    the state is read and written there."""
    from pathlib import Path

    from ..infra.outdir import check_output_file
    from .client import partial_path

    state = check_output_file(args.state, overwrite=True, inputs=_input_files(args))
    if args.log and state in {Path(p).expanduser().resolve() for p in (args.log, partial_path(args.log))}:
        raise TwinInputError(f"--state {args.state}: the file of --log too; the state needs a file of its own")


def _not_observed(stats, server):
    """Why the session did not observe the machine to its end (one line naming ``server``), or None."""
    if not stats.ended_connected:
        return (f"the session ended disconnected from {server} after {stats.failed_attempts} failed connection "
                f"attempts (last: {stats.last_error})")
    if not stats.samples:
        return f"no sample fused from {server}"
    return None


def _log_state(path):
    """What a partial log at ``path`` is now (None: not there), to tell whether this session wrote it."""
    from .client import partial_path

    try:
        return partial_path(path).stat().st_mtime_ns
    except (OSError, TypeError):               # no such file, or no --log
        return None


def _partial_log(path, before):
    """'; its partial log is kept as FILE.part' when this session left one (its state changed from ``before``)."""
    from .client import partial_path

    state = _log_state(path)
    return f"; its partial log is kept as {partial_path(path)}" if state is not None and state != before else ""


def _observe(args):
    """Run the session; Ctrl-C, a failing observer and errors say what became of the log."""
    from .client import ObserverFailure, SessionInterrupted

    before = _log_state(args.log)
    try:
        return _run_replay(args) if args.replay else _run_endpoint(args)
    except (KeyboardInterrupt, SessionInterrupted):
        print(f"twin live: interrupted{_partial_log(args.log, before) or '; no log was written'}", file=sys.stderr)
        raise _Ended(EXIT_INTERRUPTED) from None
    except ObserverFailure as exc:
        print(f"twin live: {exc}{_partial_log(args.log, before)}", file=sys.stderr)
        raise _Ended(EXIT_NOT_OBSERVED) from None
    except TwinInputError as exc:
        raise TwinInputError(f"{exc}{_partial_log(args.log, before)}") from None


def _check_options(args):
    """Refuse, before anything is built or served, option values no session could honour."""
    if not 0.0 <= args.late_after < float("inf"):
        raise TwinInputError(f"--late-after must be a finite number of seconds ≥ 0, got {args.late_after:g}")
    if args.duration is not None and not 0.0 < args.duration < float("inf"):
        # 0 and NaN would run for ever (``or inf``), a negative one end at once as if the server were gone
        raise TwinInputError(f"--duration must be a finite number of seconds > 0, got {args.duration:g}")
    if args.thermometers is not None:
        # one thermometer twice would be one reading fused as two (and a replay server's node made twice)
        check_distinct("--thermometers", split_names(args.thermometers), "thermometer")


class _Ended(Exception):
    """The session ended early, already explained on stderr, with the exit code ``code``."""

    def __init__(self, code):
        super().__init__(code)
        self.code = code


def cmd_live(args: argparse.Namespace) -> int:
    """``twin live``: replay (``--replay``) or observe a machine (``--endpoint``); print the summary.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``twin live`` options.

    Returns
    -------
    int
        0; :data:`EXIT_NOT_OBSERVED` when no sample was fused, the session ended without a connection or the
        observer's estimate was not finite; :data:`EXIT_INTERRUPTED` after Ctrl-C (each with the reason on
        stderr, naming the partial log the session left, if any).
    """
    _check_options(args)
    from pathlib import Path

    if args.state:
        _check_state_file(args)
    if args.log:
        from ..infra.outdir import check_output_file
        from .client import partial_path

        logs = (args.log, partial_path(args.log))        # a partial log is a session's record too
        for path in logs:
            check_output_file(path, args.overwrite, inputs=_input_files(args))
        for path in logs:
            # --overwrite replaces both now: an older session's complete log left beside this one's partial log
            # would be taken for this session's result
            Path(path).unlink(missing_ok=True)
    try:
        stats, thermometers, dataset = _observe(args)
    except _Ended as ended:
        return ended.code
    _print_summary(stats, thermometers, dataset)
    if stats.log is not None and stats.log == Path(args.log):
        print(f"log written to {stats.log}")
    reason = _not_observed(stats, f"--endpoint {args.endpoint}" if args.endpoint else "the replay server")
    if reason:
        kept = f"; its partial log is kept as {stats.log}" if stats.log is not None else ""
        print(f"twin live: {reason}{kept}", file=sys.stderr)
        return EXIT_NOT_OBSERVED
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``live`` command to the ``twin`` subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The ``twin`` subparsers.
    """
    p = sub.add_parser("live", help="run the drift observer on a machine's OPC UA sensors (or a replayed dataset)",
                       epilog=f"Exit code: 0 done, {EXIT_NOT_OBSERVED} no sample fused, the session ended "
                                  "without a connection to the server or the estimate was not finite, 2 bad "
                                  f"input, {EXIT_INTERRUPTED} interrupted (Ctrl-C).")
    p.add_argument("--endpoint", help="OPC UA server, opc.tcp://HOST:PORT/…")
    p.add_argument("--node-map", help="TOML file: [inputs] spindle_speed, room_air; [thermometers]; [outputs]")
    p.add_argument("--replay", metavar="DATASET", help="serve this dataset (CSV) on a local OPC UA server and run "
                                                         "against it")
    p.add_argument("--speed", type=float, default=DEFAULT_SPEED,
                   help=f"replay speed, machine seconds per wall second (default {DEFAULT_SPEED:g})")
    p.add_argument("--port", type=int, help="replay server port (default: a free one on 127.0.0.1)")
    p.add_argument("--thermometers", help="comma-separated ROM thermometers the observer fuses (default: the "
                                          "placement's chosen set with --thermometers-from, else the node map's; "
                                          f"replay: {','.join(DEFAULT_THERMOMETERS)})")
    p.add_argument("--thermometers-from", metavar="PLACEMENT",
                   help="thermometers at the locations a placement study chose: a `twin place` result folder or its "
                        "chosen_sensors.csv (the ROM gets a point-temperature output at each)")
    p.add_argument("--placement-axis", default="Z", help="with --thermometers-from: the drift axis whose chosen set "
                                                         "is read (default Z)")
    p.add_argument("--room-air", default="T15", help="replay: the dataset channel of the room air (default T15)")
    p.add_argument("--spindle", default="spindle", help="replay: the dataset channel of the spindle speed, rpm")
    p.add_argument("--machine", default="vmc_ram", help="machine name or TOML path (default vmc_ram)")
    p.add_argument("--order", type=int, default=DEFAULT_ORDER, help=f"ROM order (default {DEFAULT_ORDER})")
    p.add_argument("--log", help="CSV log of the estimates (µm), written as FILE.part and renamed to FILE when the "
                                 "session ends as asked (an interrupted or failed one leaves FILE.part)")
    p.add_argument("--duration", type=float, help="stop after this many wall seconds from the client's start, a replay "
                                                  "before its end if need be (default: run until stopped, a replay "
                                                  "until its end)")
    p.add_argument("--late-after", type=float, default=1.0,
                   help="wall seconds to wait for a sample's missing readings before fusing it (default 1)")
    p.add_argument("--at-rest", action="store_true",
                   help="the machine stood idle in the room air for hours before the session: start from its "
                        "equilibrium with the room (default: its past is unknown, and the first bands say so)")
    p.add_argument("--state", metavar="FILE",
                   help="keep the observer's state in FILE (JSON, written atomically every 30 wall s and when the "
                        "session stops): a session started with FILE there goes on from it, across the time away "
                        "with the inputs unknown (up to 8 h; docs/live.md, \"Resuming from a saved state\")")
    add_overwrite(p, "file")
    p.set_defaults(func=cmd_live)
