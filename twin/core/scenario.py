"""Scenarios (TOML under ``scenarios/``): duty cycles, ambient, events, initial state, noise and seed.

A scenario turns into operating conditions on any time grid: spindle speed
(rpm), axis feeds (mm/min), the ambient temperature of each convection zone
(°C) and the vertical ambient gradient (K/m).  See ``docs/scenarios.md``
for the format; every shipped scenario is an example.

Point values of piecewise-constant duty cycles are left limits (the sample
at the moment the spindle stops still shows it running).  The solver does
not use point values: it integrates the inputs over each time step
(:meth:`Scenario.breakpoints_s` tells it where they jump), so every segment
injects exactly its energy whether or not its ends fall on the step grid.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from meshes.tomlspec import DefinitionError, Table, plain_value, read_toml, resolve_definition

from .dataset import other_separator_text, other_time_unit_text

if TYPE_CHECKING:   # for annotations only: a scenario is read without its machine
    from .machine_definition import MachineDefinition

SCENARIOS_DIR = Path(__file__).resolve().parents[2] / "scenarios"
#: The shipped machines, ``meshes.definition.MACHINES_DIR`` (that module loads pyvista; reading a scenario must not).
MACHINES_DIR = Path(__file__).resolve().parents[2] / "meshes" / "machines"
HOUR = 3600.0
#: Ambient temperatures (°C) accepted as plausible for a machine-tool room (the FMU's input range too).
AMBIENT_RANGE_C = (-50.0, 100.0)
ABSOLUTE_ZERO_C = -273.15
#: Bytes per sample and per integration step of a run (time axis, recorded channels and conditions,
#: dataset and CSV copies; step inputs and their quadrature), used to refuse a scenario up front.
BYTES_PER_SAMPLE = 8 * 64 * 4
BYTES_PER_STEP = 8 * 16 * 6
#: An ambient CSV's time column short of the scenario is said to look like minutes (hours) when, read so, it
#: would cover the scenario up to this many times over; a file in s that is short, but not 8× short, is just
#: short (a file 0 … 72000 s under a 24 h scenario is not a 50-day record in minutes).
UNIT_GUESS_MAX_COVER = 8.0
#: An ambient CSV of more than COARSE_LOG_READINGS readings, fewer than 2 of which fall within the scenario's
#: 0 … duration, while its times divided by 1000 would put 2 or more inside and still reach the end, and whose
#: median step is longer than MS_LOG_STEP_S[0] read in s (no one logs a room's air less than daily: it has a day's
#: cycle) but at most MS_LOG_STEP_S[1] read in ms (a logger's), is refused as a log in ms under a header in s
#: (72 h of 10-min readings in ms: steps of 600000 "s", 1 reading in a 6 h ETVE, which the twin would replay as a
#: straight line). A longer log in s has many readings inside (a week of 1-min readings: 361 in 6 h); a short
#: hand-written profile, or a log really coarser than the scenario (daily readings for a year, hourly ones for a
#: month, under a 6 h run), is taken as written: between readings the twin interpolates, as it says. A log in ms
#: of one reading every 86.4 s or faster cannot be told from daily readings in s by its step and is taken as s.
COARSE_LOG_READINGS = 10
MS_LOG_STEP_S = (86400.0, 600.0)
TOP_KEYS = {"scenario", "initial", "ambient", "segments", "events", "noise", "outputs", "iso230_3"}


def _duration_s(t: Table, required=True, prefix="duration", strict=True):
    """Read one of ``<prefix>_s``, ``<prefix>_min`` or ``<prefix>_h`` (exactly one) in seconds (> 0, or ≥ 0)."""
    given = [(k, f) for k, f in ((f"{prefix}_s", 1.0), (f"{prefix}_min", 60.0), (f"{prefix}_h", HOUR)) if k in t]
    if len(given) > 1:
        raise t.error(given[1][0], f"conflicts with {given[0][0]}: give one of {prefix}_s/_min/_h")
    if not given:
        if required:
            raise t.error(f"{prefix}_min", "is required (or _s / _h)")
        return None
    key, factor = given[0]
    return t.number(key, minimum=0.0, strict_minimum=strict) * factor


@dataclass(frozen=True)
class Segment:
    """Constant spindle speed (rpm) and axis feeds (mm/min) over [start_s, end_s)."""

    start_s: float
    end_s: float
    spindle_rpm: float
    feed_mm_min: tuple = (0.0, 0.0, 0.0)
    origin: str = field(default="", compare=False)   # where it was written, e.g. "segments[2].steps[1]"


@dataclass(frozen=True)
class DoorOpening:
    """Ambient drop in some zones: a linear fall of ``drop_K`` over the opening, then exponential recovery."""

    start_s: float
    duration_s: float
    drop_K: float
    recovery_s: float
    zones: tuple | None

    def offset(self, t: np.ndarray) -> np.ndarray:
        """The change of the ambient the opening causes.

        Parameters
        ----------
        t : ndarray
            Times, s.

        Returns
        -------
        ndarray
            Offset, K (≤ 0), same shape as ``t``.
        """
        t = np.asarray(t, float)
        s = t - self.start_s
        falling = np.clip(s / self.duration_s, 0.0, 1.0) * self.drop_K
        after = np.exp(-np.clip(s - self.duration_s, 0.0, None) / self.recovery_s)
        return -np.where(s <= self.duration_s, falling, self.drop_K * after) * (s > 0)

    def reaches(self, zone: str, lagged: bool = False) -> bool:
        """Whether the opening changes the air of a zone.

        Parameters
        ----------
        zone : str
            A convection zone of the machine.
        lagged : bool
            The zone sees the room through a lag (an enclosure), so an opening that reaches the room reaches it.

        Returns
        -------
        bool
            True for an opening without ``zones``, or one naming the zone (or the room, for a lagged zone).
        """
        return self.zones is None or zone in self.zones or (lagged and "room" in self.zones)


@dataclass
class Ambient:
    """The room temperature (°C) as a function of time, plus a vertical gradient (K/m)."""

    kind: str
    params: dict
    gradient_K_per_m: float = 0.0

    def __call__(self, t):
        t = np.asarray(t, float)
        p = self.params
        if self.kind == "constant":
            base = np.full(t.shape, p["temperature_C"])
        elif self.kind == "sinusoid":
            clock = p["start_clock_h"] * HOUR + t
            base = p["mean_C"] + p["amplitude_K"] * np.cos(2 * np.pi * (clock - p["peak_clock_h"] * HOUR)
                                                          / (p["period_h"] * HOUR))
        else:  # piecewise or csv: linear interpolation, held beyond the ends
            base = np.interp(t, p["times_s"], p["values_C"])
        if p.get("hvac_amplitude_K"):
            base = base + p["hvac_amplitude_K"] * np.sin(2 * np.pi * t / (p["hvac_period_min"] * 60.0))
        return base


@dataclass
class Scenario:
    """A validated scenario; :meth:`conditions` evaluates it on a time grid."""

    name: str
    description: str
    source: str
    machine: str
    duration_s: float
    sample_interval_s: float
    time_step_s: float
    theta: float
    segments: list
    ambient: Ambient
    events: list
    initial: dict
    noise: dict
    seed: int
    record_camera: bool = False
    field_times_s: list = field(default_factory=list)
    camera_image_times_s: list = field(default_factory=list)
    iso_test: str | None = None
    machine_as_written: str = ""

    def times(self) -> np.ndarray:
        """The output (sampling) times.

        Returns
        -------
        ndarray
            From 0 to the duration inclusive, s.
        """
        n = int(round(self.duration_s / self.sample_interval_s))
        return np.arange(n + 1) * self.sample_interval_s

    def breakpoints_s(self, lags_s: dict[str, float] | None = None) -> np.ndarray:
        """Times where the conditions jump or kink between samples, for exact step means.

        Segment ends (speeds and feeds jump), the knots of a piecewise or CSV
        ambient, the start and end of a door's fall, and the grid on which a
        lagged zone's air is computed.

        Parameters
        ----------
        lags_s : dict of str to float, optional
            Zone → air lag, s.

        Returns
        -------
        ndarray
            Sorted unique times, s.
        """
        cuts = [[s.start_s for s in self.segments], [s.end_s for s in self.segments]]
        if self.ambient.kind in ("piecewise", "csv"):
            cuts.append(self.ambient.params["times_s"])
        cuts += [[ev.start_s, ev.start_s + ev.duration_s] for ev in self.events]
        for tau in set((lags_s or {}).values()):
            if tau > 0:
                step = lag_step_s(tau)
                cuts.append(np.arange(0.0, self.duration_s + step, step))
        return np.unique(np.concatenate([np.asarray(c, float).ravel() for c in cuts]))

    def operating(self, t: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Spindle speed and feeds at some times (left limits at segment ends; 0 after the cycle).

        Parameters
        ----------
        t : ndarray
            Times, s.

        Returns
        -------
        spindle_rpm : ndarray
            Spindle speed, rpm.
        feed_mm_min : dict of str to ndarray
            Axis (``x``, ``y``, ``z``) → feed, mm/min.
        """
        t = np.atleast_1d(np.asarray(t, float))
        if not self.segments:
            return np.zeros(t.shape), {a: np.zeros(t.shape) for a in "xyz"}
        ends = np.array([s.end_s for s in self.segments])
        # Left limit at a step end; t = 0 (before the test starts) takes the first segment.
        k = np.where(t <= 0, 0, np.searchsorted(ends, t, side="left"))
        inside = k < len(self.segments)
        k = np.minimum(k, len(self.segments) - 1)
        rpm = np.where(inside, np.array([s.spindle_rpm for s in self.segments])[k], 0.0)
        feed = np.array([s.feed_mm_min for s in self.segments])
        feeds = {a: np.where(inside, feed[k, i], 0.0) for i, a in enumerate("xyz")}
        return rpm, feeds

    def idle_start(self, ambient_C: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray],
                                                                     dict[str, np.ndarray]]:
        """The conditions a steady initial state is computed for.

        The machine stands idle before the test unless ``[initial]`` names a
        ``spindle_rpm``; the feeds are zero; the air is the scenario's at the
        start unless ``[initial]`` names an ``ambient_C``.

        Parameters
        ----------
        ambient_C : dict of str to ndarray, shape (1,)
            Zone → the scenario's ambient at the start, °C.

        Returns
        -------
        spindle_rpm : ndarray, shape (1,)
            Spindle speed, rpm.
        feed_mm_min : dict of str to ndarray, shape (1,)
            Axis → feed, mm/min (zero).
        ambient_C : dict of str to ndarray, shape (1,)
            Zone → ambient, °C.
        """
        named = self.initial.get("ambient_C")
        ambient = ambient_C if named is None else {z: np.array([named]) for z in ambient_C}
        return np.array([self.initial.get("spindle_rpm") or 0.0]), {a: np.zeros(1) for a in "xyz"}, ambient

    def zone_ambient(self, t: np.ndarray, zones: list[str],
                     lags_s: dict[str, float] | None = None) -> dict[str, np.ndarray]:
        """The ambient of each zone at some times.

        A zone sees the room plus the events that reach it.  A zone with a
        lag (e.g. the air inside a machine enclosure) sees the room and the
        room's events through a first-order lag, starting in equilibrium at t = 0.

        Parameters
        ----------
        t : ndarray
            Times, s.
        zones : list of str
            The machine's convection zones.
        lags_s : dict of str to float, optional
            Zone → air lag, s.

        Returns
        -------
        dict of str to ndarray
            Zone → ambient, °C.
        """
        t = np.atleast_1d(np.asarray(t, float))
        lags_s = lags_s or {}
        out = {}
        for zone in zones:
            tau = lags_s.get(zone, 0.0)

            def raw(x, zone=zone, lagged=tau > 0):
                value = self.ambient(x)
                for ev in self.events:
                    if ev.reaches(zone, lagged):
                        value = value + ev.offset(x)
                return value

            out[zone] = first_order_lag(raw, t, tau) if tau > 0 else raw(t)
        return out

    def machine_definition(self) -> MachineDefinition:
        """The definition of the machine the scenario names (``[scenario] machine``), read.

        The field is a default that ``--machine`` replaces, so it is checked
        here, where it is used, not when the scenario is read.

        Returns
        -------
        MachineDefinition
            The machine.

        Raises
        ------
        DefinitionError
            Naming the scenario file, ``scenario.machine`` and the value: an unknown name (with the shipped
            machines) or a missing file (with the path it was looked for at); or the machine file's own error.
        """
        from .machine_definition import load_machine  # a scenario is read without its machine

        written = self.machine_as_written or self.machine
        problem = _unknown_machine(self.source, written, self.machine)
        if problem:
            raise DefinitionError(f"{self.source}: scenario.machine {problem}, got {written!r}")
        return load_machine(self.machine)

    def check_machine(self, definition: MachineDefinition) -> None:
        """Validate the scenario against a machine: speeds and feeds within limits, event zones known, air plausible.

        The air check is :meth:`check_air`.

        Parameters
        ----------
        definition : MachineDefinition
            The machine it runs on.

        Raises
        ------
        DefinitionError
            Naming the scenario file, the segment or event and the machine's limit; or, from
            :meth:`check_air`, the event or gradient that takes the air out of range.
        """
        for i, s in enumerate(self.segments):
            where = s.origin or f"segment {i}"
            if s.spindle_rpm > definition.max_spindle_rpm:
                raise DefinitionError(f"{self.source}: {where}.spindle_rpm {s.spindle_rpm:g} exceeds the "
                                      f"maximum of machine {definition.name!r} ({definition.max_spindle_rpm:g} rpm)")
            for axis, f in zip("xyz", s.feed_mm_min):
                if abs(f) > definition.max_feed_mm_min:
                    raise DefinitionError(f"{self.source}: {where}.feed_{axis}_mm_min {f:g} exceeds the maximum "
                                          f"of machine {definition.name!r} ({definition.max_feed_mm_min:g} mm/min)")
        for i, ev in enumerate(self.events):
            for zone in ev.zones or ():
                if zone not in definition.zones:
                    raise DefinitionError(f"{self.source}: events[{i}].zones names an unknown zone {zone!r}; "
                                          f"zones of {definition.name!r}: {definition.zones}")
        self.check_air(definition)

    def check_air(self, definition: MachineDefinition) -> None:
        """Refuse a scenario whose air, as a run on the machine applies it, leaves :data:`AMBIENT_RANGE_C`.

        Reading a scenario checks the room ambient alone.  The door openings
        (which may overlap) and the vertical gradient need the machine: its
        zones, their lags, and the heights its convecting parts and air
        sensors span.  Each zone's air is taken as the run computes it
        (:meth:`zone_ambient`) at the sample times and the breakpoints (a
        door's deepest point is one), plus g·(z − z_ref) at the zone's lowest
        and highest point (linear in z, so those are its extremes); a steady
        start with ``[initial] ambient_C`` adds the gradient to that too.

        Parameters
        ----------
        definition : MachineDefinition
            The machine it runs on.

        Raises
        ------
        DefinitionError
            One line (:func:`check_ambient_C`): the scenario file, the field that pushes the coldest (or
            warmest) air furthest (``events[i].drop_K`` or ``ambient.vertical_gradient_K_per_m``) and its
            value, then the zone, height (m) and time (h) of that air and its temperature (°C).
        """
        places = self._air_extremes(definition)
        coldest = min(places, key=lambda place: place[0])
        warmest = max(places, key=lambda place: place[0])
        check_ambient_C([coldest[0], warmest[0]], self.source,
                        lambda i: self._air_culprit(definition, (coldest, warmest)[i], (-1.0, 1.0)[i]))

    def _air_extremes(self, definition: MachineDefinition) -> list[tuple]:
        """(°C, zone, height in m or None, time in s or None for the steady start) of each zone's extreme air."""
        lags = definition.zone_lags_s
        t = np.union1d(self.times(), self.breakpoints_s(lags))
        g, ref = self.ambient.gradient_K_per_m, definition.ambient_reference_height_m
        heights = _zone_heights(definition) if g else {}     # without a gradient the height does not matter
        steady = self.initial.get("ambient_C")
        places = []
        for zone, air in self.zone_ambient(t, definition.zones, lags).items():
            for z in heights.get(zone, (None,)):
                shift = 0.0 if z is None else g * (z - ref)
                values = air + shift
                places += [(float(values[k]), zone, z, float(t[k])) for k in (np.argmin(values), np.argmax(values))]
                if steady is not None:
                    places.append((steady + shift, zone, z, None))
        return places

    def _air_culprit(self, definition: MachineDefinition, place: tuple, sign: float) -> str:
        """``: field = value (zone, height, time)``: what moves the air at ``place`` furthest towards ``sign``.

        The room ambient (with its HVAC ripple) was checked on reading, so the
        field is a door opening reaching the zone or the gradient at that
        height, whichever pushes the air most towards −1 (colder) or +1 (warmer).
        """
        _, zone, z, t = place
        g = self.ambient.gradient_K_per_m
        lagged = definition.zone_lags_s.get(zone, 0.0) > 0
        pushes = {f"events[{i}].drop_K": (float(ev.offset(t)), ev.drop_K)
                  for i, ev in enumerate(self.events) if t is not None and ev.reaches(zone, lagged)}
        pushes["ambient.vertical_gradient_K_per_m"] = (0.0 if z is None else
                                                       g * (z - definition.ambient_reference_height_m), g)
        name = max(pushes, key=lambda key: sign * pushes[key][0])
        at = ([] if z is None else [f"z = {z:.3g} m"]) + (["the steady start"] if t is None else
                                                          [f"t = {t / HOUR:.4g} h"])
        return f": {name} = {pushes[name][1]:g} (zone {zone!r} air at {', '.join(at)})"


def first_order_lag(signal: Callable[[np.ndarray], np.ndarray], t: np.ndarray, tau_s: float) -> np.ndarray:
    """Response of ``dy/dt = (signal − y)/τ`` with y(0) = signal(0).

    Integrated exactly for a signal that is linear between the points of a
    fine grid (step ≤ τ/20 and ≤ 60 s).

    Parameters
    ----------
    signal : callable
        ``signal(times_s)`` → values (e.g. °C).
    t : ndarray
        Times of the response, s.
    tau_s : float
        Time constant, s.

    Returns
    -------
    ndarray
        The response at ``t``, in the signal's unit.
    """
    t = np.asarray(t, float)
    end = max(float(t.max()), 0.0)
    dt = lag_step_s(tau_s)
    grid = np.arange(0.0, end + dt, dt)
    x = signal(grid)
    a = np.exp(-dt / tau_s)
    slope = np.diff(x) / dt
    y = np.empty_like(x)
    y[0] = x[0]
    for k in range(len(slope)):
        y[k + 1] = x[k + 1] - slope[k] * tau_s + (y[k] - x[k] + slope[k] * tau_s) * a
    return np.interp(t, grid, y)


def lag_step_s(tau_s: float) -> float:
    """The grid step on which :func:`first_order_lag` integrates a lag.

    Parameters
    ----------
    tau_s : float
        Time constant, s.

    Returns
    -------
    float
        τ/20, at most 60 s.
    """
    return min(tau_s / 20.0, 60.0)


def _zone_heights(definition: MachineDefinition) -> dict[str, tuple[float, float]]:
    """The lowest and highest air of each zone: its convecting parts' extents and its air sensors.

    A part counts with its whole height even when its rule takes only some of
    its faces (``facing``): the extremes may be a little wide, never narrow.

    Parameters
    ----------
    definition : MachineDefinition
        The machine.

    Returns
    -------
    dict of str to (float, float)
        Zone → (lowest, highest) z, m.
    """
    size = definition.geometry.mesh_size_m
    used = {name for rule in definition.convection for name in rule.parts}
    extent = {p.name: p.shape.surface(size).bounds[4:6] for p in definition.geometry.parts if p.name in used}
    heights = {}
    for rule in definition.convection:
        for name in rule.parts:
            heights.setdefault(rule.zone, []).extend(float(z) for z in extent[name])
    for sensor in definition.sensors:
        if sensor.kind == "air":
            heights.setdefault(sensor.zone, []).append(float(sensor.position[2]))
    return {zone: (min(zs), max(zs)) for zone, zs in heights.items()}


def check_ambient_C(values: float | np.ndarray, where: str, hint: str | Callable[[int], str] = "") -> None:
    """Refuse a temperature that is not a plausible room ambient (:data:`AMBIENT_RANGE_C`).

    Parameters
    ----------
    values : float or ndarray
        Temperatures, °C.
    where : str
        The file and field, starting the message.
    hint : str or callable
        Where in it (e.g. a row); a callable gets the index of the first bad value.

    Raises
    ------
    DefinitionError
        The first bad value, saying when it looks like kelvin.
    """
    values = np.atleast_1d(np.asarray(values, float))
    low, high = AMBIENT_RANGE_C
    bad = np.flatnonzero((values < low) | (values > high))
    if not len(bad):
        return
    value = float(values[bad[0]])
    at = hint(int(bad[0])) if callable(hint) else hint
    if value <= ABSOLUTE_ZERO_C:
        why = f"is at or below absolute zero ({ABSOLUTE_ZERO_C} °C)"
    elif 200.0 <= value <= 400.0:
        why = (f"is not a plausible ambient in °C ({low:g} to {high:g} °C); it looks like kelvin: "
               f"give °C (K − 273.15, here {value - 273.15:.2f} °C)")
    else:
        why = f"is not a plausible ambient in °C ({low:g} to {high:g} °C)"
    raise DefinitionError(f"{where}{at}: {value:g} {why}")


def scenario_path(scenario: str | Path) -> Path:
    """The TOML file of a scenario.

    Parameters
    ----------
    scenario : str or Path
        A shipped scenario's name (``heat_cool_9000``) or a path.

    Returns
    -------
    Path
        The scenario file.
    """
    return resolve_definition(scenario, SCENARIOS_DIR, "scenario")


def _segments(root: Table):
    segments, t = [], 0.0
    for seg in root.tables("segments"):
        seg.check_keys({"duration_s", "duration_min", "duration_h", "spindle_rpm", "feed_mm_min", "feed_x_mm_min",
                        "feed_y_mm_min", "feed_z_mm_min", "repeat", "steps", "label"})
        if "steps" in seg:
            extra = sorted(set(seg.keys()) - {"repeat", "steps", "label"})
            if extra:
                raise seg.error(extra[0], "cannot be combined with steps (give it inside each step)")
            repeat = seg.integer("repeat", 1, minimum=1)
            steps = seg.tables("steps", required=True)
            if not steps:
                raise seg.error("steps", "must list at least one step", [])
            block = [(_one_segment(s), s.path) for s in steps]
            for _ in range(repeat):
                for (length, rpm, feed), origin in block:
                    segments.append(Segment(t, t + length, rpm, feed, origin))
                    t += length
        else:
            if "repeat" in seg:
                raise seg.error("repeat", "needs steps = [...] to repeat")
            length, rpm, feed = _one_segment(seg)
            segments.append(Segment(t, t + length, rpm, feed, seg.path))
            t += length
    return segments, t


def _one_segment(seg: Table):
    seg.check_keys({"duration_s", "duration_min", "duration_h", "spindle_rpm", "feed_mm_min", "feed_x_mm_min",
                    "feed_y_mm_min", "feed_z_mm_min", "label"})
    length = _duration_s(seg)
    rpm = seg.number("spindle_rpm", 0.0, minimum=0.0)
    common = seg.number("feed_mm_min", 0.0, minimum=0.0)
    feed = tuple(seg.number(f"feed_{a}_mm_min", common, minimum=0.0) for a in "xyz")
    return length, rpm, feed


def _ambient(root: Table, base_dir: Path, duration_s: float):
    """``[ambient]`` of a scenario of ``duration_s`` s (a CSV must cover it), its file in ``base_dir``."""
    a = root.table("ambient")
    kind = a.string("kind", "constant", choices={"constant", "sinusoid", "piecewise", "csv"})
    common = {"kind", "vertical_gradient_K_per_m", "hvac_amplitude_K", "hvac_period_min"}
    params = {"hvac_amplitude_K": a.number("hvac_amplitude_K", 0.0, minimum=0.0),
              "hvac_period_min": a.number("hvac_period_min", 30.0, minimum=0.0, strict_minimum=True)}
    swing = params["hvac_amplitude_K"]
    if kind == "constant":
        a.check_keys(common | {"temperature_C"})
        params["temperature_C"] = a.number("temperature_C", 20.0)
        _check_with_ripple(np.array([params["temperature_C"]]), swing, a.where("temperature_C"), lambda i: "")
    elif kind == "sinusoid":
        a.check_keys(common | {"mean_C", "amplitude_K", "period_h", "peak_clock_h", "start_clock_h"})
        params.update(mean_C=a.number("mean_C", 20.0), amplitude_K=a.number("amplitude_K", minimum=0.0),
                      period_h=a.number("period_h", 24.0, minimum=0.0, strict_minimum=True),
                      peak_clock_h=a.number("peak_clock_h", 17.0), start_clock_h=a.number("start_clock_h", 0.0))
        reach = params["amplitude_K"] + swing
        check_ambient_C(params["mean_C"] + np.array([-reach, reach]), a.where("mean_C"), " ± amplitude")
    elif kind == "piecewise":
        a.check_keys(common | {"times_h", "values_C"})
        times = np.asarray(a.vector("times_h")) * HOUR
        values = np.asarray(a.vector("values_C"))
        if len(times) != len(values) or len(times) == 0:
            raise a.error("values_C", f"must have one value per time ({len(times)})", list(values))
        if np.any(np.diff(times) <= 0):
            raise a.error("times_h", "must increase strictly", list(times / HOUR))
        _check_with_ripple(values, swing, a.where("values_C"), lambda i: f"[{i}]")
        params.update(times_s=times, values_C=values)
    else:
        a.check_keys(common | {"file", "time_column", "value_column"})
        params.update(_ambient_csv(a, base_dir, swing, duration_s))
    return Ambient(kind, params, a.number("vertical_gradient_K_per_m", 0.0))


def _check_with_ripple(values: np.ndarray, swing: float, where: str, hint: Callable[[int], str]) -> None:
    """:func:`check_ambient_C` of ambient values (°C) widened by ± the HVAC ripple's amplitude ``swing`` (K)."""
    n = len(values)
    suffix = " (with the HVAC ripple)" if swing else ""
    check_ambient_C(np.concatenate([values - swing, values + swing]), where, lambda i: hint(i % n) + suffix)


def _ambient_csv(a: Table, base_dir: Path, swing: float, duration_s: float):
    """Times (s) and temperatures (°C) of an ambient CSV, checked: numbers, strictly increasing times, plausible
    temperatures (widened by the HVAC ripple ``swing``, K), and times covering the scenario's ``duration_s`` s."""
    import pandas as pd

    path = Path(a.string("file"))
    path = path if path.is_absolute() else base_dir / path
    time_col = a.string("time_column", "time_s")
    _refuse_other_time_unit(a, time_col)
    value_col = a.string("value_column", "ambient_degC")
    if not path.exists():
        raise a.error("file", "names a file that does not exist", str(path))
    try:
        frame = pd.read_csv(path)
    except (OSError, ValueError) as exc:  # pandas' ParserError, EmptyDataError and UnicodeDecodeError are ValueErrors
        raise a.error("file", f"could not be read as CSV ({exc})", str(path)) from None
    for col in (time_col, value_col):
        if col not in frame.columns:
            raise DefinitionError(f"{a.where('file')} {path}: no column {col!r}; "
                                  f"{other_separator_text(list(frame.columns)) or f'columns: {list(frame.columns)}'}")
    t = pd.to_numeric(frame[time_col], errors="coerce").to_numpy(float)
    v = pd.to_numeric(frame[value_col], errors="coerce").to_numpy(float)
    if len(t) == 0:
        raise DefinitionError(f"{a.where('file')} {path}: no data rows")
    if not (np.isfinite(t).all() and np.isfinite(v).all()):
        row = int(np.flatnonzero(~(np.isfinite(t) & np.isfinite(v)))[0])
        raise DefinitionError(f"{a.where('file')} {path}: row {row + 2}: {time_col}/{value_col} is empty or not "
                              f"a number, got {plain_value(frame[time_col].iloc[row])!r}, "
                              f"{plain_value(frame[value_col].iloc[row])!r}")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise DefinitionError(f"{a.where('file')} {path}: column {time_col!r} must increase strictly: "
                              f"row {k + 3} has {t[k + 1]:g} after {t[k]:g}")
    _check_with_ripple(v, swing, f"{a.where('file')} {path}", lambda i: f": column {value_col!r}, row {i + 2}")
    _check_covers(f"{a.where('file')} {path}", time_col, t, duration_s)
    _check_readings_inside(f"{a.where('file')} {path}", time_col, t, duration_s)
    return {"times_s": t, "values_C": v}


def _refuse_other_time_unit(a: Table, column: str) -> None:
    """Refuse a ``time_column`` whose header names another unit than s, as a measured CSV's is
    (:func:`~twin.core.dataset.other_time_unit_text`): :func:`_check_covers` catches a file in hours or minutes only
    when its span falls short of the scenario."""
    text = other_time_unit_text(column)
    if text is not None:
        raise a.error("time_column", f"names a column whose header {text}", column)


def _check_covers(where: str, column: str, t: np.ndarray, duration_s: float) -> None:
    """Refuse an ambient CSV whose times ``t`` (s, increasing) do not reach from the scenario's start (0 s) to its
    end (``duration_s``, s).

    Beyond the file's ends the twin holds its first and last readings, so a day logged in minutes or hours under
    a header in s (0 … 1440, 0 … 24), or timed from another origin (clock times), would have been read as a room
    at one temperature.  The end is checked first: a short file's span tells its unit, whatever its origin.
    """
    if t[-1] < duration_s:
        cover = (t[-1] - t[0]) / duration_s
        guess = next((f"the times look like {unit}: write them in s (× {factor:g})"
                      for factor, unit in ((60.0, "minutes"), (HOUR, "hours"))
                      if 1.0 <= cover * factor <= UNIT_GUESS_MAX_COVER),
                     f"past {t[-1]:g} s the twin would hold the last reading: give readings up to {duration_s:g} s")
        raise DefinitionError(f"{where}: column {column!r} spans {t[0]:g} … {t[-1]:g} s, short of the scenario's "
                              f"{duration_s:g} s ({duration_s / HOUR:g} h): {guess}")
    if t[0] > 0.0:
        raise DefinitionError(f"{where}: column {column!r} starts at {t[0]:g} s, after the scenario's start (0 s), "
                              "and before it the twin would hold the first reading: the times count from the "
                              f"scenario's start; subtract {t[0]:g} s (clock times?) or add a reading at 0 s")


def _check_readings_inside(where: str, column: str, t: np.ndarray, duration_s: float) -> None:
    """Refuse an ambient log of many readings (over :data:`COARSE_LOG_READINGS`) that, covering the scenario
    (:func:`_check_covers`), has fewer than 2 of its times ``t`` (s, increasing) within 0 … ``duration_s`` s, when
    the same times in ms would put 2 or more inside and reach the scenario's end, and its median step is more than
    a day in s but a logger's in ms (:data:`MS_LOG_STEP_S`): the scenario would see a straight line between two
    readings of a log in ms."""
    def inside(times):
        return int(np.count_nonzero((times >= 0.0) & (times <= duration_s)))

    in_ms = t * 1e-3
    if inside(t) >= 2 or len(t) <= COARSE_LOG_READINGS or in_ms[-1] < duration_s or inside(in_ms) < 2:
        return
    step_s = float(np.median(np.diff(t)))
    if not MS_LOG_STEP_S[0] < step_s <= MS_LOG_STEP_S[1] * 1e3:   # a coarse log in s: taken as written
        return
    raise DefinitionError(f"{where}: column {column!r} has {inside(t)} of its {len(t)} readings within the "
                          f"scenario's 0 … {duration_s:g} s ({duration_s / HOUR:g} h), readings {step_s:g} s "
                          f"apart (over a day; {step_s * 1e-3:g} s if they are ms), and the twin would replay a "
                          "straight line between two of them: the times look like ms: write them in s (× 1e-3)")


def _memory_limit_bytes():
    """Half the physical memory (8 GB when the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (AttributeError, ValueError, OSError):
        return 8 * 2**30


def _check_size(head: Table, duration, sample, step):
    """Refuse, before any array is made, a scenario whose run would not fit in memory."""
    samples = int(round(duration / sample)) + 1
    steps = int(np.ceil(duration / step - 1e-9))
    need = samples * BYTES_PER_SAMPLE + steps * BYTES_PER_STEP
    limit = _memory_limit_bytes()
    if need > limit:
        raise head.error("sample_interval_s", f"gives {samples:,} samples and {steps:,} integration steps over "
                         f"{duration / HOUR / 24:,.1f} days; a run would need about {need / 2**30:,.0f} GB of "
                         f"memory, more than the {limit / 2**30:,.0f} GB it may use here: sample less often "
                         f"(and raise time_step_s) or split the scenario", sample)


def load_scenario(scenario: str | Path) -> Scenario:
    """Read and validate a scenario.

    Parameters
    ----------
    scenario : str or Path
        Name of a shipped scenario (``iso230_3_spindle_short``) or path of a scenario TOML file.

    Returns
    -------
    Scenario
        The validated scenario; times in s, temperatures in °C.

    Raises
    ------
    DefinitionError
        One line naming the file, the field and the bad value.
    """
    path = scenario_path(scenario)
    root = read_toml(path)
    root.check_keys(TOP_KEYS)
    head = root.table("scenario")
    head.check_keys({"name", "description", "machine", "duration_s", "duration_min", "duration_h",
                     "sample_interval_s", "time_step_s", "scheme", "seed"})
    segments, cycle_end = _segments(root)
    duration, sample, step = _time_grid(head, cycle_end)
    scheme = head.string("scheme", "backward_euler", choices={"backward_euler", "crank_nicolson"})
    events = [_door_opening(ev, duration) for ev in root.tables("events")]
    initial = _initial(root.table("initial"))
    noise_spec = _noise(root.table("noise"))
    out = root.table("outputs")
    out.check_keys({"camera", "fields_at_h", "camera_images_at_h"})
    iso = root.table("iso230_3")
    iso.check_keys({"test"})
    machine = head.string("machine", "vmc_ram")
    return Scenario(
        name=head.string("name", path.stem),
        description=head.string("description", ""),
        source=str(path),
        machine=_machine_reference(machine, path.parent),
        machine_as_written=machine,
        duration_s=duration,
        sample_interval_s=sample,
        time_step_s=step,
        theta=1.0 if scheme == "backward_euler" else 0.5,
        segments=segments,
        ambient=_ambient(root, path.parent, duration),
        events=events,
        initial=initial,
        noise=noise_spec,
        seed=head.integer("seed", 0, minimum=0),
        record_camera=out.boolean("camera", False),
        field_times_s=_times_h(out, "fields_at_h", duration),
        camera_image_times_s=_times_h(out, "camera_images_at_h", duration),
        iso_test=iso.string("test", None, choices={"spindle", "etve"}) if "test" in iso else None,
    )


def _machine_reference(value: str, base_dir: Path) -> str:
    """``[scenario] machine``: a shipped machine's name, or the path of a machine file (not read here).

    A value ending in ``.toml`` or holding a path separator is a path and, as
    ``ambient.file``, a relative one is read from the scenario file's folder
    (``base_dir``), whatever the current folder; anything else is a name.  It
    is only a default (``--machine`` replaces it), so it is checked when it is
    used (:meth:`Scenario.machine_definition`).

    Returns
    -------
    str
        The name, or the absolute path of the file.
    """
    if value.endswith(".toml") or "/" in value or os.sep in value:
        return str((base_dir / value).resolve())       # an absolute value stays itself
    return value


def _unknown_machine(source: str, written: str, machine: str) -> str | None:
    """Why the machine a scenario names (``written`` in ``source``, resolved to ``machine``) cannot be read, or
    None: an unknown name (with the shipped machines) or a missing file (with where it was looked for)."""
    if Path(machine).is_absolute():
        if Path(machine).is_file():
            return None
        return (f"names a machine file that does not exist: {machine} (a relative path is read from the scenario "
                f"file's folder{_moved_hint(written, Path(source).parent)})")
    try:
        resolve_definition(machine, MACHINES_DIR, "machine")
    except DefinitionError:
        known = sorted(p.stem for p in MACHINES_DIR.glob("*.toml"))
        return f"names an unknown machine {machine!r}; available: {known} (or the path of a machine .toml file)"
    return None


def _moved_hint(value: str, base_dir: Path) -> str:
    """How to write a machine path that was read from the current folder before paths became scenario-relative."""
    old = Path(value)
    if old.is_absolute() or not old.is_file():
        return ""
    fixed = Path(os.path.relpath(old.resolve(), base_dir.resolve())).as_posix()
    return f"; {value} is found from the current folder: write {fixed!r}"


def _time_grid(head: Table, cycle_end: float):
    """(duration, sample interval, integration step) in s from ``[scenario]``, checked against each other."""
    duration = _duration_s(head, required=False) or cycle_end
    if not duration:
        raise head.error("duration_h", "is required when there are no segments")
    if cycle_end > duration * (1 + 1e-12):
        raise head.error("duration_h", f"is shorter than the segments ({cycle_end / HOUR:g} h)", duration / HOUR)
    sample = head.number("sample_interval_s", 60.0, minimum=0.0, strict_minimum=True)
    if sample > duration:
        raise head.error("sample_interval_s", f"exceeds the duration ({duration:g} s)", sample)
    n_samples = duration / sample
    if abs(n_samples - round(n_samples)) > 1e-6 * max(1.0, n_samples):
        raise head.error("sample_interval_s", f"must divide the duration ({duration:g} s) into whole samples",
                         sample)
    step = head.number("time_step_s", min(sample, 60.0), minimum=0.0, strict_minimum=True)
    _check_size(head, duration, sample, min(step, sample))
    return duration, sample, min(step, sample)


def _door_opening(ev: Table, duration: float):
    """One ``[[events]]`` entry (a door opening) within a scenario of ``duration`` s."""
    ev.check_keys({"kind", "start_s", "start_min", "start_h", "duration_s", "duration_min", "duration_h",
                   "drop_K", "recovery_h", "zones"})
    ev.string("kind", choices={"door_opening"})
    start = _duration_s(ev, required=False, prefix="start", strict=False) or 0.0
    if start >= duration:
        key = next(k for k in ("start_s", "start_min", "start_h") if k in ev)
        raise ev.error(key, f"is not within the scenario (0–{duration / HOUR:g} h)", ev.raw(key))
    return DoorOpening(start, _duration_s(ev),
                       ev.number("drop_K"), ev.number("recovery_h", 1.0, minimum=0.0, strict_minimum=True) * HOUR,
                       tuple(ev.strings("zones")) if "zones" in ev else None)


def _initial(init: Table):
    """The ``[initial]`` state: uniform temperature (°C) or steady state at a speed (rpm) and ambient (°C)."""
    initial = {"kind": init.string("kind", "uniform", choices={"uniform", "steady"})}
    if initial["kind"] == "uniform":
        init.check_keys({"kind", "temperature_C"})
        initial["temperature_C"] = init.number("temperature_C", None)
    else:
        init.check_keys({"kind", "spindle_rpm", "ambient_C"})
        initial["spindle_rpm"] = init.number("spindle_rpm", None, minimum=0.0)
        initial["ambient_C"] = init.number("ambient_C", None)
    for key in ("temperature_C", "ambient_C"):
        if initial.get(key) is not None:
            check_ambient_C(initial[key], init.where(key))
    return initial


def _noise(noise: Table):
    """The ``[noise]`` table: sensor model name per channel kind (``none`` for exact values)."""
    noise.check_keys({"temperature", "displacement", "strain", "camera"})
    return {"temperature": noise.string("temperature", "none", choices={"none", "DS18S20"}),
            "displacement": noise.string("displacement", "none", choices={"none", "NCDT"}),
            "strain": noise.string("strain", "none", choices={"none", "FBG"}),
            "camera": noise.string("camera", "none", choices={"none", "S65"})}


def _times_h(out: Table, key: str, duration: float):
    """Times given in h under ``[outputs].key``, checked to lie in the scenario, as s."""
    values = out.vector(key, default=[])
    bad = [v for v in values if not 0 <= v * HOUR <= duration]
    if bad:
        raise out.error(key, f"must lie within the scenario (0–{duration / HOUR:g} h)", list(values))
    return [v * HOUR for v in values]


def available_scenarios() -> list[str]:
    """The shipped scenarios.

    Returns
    -------
    list of str
        Names of the TOML files in ``scenarios/``, sorted.
    """
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))
