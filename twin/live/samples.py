"""Sample assembly of ``twin live``: the readings of the nodes grouped into samples by their timestamp.

One sample = one timestamp: the value's **SourceTimestamp**; a server that sends none is timed by the
**ServerTimestamp**, and one that sends neither by the time the client received the batch of notifications
(one time per batch, so the values of one publishing cycle stay one sample); which one the run uses is said
once.  A sample is ready when every node has reported it, or ``late_after_s`` wall seconds after its first
reading.  A value for a time already fused is *late*: counted and dropped — unless values keep coming behind
the last fused sample over at least half a sample interval, which is the server's clock jumping back (a
clock set back, a controller restarted with its own clock): that is said once per jump, with the
timestamps, and the times are **re-anchored** — shifted to continue one interval after the last fused
sample — so the filter, which never goes back in time, keeps fusing.
"""
from __future__ import annotations

import datetime as _dt
import logging
from typing import TYPE_CHECKING

import numpy as np

from .replay import machine_time, timestamp

if TYPE_CHECKING:
    from asyncua import ua

    from .readings import ReadingChecks

log = logging.getLogger("thermal_twin")

#: The timestamps a value may be timed by, in order of preference, as the notices name them.
CLOCKS = ("SourceTimestamp", "ServerTimestamp", "the client's receive time")


class SampleAssembler:
    """Readings → samples (see the module docstring).

    Parameters
    ----------
    keys : list of str
        The node map keys a complete sample has.
    late_after_s : float
        Wall seconds to wait for a sample's missing readings.
    endpoint : str
        The server, named in the notices.
    checks : ReadingChecks
        Told each node's update times (its sample interval and stale nodes come from them).
    """

    def __init__(self, keys: list[str], late_after_s: float, endpoint: str, checks: ReadingChecks) -> None:
        self.keys, self.late_after_s, self.endpoint, self.checks = list(keys), late_after_s, endpoint, checks
        self.pending = {}            # machine time → (first seen wall s, {key: (value, status)})
        self.done_until = -np.inf    # machine time of the last fused sample, s
        self.offset = 0.0            # s added to the timestamps since the clock jumped back
        self.late = 0
        self._behind = {}            # machine time → {key: (value, status)} at or before done_until
        self._clocks = set()

    def machine_time(self, value: ua.DataValue, received: _dt.datetime) -> float:
        """The timestamp of ``value`` (see the module docstring) as machine time before re-anchoring, s.

        Parameters
        ----------
        value : asyncua.ua.DataValue
            The notification's value.
        received : datetime.datetime
            When the client received its batch (UTC).

        Returns
        -------
        float
            Machine time, s after :data:`twin.live.replay.EPOCH`.
        """
        clock, stamp = next((c, s) for c, s in zip(CLOCKS, (value.SourceTimestamp, value.ServerTimestamp, received))
                            if s is not None)
        if clock not in self._clocks:
            self._clocks.add(clock)
            if clock != CLOCKS[0]:
                log.warning("live: %s sends values without a SourceTimestamp: those samples are timed by %s",
                            self.endpoint, clock)
        return machine_time(stamp)

    def add(self, key: str, time_s: float, value: float | None, status: ua.StatusCode | None, now: float) -> None:
        """File a value of ``key`` stamped ``time_s`` (machine s, before re-anchoring), received at wall ``now`` (s).

        Parameters
        ----------
        key : str
            Node map key.
        time_s : float
            Its timestamp as machine time, s.
        value : float or None
            The value (None: the server sent none).
        status : asyncua.ua.StatusCode or None
            Its status.
        now : float
            Wall clock (``time.monotonic()``), s.
        """
        t = round(time_s + self.offset, 6)
        if t > self.done_until:
            # this node's clock did not jump: what it sent behind was late for fused samples.  Only its own: a
            # batch holds each node's values in turn, so another node's straggler may come after a jumped value
            for values in self._behind.values():
                values.pop(key, None)
            self._behind = {stamp: values for stamp, values in self._behind.items() if values}
            self._file(key, t, value, status, now)
            return
        self.late += 1
        self._behind.setdefault(t, {})[key] = (value, status)
        interval = self.checks.interval()
        if interval and max(self._behind) - min(self._behind) >= 0.5 * interval:
            self._reanchor(interval, now)

    def _file(self, key, t, value, status, now):
        self.checks.updated(key, t)
        self.pending.setdefault(t, (now, {}))[1][key] = (value, status)

    def _reanchor(self, interval, now):
        """The clock jumped back: shift the times so that the first value behind comes one interval after the last
        fused sample, and file what came behind."""
        first = min(self._behind)
        shift = self.done_until + interval - first
        log.warning("live: %s: the timestamps jumped back %.0f s (a value stamped %s after the sample stamped %s); "
                    "times re-anchored to continue at t = %.15g s", self.endpoint, self.done_until - first,
                    timestamp(first - self.offset).isoformat(), timestamp(self.done_until - self.offset).isoformat(),
                    first + shift)
        self.offset += shift
        behind, self._behind = self._behind, {}
        for t, values in sorted(behind.items()):
            for key, (value, status) in values.items():
                self.late -= 1
                self._file(key, round(t + shift, 6), value, status, now)

    def ready(self, now: float) -> list[float]:
        """Machine times that can be fused at wall time ``now`` (s), in order.

        Parameters
        ----------
        now : float
            Wall clock (``time.monotonic()``), s.

        Returns
        -------
        list of float
            Every time up to the newest sample that is complete or was waited for ``late_after_s``.
        """
        complete = [t for t, (_, v) in self.pending.items() if len(v) == len(self.keys)]
        waited = [t for t, (seen, _) in self.pending.items() if now - seen >= self.late_after_s]
        # everything older than a sample that is fused goes with it: the filter never goes back in time
        newest = max(complete + waited, default=-np.inf)
        return sorted(t for t in self.pending if t <= newest)

    def pop(self, time_s: float) -> dict:
        """Take the sample at ``time_s`` (s) out, to be fused.

        Parameters
        ----------
        time_s : float
            A time :meth:`ready` returned, s.

        Returns
        -------
        dict
            key → (value, status) of the nodes that reported it.
        """
        _, values = self.pending.pop(time_s)
        self.done_until = time_s
        return values
