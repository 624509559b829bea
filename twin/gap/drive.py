"""Operating conditions on the twin's uniform time grid: from measured data or from a scenario.

A *drive* gives the spindle speed (rpm), axis feeds (mm/min), the vertical
ambient gradient (K/m) and the ambient of every convection zone (°C) on a
uniform grid, and can recompute the zone ambients under a hypothesis (an
extra vertical gradient, other zone lags).  The gap effects perturb the twin
through it, so the same effect code serves the diagnosis (measured inputs)
and the benchmark's truth runs (scenario inputs).

Measured ambients come from the air sensors: each zone's ambient at the
reference height is the mean of its air sensors corrected by the gradient;
a zone with a lag (the enclosure) and no sensor follows the room through
that lag, as :meth:`twin.core.scenario.Scenario.zone_ambient` does; other zones
without sensors take the room.
"""
from __future__ import annotations

import numpy as np

from ..core.machine_definition import room_zone
from ..errors import TwinInputError
from .signals import lag, step_values


class Drive:
    """Conditions on ``grid`` (uniform, step ``step_s``); see the module docstring."""

    def __init__(self, grid, spindle_rpm, feed_mm_min, gradient_K_per_m, zones, lags_s, room_zone):
        self.grid = np.asarray(grid, float)
        self.step_s = float(self.grid[1] - self.grid[0])
        self.spindle_rpm = np.asarray(spindle_rpm, float)
        self.feed_mm_min = {a: np.asarray(v, float) for a, v in feed_mm_min.items()}
        self.gradient_K_per_m = np.asarray(gradient_K_per_m, float) * np.ones(len(self.grid))
        self.zones = list(zones)
        self.lags_s = dict(lags_s)
        self.room_zone = room_zone
        self.notes = []

    def __len__(self):
        return len(self.grid)

    def room(self, extra_gradient=None):
        """The room's ambient at the reference height (unlagged), °C."""
        raise NotImplementedError

    def zone_ambient(self, extra_gradient=None, lags_s=None):
        """Ambient of every zone (dict zone → (n,)) under an extra gradient (K/m, (n,)) and zone lags (s)."""
        raise NotImplementedError

    def room_excursion(self):
        """The room ambient minus its mean over the record, K (drives the stratification effect)."""
        room = self.room()
        return room - room.mean()

    def inputs(self, machine, n_extra=0):
        """The nominal thermal input matrix (n, m + n_extra) of a machine, extra columns zero."""
        U = machine.input_matrix(self.spindle_rpm, self.feed_mm_min, self.zone_ambient(), self.gradient_K_per_m)
        return np.hstack([U, np.zeros((len(U), n_extra))])


class MeasuredDrive(Drive):
    """Conditions from measured channels (see the module docstring).

    ``air`` maps zone → list of (readings on the grid (n,), height above the
    reference height, m); ``fallback_room`` (n,) is used when the room has no
    air sensor.
    """

    def __init__(self, grid, spindle_rpm, feed_mm_min, gradient_K_per_m, zones, lags_s, room_zone, air,
                 fallback_room=None):
        super().__init__(grid, spindle_rpm, feed_mm_min, gradient_K_per_m, zones, lags_s, room_zone)
        self.air = {z: list(v) for z, v in air.items() if v}
        self.fallback_room = None if fallback_room is None else np.asarray(fallback_room, float)
        if room_zone not in self.air and self.fallback_room is None:
            if not self.air:
                raise TwinInputError("no ambient: the data has no air sensor; give a scenario for the ambient")
            pooled = [s for v in self.air.values() for s in v]
            self.air[room_zone] = pooled
            self.notes.append(f"zone {room_zone!r} has no air sensor: it takes the mean of all air sensors")
        for z in self.zones:
            if z not in self.air and z != room_zone:
                how = (f"the room through its {self.lags_s[z] / 3600:g} h lag" if self.lags_s.get(z)
                       else "the room")
                self.notes.append(f"zone {z!r} has no air sensor: it follows {how}")

    def _measured_zone(self, zone, extra_gradient):
        g = self.gradient_K_per_m if extra_gradient is None else self.gradient_K_per_m + extra_gradient
        sensors = self.air[zone]
        return np.mean([reading - g * height for reading, height in sensors], axis=0)

    def room(self, extra_gradient=None):
        if self.room_zone in self.air:
            return self._measured_zone(self.room_zone, extra_gradient)
        return self.fallback_room.copy()

    def zone_ambient(self, extra_gradient=None, lags_s=None):
        lags = {**self.lags_s, **(lags_s or {})}
        room = self.room(extra_gradient)
        out = {}
        for z in self.zones:
            if z in self.air:
                out[z] = self._measured_zone(z, extra_gradient)
            elif lags.get(z, 0.0) > 0:
                out[z] = lag(room, self.step_s, lags[z])
            else:
                out[z] = room
        return out


class ScenarioDrive(Drive):
    """Conditions of a scenario (the truth of the benchmark): true zone ambients, events and lags."""

    def __init__(self, scenario, machine, grid):
        rpm, feeds = scenario.operating(grid)
        d = machine.definition
        super().__init__(grid, rpm, feeds, np.full(len(grid), scenario.ambient.gradient_K_per_m), d.zones,
                         d.zone_lags_s, room_zone(d.zones))
        self.scenario = scenario
        self._room = scenario.zone_ambient(self.grid, [self.room_zone])[self.room_zone]
        self._cache = {}

    def room(self, extra_gradient=None):
        return self._room.copy()

    def zone_ambient(self, extra_gradient=None, lags_s=None):
        lags = {**self.lags_s, **(lags_s or {})}
        key = tuple(sorted(lags.items()))
        if key not in self._cache:
            self._cache[key] = self.scenario.zone_ambient(self.grid, self.zones, lags)
        return {z: v.copy() for z, v in self._cache[key].items()}


def measured_drive(machine, grid, record, scenario=None):
    """A :class:`MeasuredDrive` for a measured record (see :mod:`twin.gap.measured`) on ``grid``.

    Spindle speed and feeds are step signals (a sample describes the interval
    before it); ambients are interpolated linearly.  Missing spindle or feed
    channels come from the scenario, or are zero (feeds) / an error (spindle).
    """
    d = machine.definition
    t = record.time_s
    notes = []
    if record.spindle is not None:
        rpm = step_values(t, record.spindle, grid)
    elif scenario is not None:
        rpm = scenario.operating(grid)[0]
        notes.append(f"no spindle channel: the spindle speed of scenario {scenario.name!r} is used")
    else:
        raise TwinInputError("the data has no spindle-speed channel ('spindle_rpm'); give it or a scenario")
    feeds = {}
    for a in "xyz":
        if a in record.feeds:
            feeds[a] = step_values(t, record.feeds[a], grid)
        elif scenario is not None:
            feeds[a] = scenario.operating(grid)[1][a]
        else:
            feeds[a] = np.zeros(len(grid))
    if not record.feeds:
        notes.append("no feed channels: " + (f"feeds of scenario {scenario.name!r}" if scenario is not None
                                             else "feeds taken as zero"))
    if record.gradient is not None:
        gradient = np.interp(grid, t, record.gradient)
    else:
        gradient = np.full(len(grid), scenario.ambient.gradient_K_per_m if scenario is not None else 0.0)
    air = {}
    for name, zone, height, values in record.air:
        air.setdefault(zone, []).append((np.interp(grid, t, values), height))
    room = room_zone(d.zones)
    fallback = None
    if room not in air and scenario is not None:
        fallback = scenario.zone_ambient(grid, [room])[room]
        notes.append(f"no air sensor in zone {room!r}: the ambient of scenario {scenario.name!r} is used")
    drive = MeasuredDrive(grid, rpm, feeds, gradient, d.zones, d.zone_lags_s, room, air, fallback)
    drive.notes = notes + drive.notes
    return drive
