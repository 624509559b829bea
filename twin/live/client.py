"""The OPC UA side of ``twin live``: subscribe to a machine's sensors, run the observer, publish the drift.

:class:`LiveClient` connects with asyncua, checks every node of the node map (a missing one is a
:class:`~twin.errors.TwinInputError` naming the map file, key and node), subscribes to the sensor nodes
(trigger on value *or* source timestamp, so a repeated reading still counts; a queue per item, so no
sample is lost between publishing cycles) and groups the values of one sample by their source
timestamp.  A sample is fused when every node has reported it, or after ``late_after_s`` wall seconds
with the missing readings as NaN (the observer skips them); a value that arrives for a sample already
fused is *late*: counted and dropped (the filter does not go back in time).  After each sample it writes a
row to the CSV log, and the newest estimate, its 95 % half-band and the compensation value
(−estimate) to the output nodes (once per batch of samples that arrived together: the nodes show
the present value, the log keeps every sample).  A dropped connection (server restart, network) is retried with exponential
backoff (``backoff_s`` … ``max_backoff_s``); the observer keeps its state, and the gap is bridged by
its prediction at the next sample.
"""
from __future__ import annotations

import asyncio
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import TwinInputError
from .nodemap import AXES, NodeMap
from .replay import machine_time

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


class CsvLog:
    """The estimates as CSV (µm, units in the headers), written to ``<path>.part`` and renamed at close.

    Parameters
    ----------
    path : str or Path
        The log file.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.part = self.path.with_name(self.path.name + ".part")
        self.file = open(self.part, "w", encoding="utf-8")
        cols = ["time_s"] + [f"{a}_{k}_um" for a in AXES for k in ("estimate", "band95", "compensation")]
        self.file.write(",".join(cols + ["thermometers_used"]) + "\n")

    def write(self, e: Estimate) -> None:
        """Append one estimate: time (s), per axis the estimate, band and compensation (µm), readings used.

        Parameters
        ----------
        e : Estimate
            One observer estimate.
        """
        row = [f"{e.time_s:.10g}"] + [f"{v:.6g}" for a in range(3)
                                      for v in (e.drift_um[a], e.band_um[a], -e.drift_um[a])]
        self.file.write(",".join(row + [str(e.used)]) + "\n")

    def close(self, keep: bool = True) -> None:
        """Rename the log into place, or remove it (``keep=False``: nothing was fused).

        Parameters
        ----------
        keep : bool, default True
            Keep the log (rename it into place); False removes it.
        """
        self.file.flush()
        os.fsync(self.file.fileno())
        self.file.close()
        if keep:
            os.replace(self.part, self.path)
        else:
            self.part.unlink()


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
        If the node map lacks a node for one of the observer's thermometers.
    """

    def __init__(self, endpoint: str, node_map: NodeMap, observer: RecordRunner, log_path: str | Path | None = None,
                 late_after_s: float = 1.0, backoff_s: float = 0.2, max_backoff_s: float = 5.0, timeout_s: float = 10.0,
                 publish_ms: int = 20) -> None:
        self.endpoint, self.map, self.observer = endpoint, node_map, observer
        missing = [t for t in observer.thermometers if t not in node_map.thermometers]
        if missing:
            raise TwinInputError(f"{node_map.source}: [thermometers] has no node for {missing[0]}")
        self.keys = [k for k, _ in node_map.sensors()]
        self.log_path, self.late_after_s = log_path, late_after_s
        self.backoff_s, self.max_backoff_s, self.timeout_s, self.publish_ms = \
            backoff_s, max_backoff_s, timeout_s, publish_ms
        self.stats = LiveStats()
        self._pending = {}          # machine time → (first seen wall time, {key: value})
        self._done_until = -np.inf  # machine time of the last fused sample
        self._queue, self._subscribed, self.csv = None, False, None

    # ------------------------------------------------------------------ subscription callbacks
    def datachange_notification(self, node: Node, value: float | None, data: DataChangeNotif) -> None:
        """asyncua's callback for a monitored value: queue (key, machine time s, value).

        Parameters
        ----------
        node : asyncua.Node
            The monitored node.
        value : float or None
            Its new value in the channel's unit (rpm, °C); None if the server sent none.
        data : DataChangeNotif
            asyncua's notification (its source timestamp is the machine time).
        """
        stamp = data.monitored_item.Value.SourceTimestamp
        self._queue.put_nowait((self._key_of[node.nodeid], machine_time(stamp), value))

    def status_change_notification(self, status: ua.StatusChangeNotification) -> None:
        """asyncua's callback for a subscription status change (the session is gone): reconnect.

        Parameters
        ----------
        status : ua.StatusChangeNotification
            The new status (not read: any change means the session is gone).
        """
        self._lost.set()

    # ------------------------------------------------------------------ sample assembly
    def _add(self, key, t, value):
        t = round(t, 6)
        if t <= self._done_until:
            self.stats.late += 1
            return
        entry = self._pending.setdefault(t, (time.monotonic(), {}))
        entry[1][key] = np.nan if value is None else float(value)

    def _ready(self, now):
        """Machine times that can be fused now, in order."""
        complete = [t for t, (_, v) in self._pending.items() if len(v) == len(self.keys)]
        last = max(complete, default=-np.inf)
        return sorted(t for t, (seen, _) in self._pending.items()
                      if t <= last or now - seen >= self.late_after_s)

    def _fuse(self, t):
        _, values = self._pending.pop(t)
        self._done_until = t
        v = lambda key: values.get(key, np.nan)      # noqa: E731
        y = np.array([v(name) for name in self.observer.thermometers])
        self.stats.missing += int((~np.isfinite(y)).sum())
        e = self.observer.step(t, v("spindle_speed"), v("room_air"), y)
        if e is not None:
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
                await node.read_data_type()
            except ua.UaStatusCodeError as exc:
                raise TwinInputError(f"{self.map.where(key)}: no such node on {self.endpoint} "
                                     f"({type(exc).__name__})") from None
            nodes[key] = node
        return nodes

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
            key, t, value = await asyncio.wait_for(self._queue.get(), timeout=0.05)
        except asyncio.TimeoutError:
            return
        self._add(key, t, value)
        while not self._queue.empty():
            self._add(*self._queue.get_nowait())

    async def _fuse_ready(self):
        """Fuse every complete sample (logging each); the newest estimate, or None."""
        last = None
        for t in self._ready(time.monotonic()):
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
                    await client.write_values(out_nodes, [self._output(last, k) for k in out_keys])
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
        """
        from asyncua import ua

        self._queue = asyncio.Queue()
        self.csv = CsvLog(self.log_path) if self.log_path else None
        start = time.monotonic()

        def stop():
            return self._done_until >= until_time_s or time.monotonic() - start >= max_wall_s

        delay, sessions = self.backoff_s, 0
        try:
            while not stop():
                try:
                    await self._session(stop)
                    self.stats.ended_connected = True        # it returns only when stop() ends a live session
                except (ConnectionError, OSError, asyncio.TimeoutError, ua.UaError) as exc:
                    if self._subscribed:
                        delay = self.backoff_s       # it was up: start the backoff again
                    self._connection_failed(exc, delay)
                    await asyncio.sleep(delay)
                    delay = min(2 * delay, self.max_backoff_s)
                sessions += self._subscribed
                self.stats.reconnects = max(0, sessions - 1)
        finally:
            if self.csv is not None:
                self.csv.close(keep=self.stats.samples > 0)
            self.stats.wall_s = time.monotonic() - start
        return self.stats
