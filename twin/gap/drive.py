"""Operating conditions on the twin's uniform time grid: from measured data or from a scenario.

A *drive* gives the spindle speed (rpm), axis feeds (mm/min), the vertical
ambient gradient (K/m) and the ambient of every convection zone (°C) on a
uniform grid, and can recompute the zone ambients under a hypothesis (an
extra vertical gradient, other zone lags).  The gap effects perturb the twin
through it, so the same effect code serves the diagnosis (measured inputs)
and the benchmark's truth runs (scenario inputs).

Spindle speed and feeds are piecewise-constant (or event) signals, and the
twin integrates them exactly: every power input over a solver step is the
*interval mean* of the power over that step (:meth:`Drive.step_mean`, by
:func:`fea.inputs.interval_means`), as the full FE of
:func:`twin.core.simulate.simulate` does, so the energy of a 10 min cycle sampled
every 45 s is not lost to an end-of-step hold.  A measured sample of the speed
is the speed *at* its time; when two samples differ, the change happened
somewhere between them.  :func:`measured_drive` puts it at ``position`` of the
way (0: the earliest possible time, the convention of a logger that writes the
value of the interval before each sample, as the twin's own datasets do; ½:
the midpoint, unbiased for a logger that writes the instant's value; 1: the
latest); :func:`twin.gap.diagnose.reconstruct_inputs` chooses it on the fit
part and measures what ± half a sample does to the twin (the *timing floor*
of :mod:`twin.gap.verdict`).
Irregular sampling and a logger clock offset from the programme's minute
need nothing else.

Measured ambients come from the air sensors: each zone's ambient at the
reference height is the mean of its air sensors corrected by the gradient;
a zone with a lag (the enclosure) and no sensor follows the room through
that lag, as :meth:`twin.core.scenario.Scenario.zone_ambient` does; other zones
without sensors take the room.
"""
from __future__ import annotations

import numpy as np

from fea.inputs import interval_means

from ..core.machine import power_input
from ..core.machine_definition import room_zone
from ..errors import TwinInputError
from .signals import lag


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

    def operating_at(self, times_s):
        """Spindle speed (k,) and feeds {axis: (k,)} at any times inside the grid (continuous time)."""
        raise NotImplementedError

    def breakpoints_s(self):
        """Times where the operating conditions may jump (interval means split there)."""
        return ()

    def step_mean(self, fn):
        """``fn(rpm, feeds)`` averaged exactly over every grid step → (n, …): row k is the mean over
        (grid[k−1], grid[k]] (what the solvers hold over step k), row 0 the value at grid[0]."""
        def at(t):
            rpm, feeds = self.operating_at(t)
            return np.asarray(fn(rpm, feeds), float)

        first = at(self.grid[:1])
        means = interval_means(at, self.grid, self.breakpoints_s())
        return np.concatenate([first.reshape(1, -1), means]).reshape((len(self.grid),) + first.shape[1:])

    def idle(self):
        """A copy with the spindle and feeds stopped (for the steady start)."""
        return IdleDrive(self)

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
        """The nominal thermal input matrix (n, m + n_extra) of a machine, extra columns zero; source powers
        as step means (:meth:`step_mean`), the other inputs at the grid points."""
        U = machine.input_matrix(self.spindle_rpm, self.feed_mm_min, self.zone_ambient(), self.gradient_K_per_m)
        names = machine.thermal.input_names
        for src in machine.definition.sources:
            U[:, names.index(power_input(src.name))] = self.step_mean(src.power_W)
        return np.hstack([U, np.zeros((len(U), n_extra))])


class IdleDrive:
    """A drive with the spindle and feeds stopped; everything else delegates to the drive it wraps."""

    def __init__(self, drive):
        self._drive = drive
        self.spindle_rpm = np.zeros_like(drive.spindle_rpm)
        self.feed_mm_min = {a: np.zeros_like(v) for a, v in drive.feed_mm_min.items()}

    def __getattr__(self, name):
        if name == "_drive":
            raise AttributeError(name)
        return getattr(self._drive, name)

    def operating_at(self, times_s):
        t = np.atleast_1d(np.asarray(times_s, float))
        return np.zeros(t.shape), {a: np.zeros(t.shape) for a in self.feed_mm_min}

    def breakpoints_s(self):
        return ()

    def step_mean(self, fn):
        return Drive.step_mean(self, fn)

    def inputs(self, machine, n_extra=0):
        return Drive.inputs(self, machine, n_extra)


class MeasuredDrive(Drive):
    """Conditions from measured channels (see the module docstring).

    ``air`` maps zone → list of (readings on the grid (n,), height above the
    reference height, m); ``fallback_room`` (n,) is used when the room has no
    air sensor.
    """

    def __init__(self, grid, operating, gradient_K_per_m, zones, lags_s, room_zone, air, fallback_room=None):
        self.operating = operating
        rpm = np.zeros(len(grid))
        super().__init__(grid, rpm, {a: rpm for a in operating.feeds}, gradient_K_per_m, zones, lags_s, room_zone)
        self.spindle_rpm = self.step_mean(lambda n, f: n)
        self.feed_mm_min = {a: self.step_mean(lambda n, f, a=a: f[a]) for a in operating.feeds}
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

    def operating_at(self, times_s):
        return self.operating(times_s)

    def breakpoints_s(self):
        return self.operating.edges_s

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

    def operating_at(self, times_s):
        return self.scenario.operating(np.atleast_1d(np.asarray(times_s, float)))

    def breakpoints_s(self):
        return self.scenario.breakpoints_s()

    def zone_ambient(self, extra_gradient=None, lags_s=None):
        lags = {**self.lags_s, **(lags_s or {})}
        key = tuple(sorted(lags.items()))
        if key not in self._cache:
            self._cache[key] = self.scenario.zone_ambient(self.grid, self.zones, lags)
        return {z: v.copy() for z, v in self._cache[key].items()}


class Operating:
    """Spindle speed and feeds in continuous time, from measured samples and (for what the record lacks) a
    scenario; a callable ``times → (rpm (k,), {axis: feed (k,)})`` with the jump times in ``edges_s``.

    A measured signal is piecewise constant: sample j holds from ``position`` of the way from sample j−1 to
    sample j up to ``position`` of the way to sample j+1 (see the module docstring).
    """

    def __init__(self, times_s, measured, scenario=None, position=0.5):
        t = np.asarray(times_s, float)
        self.position = float(position)
        self.edges = t[:-1] + self.position * np.diff(t)
        self.measured = {k: np.asarray(v, float) for k, v in measured.items()}
        self.scenario = scenario
        self.feeds = "xyz"
        cuts = [self.edges] if self.measured else []
        if scenario is not None and len(self.measured) < 4:
            cuts.append(scenario.breakpoints_s())
        self.edges_s = np.unique(np.concatenate(cuts)) if cuts else np.zeros(0)

    def __call__(self, times_s):
        t = np.atleast_1d(np.asarray(times_s, float))
        k = np.searchsorted(self.edges, t, side="right")
        rpm_sc, feeds_sc = self.scenario.operating(t) if self.scenario is not None else (None, None)

        def signal(name, fallback):
            if name in self.measured:
                return self.measured[name][k]
            return np.zeros(t.shape) if fallback is None else np.asarray(fallback, float)

        feeds = {a: signal(f"feed_{a}", None if feeds_sc is None else feeds_sc[a]) for a in self.feeds}
        return signal("spindle", rpm_sc), feeds


def measured_drive(machine, grid, record, scenario=None, position=0.5):
    """A :class:`MeasuredDrive` for a measured record (see :mod:`twin.gap.measured`) on ``grid``.

    Spindle speed and feeds are piecewise-constant signals (:class:`Operating`, change times at ``position``
    between samples); ambients are interpolated linearly.  Missing spindle or feed channels come from the
    scenario, or are zero (feeds) / an error (spindle).
    """
    d = machine.definition
    t = record.time_s
    notes = []
    measured = {f"feed_{a}": v for a, v in record.feeds.items()}
    if record.spindle is not None:
        measured["spindle"] = record.spindle
    elif scenario is not None:
        notes.append(f"no spindle channel: the spindle speed of scenario {scenario.name!r} is used")
    else:
        raise TwinInputError("the data has no spindle-speed channel ('spindle_rpm'); give it or a scenario")
    if not record.feeds:
        notes.append("no feed channels: " + (f"feeds of scenario {scenario.name!r}" if scenario is not None
                                             else "feeds taken as zero"))
    operating = Operating(t, measured, scenario, position)
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
    drive = MeasuredDrive(grid, operating, gradient, d.zones, d.zone_lags_s, room, air, fallback)
    drive.notes = notes + drive.notes
    return drive
