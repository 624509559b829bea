"""The OPC UA side of ``twin live``: subscribe to a machine's sensors, run the observer, publish the drift.

:class:`LiveClient` connects with asyncua, checks every node of the node map (a missing one is a
:class:`~twin.errors.TwinInputError` naming the map file, key and node; so is an output node that is not a
writable Double or Float), subscribes to the sensor nodes (trigger on value *or* source timestamp, so a
repeated reading still counts; a queue per item, so no sample is lost between publishing cycles) and groups
the values of one sample by their timestamp (:mod:`twin.live.samples`: late values, a clock that jumps back).
A sample is fused when every node has reported it, or after ``late_after_s`` wall seconds with the missing
readings as NaN (the observer skips them).  Readings whose status is not Good, that lie outside the plausible
range, or that the observer's innovation gate rejects are left out and counted per node
(:mod:`twin.live.readings`).  After each sample it writes a row to the CSV log, and the newest estimate, its
95 % half-band and the compensation value (−estimate) to the output nodes (once per batch of samples that
arrived together: the nodes show the present value, the log keeps every sample).  An estimate that is not
finite stops the session (:class:`ObserverFailure`): it is never written as an estimate.  A dropped connection
(server restart, network) is retried with exponential backoff (``backoff_s`` … ``max_backoff_s``); the observer
keeps its state, and the gap is bridged by its prediction at the next sample.

The log is written to ``<log>.part`` and renamed to ``<log>`` only when the session ends as asked (the machine
time or the wall time reached, connected); a session that ends otherwise — interrupted, failed, or
disconnected — leaves ``<log>.part``, so that a partial log never looks complete.
"""
from __future__ import annotations

import asyncio
import datetime as _dt
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fea.linsolve import blas_threads

from ..core.interrupt import raise_if_interrupted
from ..errors import TwinInputError
from .nodemap import AXES, NodeMap
from .observer import INNOVATION_GATE
from .readings import ReadingChecks
from .samples import SampleAssembler

if TYPE_CHECKING:
    from asyncua import Node, ua
    from asyncua.common.subscription import DataChangeNotif

    from .observer import Estimate, RecordRunner

log = logging.getLogger("thermal_twin")


@dataclass
class LiveStats:
    """What a live session did.

    Attributes
    ----------
    samples : int
        Samples fused.
    late : int
        Values that arrived after their sample was fused (dropped).
    missing : int
        Thermometer readings missing (NaN or not received) in fused samples.
    reconnects : int
        Connections re-established after a loss.
    failed_attempts : int
        Connection attempts that failed before subscribing (refused, timed out, lost): the first connection's
        and every reconnection's.
    ended_connected : bool
        Whether the client was still subscribed when the session ended (False: it ended while reconnecting,
        or never connected).
    last_error : str
        The last connection error ("" if none).
    wall_s : float
        Wall time of the session, s.
    last : Estimate or None
        The last estimate (:class:`~twin.live.observer.Estimate`).
    history : list
        (machine time s, drift (3,) µm, 95 % half-band (3,) µm) per fused sample.
    rejected : str
        Readings left out per node and reason (:meth:`~twin.live.readings.ReadingChecks.summary`; "" if none).
    log : Path or None
        The log as the session left it: the log file, its ``.part`` when the session did not end as asked,
        or None (no log, or nothing fused).
    """

    samples: int = 0
    late: int = 0
    missing: int = 0
    reconnects: int = 0
    failed_attempts: int = 0
    ended_connected: bool = False
    last_error: str = ""
    wall_s: float = 0.0
    last: Estimate | None = None
    history: list = field(default_factory=list)
    rejected: str = ""
    log: Path | None = None


class ObserverFailure(RuntimeError):
    """The observer's estimate is not finite: the session stops rather than publish it."""


class SessionInterrupted(Exception):
    """Ctrl-C during the session.  Raised in place of the KeyboardInterrupt, which asyncio would store in the
    session's task and report on exit as an exception nobody retrieved (a traceback on stderr)."""


def partial_path(path: str | Path) -> Path:
    """Where the log of a session is written until it ends as asked: ``<path>.part``.

    Parameters
    ----------
    path : str or Path
        The log file.

    Returns
    -------
    Path
        ``<path>.part``.
    """
    path = Path(path)
    return path.with_name(path.name + ".part")


def _is_nan(value):
    """Whether a value received is NaN (a string or structure is not: the checks reject it)."""
    return isinstance(value, float) and np.isnan(value)


class CsvLog:
    """The estimates as CSV (µm, units in the headers), written to ``<path>.part`` (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The log file.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.part = partial_path(self.path)
        # a log in a folder not made yet, as every twin output (``twin live`` checked that it can be made)
        self.part.parent.mkdir(parents=True, exist_ok=True)
        self.file = open(self.part, "w", encoding="utf-8")
        self.rows = 0
        cols = ["time_s"] + [f"{a}_{k}_um" for a in AXES for k in ("estimate", "band95", "compensation")]
        self.file.write(",".join(cols + ["thermometers_used"]) + "\n")

    def write(self, e: Estimate) -> None:
        """Append one estimate: time (s), per axis the estimate, band and compensation (µm), readings used.

        Parameters
        ----------
        e : Estimate
            One observer estimate.
        """
        row = [f"{e.time_s:.15g}"] + [f"{v:.6g}" for a in range(3)
                                      for v in (e.drift_um[a], e.band_um[a], -e.drift_um[a])]
        self.file.write(",".join(row + [str(e.used)]) + "\n")
        self.rows += 1

    def close(self, complete: bool) -> Path | None:
        """Rename the log into place (``complete``), or leave it as ``.part``; remove it if it has no row.

        Parameters
        ----------
        complete : bool
            Whether the session ended as asked.

        Returns
        -------
        Path or None
            The file kept, or None when nothing was fused.
        """
        self.file.flush()
        os.fsync(self.file.fileno())
        self.file.close()
        if not self.rows:
            self.part.unlink()
            return None
        if complete:
            os.replace(self.part, self.path)
            return self.path
        return self.part


class LiveClient:
    """Run an observer on the sensors of a node map at an OPC UA endpoint (see the module docstring).

    Parameters
    ----------
    endpoint : str
        ``opc.tcp://host:port/…``.
    node_map : NodeMap
        The sensor, thermometer and output nodes.
    observer : DriftObserver or MultipleModelObserver
        The observer; its thermometers must all be in ``node_map``.
    log_path : str or Path, optional
        CSV log of every fused sample.
    late_after_s : float
        Wall seconds to wait for a sample's missing readings before fusing it.
    backoff_s, max_backoff_s : float
        First and longest wait before a reconnection, s (doubling in between).
    timeout_s : float
        Request timeout of the OPC UA client, s.
    publish_ms : int
        Publishing interval of the subscription, ms.

    Raises
    ------
    TwinInputError
        If the node map lacks a node for one of the observer's thermometers, or two keys share a node.
    """

    def __init__(self, endpoint: str, node_map: NodeMap, observer: RecordRunner, log_path: str | Path | None = None,
                 late_after_s: float = 1.0, backoff_s: float = 0.2, max_backoff_s: float = 5.0, timeout_s: float = 10.0,
                 publish_ms: int = 20) -> None:
        self.endpoint, self.map, self.observer = endpoint, node_map, observer
        missing = [t for t in observer.thermometers if t not in node_map.thermometers]
        if missing:
            raise TwinInputError(f"{node_map.source}: [thermometers] has no node for {missing[0]}")
        node_map.check_distinct()
        self.keys = [k for k, _ in node_map.sensors()]
        self.log_path, self.late_after_s = log_path, late_after_s
        self.backoff_s, self.max_backoff_s, self.timeout_s, self.publish_ms = \
            backoff_s, max_backoff_s, timeout_s, publish_ms
        self.stats = LiveStats()
        self.checks = ReadingChecks(node_map, list(observer.thermometers))
        self.samples = SampleAssembler(self.keys, late_after_s, endpoint, self.checks)
        self._variants = {}         # output key → the OPC UA variant type its node takes
        self._queue, self._subscribed, self.csv = None, False, None

    # ------------------------------------------------------------------ subscription callbacks
    def datachange_notification(self, node: Node, value: float | None, data: DataChangeNotif) -> None:
        """asyncua's callback for a monitored value: queue (key, data value, value).

        Parameters
        ----------
        node : asyncua.Node
            The monitored node.
        value : float or None
            Its new value in the channel's unit (rpm, °C); None if the server sent none.
        data : DataChangeNotif
            asyncua's notification (its data value has the timestamps and the status).
        """
        self._queue.put_nowait((self._key_of[node.nodeid], data.monitored_item.Value, value))

    def status_change_notification(self, status: ua.StatusChangeNotification) -> None:
        """asyncua's callback for a subscription status change (the session is gone): reconnect.

        Parameters
        ----------
        status : ua.StatusChangeNotification
            The new status (not read: any change means the session is gone).
        """
        self._lost.set()

    # ------------------------------------------------------------------ fusing
    def _fuse(self, t):
        values, checks, thermometers = self.samples.pop(t), self.checks, self.observer.thermometers

        def reading(key):
            value, status = values.get(key, (None, None))
            good = status is None or status.is_good()      # a Bad one is counted as rejected, not missing
            self.stats.missing += key in thermometers and good and (value is None or _is_nan(value))
            return checks.reading(key, value, status, t)

        y = np.array([reading(name) for name in thermometers])
        # the observer's matrices are a reduced model's size (tens to a few hundred): BLAS threads only cost there
        with blas_threads(1):
            e = self.observer.step(t, reading("spindle_speed"), reading("room_air"), y)
        checks.check_stale(t)
        if e is None:
            return None
        if not (np.all(np.isfinite(e.drift_um)) and np.all(np.isfinite(e.band_um))):
            raise ObserverFailure(f"the observer's estimate at t = {t:.15g} s is not finite (" + ", ".join(
                f"{a} {e.drift_um[j]:.2f} ± {e.band_um[j]:.2f} µm" for j, a in enumerate(AXES)) + "); it was not "
                "written to the log or the output nodes")
        for j in np.flatnonzero(e.rejected if e.rejected is not None else []):
            checks.reject(thermometers[j], "gate", t, f"{y[j]:g} °C, more than {INNOVATION_GATE:g} σ from what "
                                                      "the model predicts")
        self.stats.samples += 1
        self.stats.last = e
        self.stats.history.append((e.time_s, e.drift_um.copy(), e.band_um.copy()))
        return e

    # ------------------------------------------------------------------ connection
    async def _check_nodes(self, client):
        from asyncua import ua

        nodes = {}
        for key, text in [*self.map.sensors(), *self.map.outputs.items()]:
            node = client.get_node(text)
            try:
                data_type = await node.read_data_type()
            except ua.UaStatusCodeError as exc:
                raise TwinInputError(f"{self.map.where(key)}: no such node on {self.endpoint} "
                                     f"({type(exc).__name__})") from None
            nodes[key] = node
            if key in self.map.outputs:
                self._variants[key] = await self._output_variant(key, node, data_type)
        return nodes

    async def _output_variant(self, key, node, data_type):
        """The variant type of an output node (Double, or Float: the estimate is converted); an error naming it
        if it is neither, or not writable (else every write fails and the client would reconnect for ever)."""
        from asyncua import ua

        types = {ua.ObjectIds.Double: ua.VariantType.Double, ua.ObjectIds.Float: ua.VariantType.Float}
        variant = types.get(data_type.Identifier) if data_type.NamespaceIndex == 0 else None
        if variant is None:
            name = ua.ObjectIdNames.get(data_type.Identifier, data_type.to_string()) \
                if data_type.NamespaceIndex == 0 else data_type.to_string()
            raise TwinInputError(f"{self.map.where(key)}: data type {name} on {self.endpoint}; an output node "
                                 "must be a Double or a Float (µm)")
        try:
            access = await node.get_user_access_level()
        except ua.UaStatusCodeError:          # a server that does not expose the user's level: the node's
            access = await node.get_access_level()
        if ua.AccessLevel.CurrentWrite not in access:
            raise TwinInputError(f"{self.map.where(key)}: not writable on {self.endpoint} (its access level "
                                 "lacks CurrentWrite)")
        return variant

    async def _write_outputs(self, client, nodes, keys, e):
        """Write the estimate ``e`` to the output nodes; a node that refuses it is an error naming it."""
        from asyncua import ua

        stamp = _dt.datetime.now(_dt.timezone.utc)
        values = [ua.DataValue(ua.Variant(self._output(e, k), self._variants[k]), SourceTimestamp=stamp)
                  for k in keys]
        results = await client.write_values(nodes, values, raise_on_partial_error=False)
        for key, result in zip(keys, results):
            if not result.is_good():
                raise TwinInputError(f"{self.map.where(key)}: {self.endpoint} refused the estimate "
                                     f"({result.name})")

    async def _subscribe(self, client, nodes):
        """Monitor every input node (status, value and timestamp changes; no sampling delay, deep queues)."""
        from asyncua import ua

        sub = await client.create_subscription(self.publish_ms, self)
        trigger = ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.StatusValueTimestamp)
        requests = []
        for handle, key in enumerate(self.keys, start=1):
            params = ua.MonitoringParameters(ClientHandle=handle, SamplingInterval=0.0, QueueSize=10000,
                                             DiscardOldest=True, Filter=trigger)
            requests.append(ua.MonitoredItemCreateRequest(
                ItemToMonitor=ua.ReadValueId(NodeId=nodes[key].nodeid, AttributeId=ua.AttributeIds.Value),
                MonitoringMode=ua.MonitoringMode.Reporting, RequestedParameters=params))
        await sub.create_monitored_items(requests)
        self._subscribed = True
        log.info("live: subscribed to %d nodes on %s", len(self.keys), self.endpoint)

    async def _take_queued(self):
        """Move what the subscription queued into the sample buffers (waits up to 50 ms for the first item)."""
        try:
            first = await asyncio.wait_for(self._queue.get(), timeout=0.05)
        except asyncio.TimeoutError:
            return
        received, now = _dt.datetime.now(_dt.timezone.utc), time.monotonic()    # one time per batch
        batch = [first] + [self._queue.get_nowait() for _ in range(self._queue.qsize())]
        for key, data_value, value in batch:
            self.samples.add(key, self.samples.machine_time(data_value, received), value, data_value.StatusCode, now)

    async def _fuse_ready(self):
        """Fuse every complete sample (logging each); the newest estimate, or None."""
        last = None
        for t in self.samples.ready(time.monotonic()):
            e = self._fuse(t)
            if e is not None:
                last = e
                if self.csv is not None:
                    self.csv.write(e)
            await asyncio.sleep(0)       # a backlog must not starve the connection's keep-alive
        return last

    async def _session(self, stop):
        """One connection: subscribe, then fuse samples until ``stop()`` or the connection is lost."""
        from asyncua import Client, ua

        client = Client(self.endpoint, timeout=self.timeout_s, watchdog_intervall=max(0.2, self.timeout_s / 4))
        self._lost, self._subscribed = asyncio.Event(), False

        async def lost(exc):
            self._lost.set()

        client.connection_lost_callback = lost
        await client.connect()
        try:
            nodes = await self._check_nodes(client)
            self._key_of = {nodes[k].nodeid: k for k in self.keys}
            out_keys = list(self.map.outputs)
            out_nodes = [nodes[k] for k in out_keys]
            await self._subscribe(client, nodes)
            while not stop() and not self._lost.is_set():
                await self._take_queued()
                last = await self._fuse_ready()
                if last is not None and out_nodes:      # nodes show the newest estimate (one write per batch)
                    await self._write_outputs(client, out_nodes, out_keys, last)
            if self._lost.is_set():
                raise ConnectionError(f"connection to {self.endpoint} lost")
        finally:
            try:
                await asyncio.wait_for(client.disconnect(), timeout=1.0)
            except (ConnectionError, OSError, asyncio.TimeoutError, ua.UaError):   # the server is gone already
                client.disconnect_socket()

    @staticmethod
    def _output(e, key):
        axis = AXES.index(key[0])
        if key.endswith("_band"):
            return float(e.band_um[axis])
        return float(-e.drift_um[axis] if key.endswith("_compensation") else e.drift_um[axis])

    def _connection_failed(self, exc, delay):
        """Count and log a lost connection or a failed attempt (``delay``: s until the next one)."""
        self.stats.ended_connected = False
        self.stats.last_error = str(exc) or type(exc).__name__
        self.stats.failed_attempts += not self._subscribed      # a session that was up was lost, not failed
        log.info("live: %s: %s; reconnecting in %.1f s", self.endpoint, self.stats.last_error, delay)

    async def run(self, until_time_s: float = np.inf, max_wall_s: float = np.inf) -> LiveStats:
        """Run until a sample at machine time ≥ ``until_time_s`` (s) is fused or ``max_wall_s`` wall s have passed.

        Connection losses are retried with backoff; a wrong node map raises at once.

        Parameters
        ----------
        until_time_s : float, default inf
            Machine time that ends the run, s.
        max_wall_s : float, default inf
            Wall-clock limit, s.

        Returns
        -------
        LiveStats
            What the session did.

        Raises
        ------
        TwinInputError
            A node map the server does not match (a node missing, an output node not a writable Double or Float).
        ObserverFailure
            An estimate that is not finite.
        SessionInterrupted
            Ctrl-C.  After any of these the log is left as ``<log>.part``.
        """
        from asyncua import ua

        self._queue = asyncio.Queue()
        self.csv = CsvLog(self.log_path) if self.log_path else None
        start = time.monotonic()

        def left():
            return max_wall_s - (time.monotonic() - start)

        def stop():
            raise_if_interrupted()       # a Ctrl-C whose KeyboardInterrupt asyncua or asyncio swallowed
            return self.samples.done_until >= until_time_s or left() <= 0

        delay, sessions, ended = self.backoff_s, 0, False
        try:
            while not stop():
                try:
                    await self._session(stop)
                    self.stats.ended_connected = True        # it returns only when stop() ends a live session
                except (ConnectionError, OSError, asyncio.TimeoutError, ua.UaError) as exc:
                    if self._subscribed:
                        delay = self.backoff_s       # it was up: start the backoff again
                    self._connection_failed(exc, delay)
                    await asyncio.sleep(max(0.0, min(delay, left())))     # the backoff must not outlast the run
                    delay = min(2 * delay, self.max_backoff_s)
                sessions += self._subscribed
                self.stats.reconnects = max(0, sessions - 1)
            ended = True
        except KeyboardInterrupt:
            raise SessionInterrupted(f"interrupted after {self.stats.samples} samples") from None
        finally:
            self._close(ended)
            self.stats.wall_s = time.monotonic() - start
        return self.stats

    def _close(self, ended):
        """Final counts; the log renamed into place only if the session ended as asked and connected."""
        self.stats.late, self.stats.rejected = self.samples.late, self.checks.summary()
        if self.csv is not None:
            self.stats.log = self.csv.close(complete=ended and self.stats.ended_connected)
