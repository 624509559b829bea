"""What ``twin live`` refuses to fuse, per node: readings whose OPC UA status is not Good, readings outside the
plausible range of their kind (:data:`twin.core.plausible.PLAUSIBLE`: a DS18x20 reads −127 °C when it is
disconnected; a spindle speed beyond :data:`MAX_SPINDLE_RPM`), readings the observer's innovation gate rejects (:func:`twin.live.observer.gated`), and nodes
that stop updating.

Each is counted per node (the summary lists them) and named once on stderr when it starts: a session of
hours must not flood the terminal, and must not hide a sensor the filter has stopped using either.
"""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np

from ..core.plausible import PLAUSIBLE

if TYPE_CHECKING:
    from asyncua import ua

    from .nodemap import NodeMap

log = logging.getLogger("thermal_twin")

#: A node is stale when its last update is older than this many sample intervals (the nodes' median spacing).
STALE_INTERVALS = 5
#: The fastest plausible spindle speed, rpm: beyond the fastest machine-tool spindles (about 60 000 rpm), so a
#: faster reading is a unit or scaling error (1e9 rpm would drive the model to millimetres of drift).  A negative
#: speed is the spindle turning in reverse (M04), whose heat the model takes by its magnitude.
MAX_SPINDLE_RPM = 100_000.0
#: Plausible range and unit per reading kind.
RANGES = {"air": (*PLAUSIBLE["air"], "°C"), "temperature": (*PLAUSIBLE["temperature"], "°C"),
          "spindle": (-MAX_SPINDLE_RPM, MAX_SPINDLE_RPM, "rpm")}
#: What each reason is called in the summary.
REASONS = {"status": "status not Good", "type": "not a number", "range": "outside the plausible range",
           "gate": "innovation gate"}


class ReadingChecks:
    """Per-node checks of the readings (see the module docstring).

    Parameters
    ----------
    node_map : NodeMap
        The nodes (named in the notices with their map entry).
    thermometers : list of str
        The thermometer keys the observer fuses.
    """

    def __init__(self, node_map: NodeMap, thermometers: list[str]) -> None:
        self.map = node_map
        self.kinds = {"spindle_speed": "spindle", "room_air": "air", **dict.fromkeys(thermometers, "temperature")}
        self.watched = ["room_air", *thermometers]
        #: key → reason (:data:`REASONS`) → readings rejected
        self.rejected: dict[str, dict[str, int]] = {}
        self._named = set()
        self._updates = {}          # key → (last update, the one before), machine s
        self._stale = set()

    def reading(self, key: str, value: float | None, status: ua.StatusCode | None, time_s: float) -> float:
        """The reading as the observer may use it: NaN if missing, if its status is not Good or if implausible.

        Parameters
        ----------
        key : str
            Node map key (``room_air``, ``T18`` …).
        value : float or None
            The value received, in the node's unit (rpm, °C).
        status : asyncua.ua.StatusCode or None
            Its OPC UA status (None: Good).
        time_s : float
            Machine time of the sample, s.

        Returns
        -------
        float
            The value, or NaN.
        """
        if status is not None and not status.is_good():
            self.reject(key, "status", time_s, f"status {status.name}")
            return np.nan
        try:
            value = np.nan if value is None else float(value)
        except (TypeError, ValueError):            # a String or structure node: no reading at all
            self.reject(key, "type", time_s, f"{value!r} is not a number")
            return np.nan
        kind = self.kinds.get(key)
        if kind is not None and np.isfinite(value):
            lo, hi, unit = RANGES[kind]
            if not lo <= value <= hi:
                what = {"air": "an air sensor", "temperature": "a temperature sensor", "spindle": "a spindle"}[kind]
                self.reject(key, "range", time_s, f"{value:g} {unit}, outside the plausible {lo:g} … {hi:g} {unit} "
                                                  f"of {what}")
                return np.nan
        return value

    def reject(self, key: str, reason: str, time_s: float, what: str) -> None:
        """Count a rejected reading of ``key``; name the node on stderr the first time ``reason`` rejects it.

        Parameters
        ----------
        key : str
            Node map key.
        reason : str
            A key of :data:`REASONS`.
        time_s : float
            Machine time of the sample, s.
        what : str
            The reading, for the notice.
        """
        counts = self.rejected.setdefault(key, {})
        counts[reason] = counts.get(reason, 0) + 1
        if (key, reason) not in self._named:
            self._named.add((key, reason))
            log.warning("live: %s: reading at t = %.15g s rejected (%s); such readings are left out and counted",
                        self.map.where(key), time_s, what)

    def summary(self) -> str:
        """``T18 1000 (outside the plausible range), …``, or "" when nothing was rejected.

        Returns
        -------
        str
            One entry per node and reason.
        """
        return ", ".join(f"{key} {n} ({REASONS[reason]})" for key, counts in self.rejected.items()
                         for reason, n in counts.items())

    def updated(self, key: str, time_s: float) -> None:
        """Note that ``key`` reported a value stamped ``time_s`` (machine s).

        Parameters
        ----------
        key : str
            Node map key.
        time_s : float
            Machine time of the value, s.
        """
        last = self._updates.get(key)
        if last is None or time_s > last[0]:
            self._updates[key] = (time_s, None if last is None else last[0])
        self._stale.discard(key)

    def interval(self) -> float | None:
        """The sample interval: the median over the nodes of the spacing of their last two updates, s (None: unknown)."""
        spacings = [a - b for a, b in self._updates.values() if b is not None]
        return float(np.median(spacings)) if spacings else None

    def check_stale(self, time_s: float) -> None:
        """Name once each watched node whose last update is more than :data:`STALE_INTERVALS` intervals old.

        Parameters
        ----------
        time_s : float
            Machine time of the sample being fused, s.
        """
        interval = self.interval()
        if not interval:
            return
        for key in self.watched:
            last = self._updates.get(key)
            if key in self._stale or last is None or time_s - last[0] <= STALE_INTERVALS * interval:
                continue
            self._stale.add(key)
            log.warning("live: %s has not updated since t = %.15g s (%.0f s before the sample at t = %.15g s, "
                        "%d sample intervals); its readings are missing", self.map.where(key), last[0],
                        time_s - last[0], time_s, round((time_s - last[0]) / interval))
