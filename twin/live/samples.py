"""Sample assembly of ``twin live``: the readings of the nodes grouped into samples by their timestamp.

One sample = one timestamp: the value's **SourceTimestamp**; a server that sends none is timed by the
**ServerTimestamp**, and one that sends neither by the time the client received the batch of notifications
(one time per batch, so the values of one publishing cycle stay one sample); which one the run uses is said
once.  A sample is ready when every node has reported it, or ``late_after_s`` wall seconds after its first
reading.  Each node is judged against its **own** previous timestamp (a server sends one node's values in
order): a value for a time already fused that repeats it (a re-subscription resends each node's current value,
and a node reported only on change carries the time it last changed) or is newer than it (a node that lags, a
straggler) is *late*: counted and dropped.  Only a value *older* than its
node's previous one may be the server's clock jumping back (a clock set back, a controller restarted with its
own clock): when such values keep coming behind the last fused sample over at least half a sample interval
(with no interval known yet: at two timestamps, their spacing taken for it), that is said once per jump, with
the timestamps, and the times are **re-anchored** — shifted to continue one interval after the last fused
sample — so the filter, which never goes back in time, keeps fusing.  Each node takes the shift when its own
clock is seen going back (or, reported on change, when its next value fits the new clock and not its old one),
so a straggler stamped before the jump is never shifted into the future.
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
        self.offset = 0.0            # s added to the timestamps since the clock last jumped back
        self.late = 0
        self._last = {}              # key → its last timestamp, machine s before re-anchoring
        self._offsets = {}           # key → s added to its timestamps (it takes a jump's shift when it jumps)
        self._suspects = set()       # keys whose values came behind their own previous one and the fused samples
        self._behind = {}            # their timestamp (machine s before re-anchoring) → {key: (value, status)}
        self._newest = -np.inf       # machine time of the newest value filed, s
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
        stamp, last = round(time_s, 6), self._last.get(key)
        self._last[key] = stamp
        back = last is not None and stamp < last
        if self._offsets.get(key, self.offset) != self.offset and (back or self._in_new_clock(key, stamp)):
            # the clock jump the other nodes were re-anchored for reaches this node: it takes their shift
            self._offsets[key], back = self.offset, False
        t = round(stamp + self._offsets.setdefault(key, self.offset), 6)
        if t > self.done_until:
            # this node's clock did not jump: what it sent behind was late for fused samples
            self._clear_behind(key)
            self._file(key, t, value, status, now)
            return
        self.late += 1
        # a repeat of the node's last timestamp is nothing new; only values behind it may be a jump
        if back or (key in self._suspects and stamp != last):
            self._suspects.add(key)
            self._behind.setdefault(stamp, {})[key] = (value, status)
            self._maybe_reanchor(now)

    def _in_new_clock(self, key, stamp):
        """Whether ``stamp`` (machine s, before re-anchoring) of ``key``, a node that has not taken the last jump's
        shift, is late in its old clock but fits the new one: a node reported on change whose first value since the
        jump is later than its last one.  A straggler of the old clock would land far beyond the samples filed."""
        if stamp + self._offsets[key] > self.done_until:
            return False
        return self.done_until < stamp + self.offset <= self._newest + (self.checks.interval() or 0.0)

    def _clear_behind(self, key):
        self._suspects.discard(key)
        for values in self._behind.values():
            values.pop(key, None)
        self._behind = {stamp: values for stamp, values in self._behind.items() if values}

    def _file(self, key, t, value, status, now):
        self._newest = max(self._newest, t)
        self.checks.updated(key, t)
        self.pending.setdefault(t, (now, {}))[1][key] = (value, status)

    def _maybe_reanchor(self, now):
        """Re-anchor when the values behind span half an interval (no interval known yet: two timestamps)."""
        stamps = sorted(self._behind)
        interval = self.checks.interval() or (stamps[1] - stamps[0] if len(stamps) > 1 else None)
        if interval and stamps[-1] - stamps[0] >= 0.5 * interval:
            self._reanchor(interval, now)

    def _reanchor(self, interval, now):
        """The clock jumped back: shift the times so that the first value behind comes one interval after the last
        fused sample, and file what came behind (its nodes take the new shift)."""
        first = min(self._behind)
        offset = self.done_until + interval - first
        log.warning("live: %s: the timestamps jumped back %.0f s (a value stamped %s after the sample stamped %s); "
                    "times re-anchored to continue at t = %.15g s", self.endpoint, self.done_until - self.offset - first,
                    timestamp(first).isoformat(), timestamp(self.done_until - self.offset).isoformat(),
                    first + offset)
        self.offset = offset
        behind, self._behind, self._suspects = self._behind, {}, set()
        for stamp, values in sorted(behind.items()):
            for key, (value, status) in values.items():
                self.late -= 1
                self._offsets[key] = offset
                self._file(key, round(stamp + offset, 6), value, status, now)

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
