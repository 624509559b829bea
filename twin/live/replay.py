"""A local OPC UA server (asyncua) that replays a dataset in accelerated time: a machine for demos and tests.

Every dataset channel becomes a Double variable ``ns=<idx>;s=<channel>`` under ``Objects/Machine``, and
the estimates ``twin live`` writes back get writable variables ``<axis>_estimate_um``,
``<axis>_band95_um`` and ``<axis>_compensation_um``.  Sample i is published at wall time
``(tᵢ − t₀)/speed`` after the start, each value with the source timestamp :data:`EPOCH` + tᵢ, so a
client groups the values of one sample by their timestamp.  NaN values are published as they are
(a missing reading).
"""
from __future__ import annotations

import asyncio
import datetime as _dt
import time

import numpy as np
from numpy.typing import ArrayLike

from .nodemap import NodeMap

NAMESPACE = "urn:thermal-twin:live"
#: Source timestamp of machine time 0 (a fixed date, so replays are reproducible).
EPOCH = _dt.datetime(2026, 1, 1, tzinfo=_dt.timezone.utc)
OUTPUT_NODES = {f"{a}{key}": f"{a}_{name}" for a in "XYZ"
                for key, name in (("", "estimate_um"), ("_band", "band95_um"), ("_compensation", "compensation_um"))}


def timestamp(time_s: float) -> _dt.datetime:
    """The source timestamp of a machine time.

    Parameters
    ----------
    time_s : float
        Machine time, s after :data:`EPOCH`.

    Returns
    -------
    datetime.datetime
        UTC timestamp.
    """
    return EPOCH + _dt.timedelta(seconds=float(time_s))


def machine_time(stamp: _dt.datetime) -> float:
    """The machine time of a source timestamp.

    Parameters
    ----------
    stamp : datetime.datetime
        Source timestamp (a naive one is taken as UTC).

    Returns
    -------
    float
        Machine time, s after :data:`EPOCH`.
    """
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=_dt.timezone.utc)
    return (stamp - EPOCH).total_seconds()


def default_node_map(thermometers: list[str], room_air: str = "T15", spindle: str = "spindle",
                     index: int = 2) -> NodeMap:
    """The node map of a replay server publishing these channels.

    Parameters
    ----------
    thermometers : list of str
        The thermometer channels (°C); each is its own node ``ns=<index>;s=<name>``.
    room_air, spindle : str
        The channels of the room air (°C) and spindle speed (rpm).
    index : int
        The server's namespace index (:attr:`ReplayServer.index`).

    Returns
    -------
    NodeMap
        Inputs, thermometers and the writable output nodes (µm) of :data:`OUTPUT_NODES`.
    """
    node = lambda name: f"ns={index};s={name}"      # noqa: E731
    return NodeMap({"spindle_speed": node(spindle), "room_air": node(room_air)},
                   {t: node(t) for t in thermometers},
                   {k: node(v) for k, v in OUTPUT_NODES.items()}, "<replay node map>")


class ReplayServer:
    """An asyncua server on ``host:port`` publishing ``channels``; use as ``async with``.

    Parameters
    ----------
    channels : list of str
        The replayed channel names: one Double variable ``ns=<index>;s=<name>`` each, in the channel's unit.
    host : str
        Address to listen on.
    port : int
        TCP port.
    """

    def __init__(self, channels: list[str], host: str = "127.0.0.1", port: int = 4840) -> None:
        self.names = list(channels)
        self.endpoint = f"opc.tcp://{host}:{port}/thermal-twin/"
        self.server = self.index = None
        self.nodes = {}
        self.published = 0

    async def __aenter__(self) -> ReplayServer:
        """Build the address space (every channel empty: NaN before machine time 0) and start serving."""
        from asyncua import Server, ua

        server = Server()
        await server.init()
        server.set_endpoint(self.endpoint)
        server.set_server_name("thermal-twin replay")
        self.index = await server.register_namespace(NAMESPACE)
        machine = await server.nodes.objects.add_object(self.index, "Machine")
        # no reading yet: NaN, stamped before machine time 0 (a client fuses it as an empty sample)
        empty = ua.DataValue(ua.Variant(float("nan"), ua.VariantType.Double), SourceTimestamp=timestamp(-1.0))
        for name in [*self.names, *OUTPUT_NODES.values()]:
            var = await machine.add_variable(ua.NodeId(name, self.index), name, float("nan"), ua.VariantType.Double)
            if name in OUTPUT_NODES.values():
                await var.set_writable()
            else:
                await server.write_attribute_value(var.nodeid, empty)
            self.nodes[name] = var
        await server.start()
        self.server = server
        return self

    async def __aexit__(self, *exc) -> None:
        """Stop the server."""
        await self.server.stop()

    async def publish(self, time_s: float, values: ArrayLike, names: list[str] | None = None) -> None:
        """Publish one sample: ``values`` of ``names`` (default every channel) stamped with machine time ``time_s`` (s).

        Parameters
        ----------
        time_s : float
            Machine time, s.
        values : array-like
            One value per name, in each channel's unit.
        names : list of str or None
            Channel names; None: every channel in order.
        """
        from asyncua import ua

        stamp = timestamp(time_s)
        for name, value in zip(self.names if names is None else names, values):
            dv = ua.DataValue(ua.Variant(float(value), ua.VariantType.Double), SourceTimestamp=stamp,
                              ServerTimestamp=stamp)
            await self.server.write_attribute_value(self.nodes[name].nodeid, dv)
        self.published += 1

    async def read_output(self, key: str) -> float:
        """The value (µm) a client wrote to an output node (``Z``, ``Z_band``, ``Z_compensation`` …).

        Parameters
        ----------
        key : str
            Output key, e.g. ``Z``, ``Z_band``, ``Z_compensation``.

        Returns
        -------
        value : float
            The value written, µm.
        """
        return await self.nodes[OUTPUT_NODES[key]].read_value()

    async def replay(self, time_s: ArrayLike, values: ArrayLike, speed: float = 1.0, start: int = 0) -> float:
        """Publish rows ``start…`` of ``values`` at their machine times, ``speed`` × faster than real time.

        Parameters
        ----------
        time_s : array_like
            (k,) machine times, s.
        values : array_like
            (k, channels) values in the channels' units.
        speed : float
            Machine seconds per wall second.
        start : int
            The first row published.

        Returns
        -------
        float
            The wall seconds taken.
        """
        t = np.asarray(time_s, float)
        wall0 = time.perf_counter()
        for i in range(start, len(t)):
            delay = (t[i] - t[start]) / speed - (time.perf_counter() - wall0)
            if delay > 0:
                await asyncio.sleep(delay)
            await self.publish(t[i], values[i])
        return time.perf_counter() - wall0
