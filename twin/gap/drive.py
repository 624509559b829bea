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

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from fea.inputs import interval_means

from ..core.machine import Machine, power_input
from ..core.machine_definition import room_zone
from ..core.scenario import Scenario
from ..errors import TwinInputError
from .measured import Record
from .signals import lag


class Drive:
    """Conditions on ``grid`` (uniform, step ``step_s``); see the module docstring.

    Parameters
    ----------
    grid : ndarray, shape (n,)
        Uniform time grid, s.
    spindle_rpm : ndarray, shape (n,)
        Spindle speed on the grid, rpm.
    feed_mm_min : mapping of str to ndarray, shape (n,)
        Axis (``x``, ``y``, ``z``) → feed on the grid, mm/min.
    gradient_K_per_m : float or ndarray, shape (n,)
        Vertical ambient gradient, K/m (a constant is repeated on the grid).
    zones : sequence of str
        The machine's convection zones.
    lags_s : mapping of str to float
        Zone → air lag behind the room, s (zones without a lag may be absent).
    room_zone : str
        The zone whose ambient is the room.
    """

    def __init__(self, grid: np.ndarray, spindle_rpm: np.ndarray, feed_mm_min: Mapping[str, np.ndarray],
                 gradient_K_per_m: float | np.ndarray, zones: Sequence[str], lags_s: Mapping[str, float],
                 room_zone: str):
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

    def operating_at(self, times_s: float | np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Spindle speed (k,) and feeds {axis: (k,)} at any times inside the grid (continuous time).

        Parameters
        ----------
        times_s : float or ndarray, shape (k,)
            Times, s.

        Returns
        -------
        spindle_rpm : ndarray, shape (k,)
            Spindle speed, rpm.
        feed_mm_min : dict of str to ndarray, shape (k,)
            Axis → feed, mm/min.
        """
        raise NotImplementedError

    def breakpoints_s(self) -> Sequence[float] | np.ndarray:
        """Times where the operating conditions may jump (interval means split there).

        Returns
        -------
        sequence of float or ndarray
            Jump times, s (none for the base class).
        """
        return ()

    def step_mean(self, fn: Callable[[np.ndarray, dict[str, np.ndarray]], np.ndarray]) -> np.ndarray:
        """``fn(rpm, feeds)`` averaged exactly over every grid step → (n, …): row k is the mean over
        (grid[k−1], grid[k]] (what the solvers hold over step k), row 0 the value at grid[0].

        Parameters
        ----------
        fn : callable
            ``fn(rpm, feeds)`` of the spindle speed (k,), rpm, and feeds {axis: (k,)}, mm/min; returns values
            (k,) or (k, …) in any unit (e.g. a source's power, W).

        Returns
        -------
        ndarray, shape (n,) or (n, …)
            Step means on the grid, in the unit of ``fn``.
        """
        def at(t):
            rpm, feeds = self.operating_at(t)
            return np.asarray(fn(rpm, feeds), float)

        first = at(self.grid[:1])
        means = interval_means(at, self.grid, self.breakpoints_s())
        return np.concatenate([first.reshape(1, -1), means]).reshape((len(self.grid),) + first.shape[1:])

    def idle(self) -> IdleDrive:
        """A copy with the spindle and feeds stopped (for the steady start).

        Returns
        -------
        IdleDrive
            Wraps this drive; ambients and gradient unchanged.
        """
        return IdleDrive(self)

    def room(self, extra_gradient: float | np.ndarray | None = None) -> np.ndarray:
        """The room's ambient at the reference height (unlagged), °C.

        Parameters
        ----------
        extra_gradient : float or ndarray, shape (n,), optional
            Vertical gradient added to the drive's, K/m (moves ambients estimated from air sensors at other
            heights).

        Returns
        -------
        ndarray, shape (n,)
            Room ambient on the grid, °C.
        """
        raise NotImplementedError

    def zone_ambient(self, extra_gradient: float | np.ndarray | None = None,
                     lags_s: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
        """Ambient of every zone (dict zone → (n,)) under an extra gradient (K/m, (n,)) and zone lags (s).

        Parameters
        ----------
        extra_gradient : float or ndarray, shape (n,), optional
            Vertical gradient added to the drive's, K/m.
        lags_s : mapping of str to float, optional
            Zone → air lag, s, replacing the drive's lag of that zone.

        Returns
        -------
        dict of str to ndarray, shape (n,)
            Zone → ambient at the reference height on the grid, °C.
        """
        raise NotImplementedError

    def room_excursion(self) -> np.ndarray:
        """The room ambient minus its mean over the record, K (drives the stratification effect).

        Returns
        -------
        ndarray, shape (n,)
            Room ambient excursion on the grid, K.
        """
        room = self.room()
        return room - room.mean()

    def inputs(self, machine: Machine, n_extra: int = 0) -> np.ndarray:
        """The nominal thermal input matrix (n, m + n_extra) of a machine, extra columns zero; source powers
        as step means (:meth:`step_mean`), the other inputs at the grid points.

        Parameters
        ----------
        machine : Machine
            The built machine (its m thermal inputs).
        n_extra : int, default 0
            Number of zero columns appended (the effects' extra inputs).

        Returns
        -------
        ndarray, shape (n, m + n_extra)
            In the order of ``machine.thermal.input_names`` (ambients °C, gradient K/m, powers W), then the
            extra columns.
        """
        U = machine.input_matrix(self.spindle_rpm, self.feed_mm_min, self.zone_ambient(), self.gradient_K_per_m)
        names = machine.thermal.input_names
        for src in machine.definition.sources:
            U[:, names.index(power_input(src.name))] = self.step_mean(src.power_W)
        return np.hstack([U, np.zeros((len(U), n_extra))])


class IdleDrive:
    """A drive with the spindle and feeds stopped; everything else delegates to the drive it wraps.

    Parameters
    ----------
    drive : Drive
        The drive wrapped (grid, ambients, gradient, zones).
    """

    def __init__(self, drive: Drive):
        self._drive = drive
        self.spindle_rpm = np.zeros_like(drive.spindle_rpm)
        self.feed_mm_min = {a: np.zeros_like(v) for a, v in drive.feed_mm_min.items()}

    def __getattr__(self, name):
        if name == "_drive":
            raise AttributeError(name)
        return getattr(self._drive, name)

    def operating_at(self, times_s: float | np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Zero spindle speed and feeds at any times.

        Parameters
        ----------
        times_s : float or ndarray, shape (k,)
            Times, s.

        Returns
        -------
        spindle_rpm : ndarray, shape (k,)
            Zeros, rpm.
        feed_mm_min : dict of str to ndarray, shape (k,)
            Axis → zeros, mm/min.
        """
        t = np.atleast_1d(np.asarray(times_s, float))
        return np.zeros(t.shape), {a: np.zeros(t.shape) for a in self.feed_mm_min}

    def breakpoints_s(self) -> Sequence[float] | np.ndarray:
        """No jump times: the conditions are constant.

        Returns
        -------
        sequence of float or ndarray
            Empty, s.
        """
        return ()

    def step_mean(self, fn: Callable[[np.ndarray, dict[str, np.ndarray]], np.ndarray]) -> np.ndarray:
        """As :meth:`Drive.step_mean`, with the spindle and feeds stopped.

        Parameters
        ----------
        fn : callable
            ``fn(rpm, feeds)`` of the spindle speed (k,), rpm, and feeds {axis: (k,)}, mm/min.

        Returns
        -------
        ndarray, shape (n,) or (n, …)
            Step means on the grid, in the unit of ``fn``.
        """
        return Drive.step_mean(self, fn)

    def inputs(self, machine: Machine, n_extra: int = 0) -> np.ndarray:
        """As :meth:`Drive.inputs`, with the spindle and feeds stopped (the ambients and gradient of the wrapped
        drive).

        Parameters
        ----------
        machine : Machine
            The built machine (its m thermal inputs).
        n_extra : int, default 0
            Number of zero columns appended.

        Returns
        -------
        ndarray, shape (n, m + n_extra)
            Thermal inputs (°C, K/m, W), then zero columns.
        """
        return Drive.inputs(self, machine, n_extra)


class MeasuredDrive(Drive):
    """Conditions from measured channels (see the module docstring).

    ``air`` maps zone → list of (readings on the grid (n,), height above the
    reference height, m); ``fallback_room`` (n,) is used when the room has no
    air sensor.

    Parameters
    ----------
    grid : ndarray, shape (n,)
        Uniform time grid, s.
    operating : Operating
        Spindle speed and feeds in continuous time (their grid values are step means).
    gradient_K_per_m : float or ndarray, shape (n,)
        Vertical ambient gradient, K/m.
    zones : sequence of str
        The machine's convection zones.
    lags_s : mapping of str to float
        Zone → air lag behind the room, s.
    room_zone : str
        The zone whose ambient is the room.
    air : mapping of str to list of (ndarray, float)
        Zone → (readings on the grid (n,), °C; height above the reference height, m) of its air sensors.
    fallback_room : ndarray, shape (n,), optional
        Room ambient, °C, when the room zone has no air sensor.

    Raises
    ------
    TwinInputError
        No air sensor and no ``fallback_room``.
    """

    def __init__(self, grid: np.ndarray, operating: Operating, gradient_K_per_m: float | np.ndarray,
                 zones: Sequence[str], lags_s: Mapping[str, float], room_zone: str,
                 air: Mapping[str, list[tuple[np.ndarray, float]]], fallback_room: np.ndarray | None = None):
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

    def operating_at(self, times_s: float | np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Measured spindle speed and feeds at any times (:class:`Operating`).

        Parameters
        ----------
        times_s : float or ndarray, shape (k,)
            Times, s.

        Returns
        -------
        spindle_rpm : ndarray, shape (k,)
            Spindle speed, rpm.
        feed_mm_min : dict of str to ndarray, shape (k,)
            Axis → feed, mm/min.
        """
        return self.operating(times_s)

    def breakpoints_s(self) -> Sequence[float] | np.ndarray:
        """The change times of the measured (and scenario) spindle and feed signals.

        Returns
        -------
        ndarray
            ``Operating.edges_s``, s.
        """
        return self.operating.edges_s

    def _measured_zone(self, zone, extra_gradient):
        g = self.gradient_K_per_m if extra_gradient is None else self.gradient_K_per_m + extra_gradient
        sensors = self.air[zone]
        return np.mean([reading - g * height for reading, height in sensors], axis=0)

    def room(self, extra_gradient: float | np.ndarray | None = None) -> np.ndarray:
        """The room's ambient at the reference height: its air sensors' mean, each corrected by the gradient
        times its height, or ``fallback_room``.

        Parameters
        ----------
        extra_gradient : float or ndarray, shape (n,), optional
            Vertical gradient added to the drive's, K/m.

        Returns
        -------
        ndarray, shape (n,)
            Room ambient on the grid, °C.
        """
        if self.room_zone in self.air:
            return self._measured_zone(self.room_zone, extra_gradient)
        return self.fallback_room.copy()

    def zone_ambient(self, extra_gradient: float | np.ndarray | None = None,
                     lags_s: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
        """Ambient of every zone: from its air sensors, else the room through the zone's lag, else the room.

        Parameters
        ----------
        extra_gradient : float or ndarray, shape (n,), optional
            Vertical gradient added to the drive's, K/m.
        lags_s : mapping of str to float, optional
            Zone → air lag, s, replacing the drive's lag of that zone.

        Returns
        -------
        dict of str to ndarray, shape (n,)
            Zone → ambient at the reference height on the grid, °C.
        """
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
    """Conditions of a scenario (the truth of the benchmark): true zone ambients, events and lags.

    Parameters
    ----------
    scenario : Scenario
        The scenario (operating conditions, ambient, events).
    machine : Machine
        The built machine (its zones and zone lags).
    grid : ndarray, shape (n,)
        Uniform time grid, s.
    """

    def __init__(self, scenario: Scenario, machine: Machine, grid: np.ndarray):
        rpm, feeds = scenario.operating(grid)
        d = machine.definition
        super().__init__(grid, rpm, feeds, np.full(len(grid), scenario.ambient.gradient_K_per_m), d.zones,
                         d.zone_lags_s, room_zone(d.zones))
        self.scenario = scenario
        self._room = scenario.zone_ambient(self.grid, [self.room_zone])[self.room_zone]
        self._cache = {}

    def room(self, extra_gradient: float | np.ndarray | None = None) -> np.ndarray:
        """The scenario's room ambient at the reference height (true, so ``extra_gradient`` does not move it).

        Parameters
        ----------
        extra_gradient : float or ndarray, shape (n,), optional
            Ignored, K/m.

        Returns
        -------
        ndarray, shape (n,)
            Room ambient on the grid, °C.
        """
        return self._room.copy()

    def operating_at(self, times_s: float | np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The scenario's spindle speed and feeds at any times.

        Parameters
        ----------
        times_s : float or ndarray, shape (k,)
            Times, s.

        Returns
        -------
        spindle_rpm : ndarray, shape (k,)
            Spindle speed, rpm.
        feed_mm_min : dict of str to ndarray, shape (k,)
            Axis → feed, mm/min.
        """
        return self.scenario.operating(np.atleast_1d(np.asarray(times_s, float)))

    def breakpoints_s(self) -> Sequence[float] | np.ndarray:
        """The scenario's jump and kink times (:meth:`twin.core.scenario.Scenario.breakpoints_s`).

        Returns
        -------
        ndarray
            Times, s.
        """
        return self.scenario.breakpoints_s()

    def zone_ambient(self, extra_gradient: float | np.ndarray | None = None,
                     lags_s: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
        """The scenario's true ambient of every zone under zone lags (cached per lag set); ``extra_gradient`` does
        not move the ambients at the reference height.

        Parameters
        ----------
        extra_gradient : float or ndarray, shape (n,), optional
            Ignored, K/m.
        lags_s : mapping of str to float, optional
            Zone → air lag, s, replacing the drive's lag of that zone.

        Returns
        -------
        dict of str to ndarray, shape (n,)
            Zone → ambient at the reference height on the grid, °C (copies).
        """
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

    Parameters
    ----------
    times_s : ndarray, shape (n_samples,)
        Sample times of the record, s, increasing.
    measured : mapping of str to ndarray, shape (n_samples,)
        Channel → samples: ``spindle`` (rpm) and ``feed_x``, ``feed_y``, ``feed_z`` (mm/min), any of them.
    scenario : Scenario, optional
        Supplies the channels not measured (else they are zero).
    position : float or ndarray, shape (n_samples - 1,), default 0.5
        Where between two samples a change is put, as a fraction of the sample interval (0 … 1); an array
        gives it per interval.
    """

    def __init__(self, times_s: np.ndarray, measured: Mapping[str, np.ndarray], scenario: Scenario | None = None,
                 position: float | np.ndarray = 0.5):
        t = np.asarray(times_s, float)
        self.edges = t[:-1] + np.asarray(position, float) * np.diff(t)
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


def measured_drive(machine: Machine, grid: np.ndarray, record: Record, scenario: Scenario | None = None,
                   position: float | np.ndarray = 0.5) -> MeasuredDrive:
    """A :class:`MeasuredDrive` for a measured record (see :mod:`twin.gap.measured`) on ``grid``.

    Spindle speed and feeds are piecewise-constant signals (:class:`Operating`, change times at ``position``
    between samples); ambients are interpolated linearly.  Missing spindle or feed channels come from the
    scenario, or are zero (feeds) / an error (spindle).

    Parameters
    ----------
    machine : Machine
        The built machine (zones, zone lags).
    grid : ndarray, shape (n,)
        Uniform time grid of the twin, s.
    record : Record
        The measured record matched to the machine.
    scenario : Scenario, optional
        Supplies the spindle, feeds, gradient and room ambient the record lacks.
    position : float or ndarray, shape (n_samples - 1,), default 0.5
        Where between two differing samples a spindle or feed change is put, fraction of the sample interval
        (0: earliest, 0.5: midpoint, 1: latest); an array gives it per interval.

    Returns
    -------
    MeasuredDrive
        With ``notes`` on what came from the scenario or was assumed.

    Raises
    ------
    TwinInputError
        No spindle-speed channel and no scenario, or no ambient at all.
    """
    d = machine.definition
    t = record.time_s
    notes = []
    measured = {f"feed_{a}": v for a, v in record.feeds.items()}
    if record.spindle is not None:
        measured["spindle"] = record.spindle
    elif scenario is not None:
        notes.append(f"no spindle channel: the spindle speed of scenario {scenario.name!r} is used")
    elif "spindle" in record.report["empty_columns"]:
        raise TwinInputError(f"{record.report['source']}: column {record.report['empty_columns']['spindle']!r} "
                             "holds no value; give the spindle speed, or a scenario that has it")
    else:
        raise TwinInputError("the data has no spindle-speed channel ('spindle_rpm'); give it or a scenario")
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
