"""``twin live --state FILE``: the observer's state kept in a file, and a restarted session that goes on from it.

A live twin restarted during a shift (a crash, a reboot, an update) would otherwise start again from the start
prior, whose past-unknown part gives a ±5 µm band on a warm machine for a while.  :class:`KeptObserver` wraps the
observer ``twin live`` runs: it writes the state (:func:`write_state`) every :data:`SAVE_EVERY_S` wall seconds and
when the session stops, and at the first sample of the next session goes on from it (:func:`resume`), the time
away bridged by the model with the inputs nobody read unknown (:meth:`~twin.live.observer.DriftObserver.bridge`).

The file is JSON: the machine time of the last sample fused (s after :data:`twin.live.replay.EPOCH`, and as UTC),
the last sample interval, what identifies the state space (:func:`model_identity`), the hypotheses' weights and
per hypothesis the filter's mean, covariance, last inputs and adaptive widening
(:class:`~twin.live.observer.FilterState`).  Floats are written as Python's shortest round-trip text, so a state
read back is the state written, bit for bit.  It is written to a hidden ``.<name>.partial`` beside it and renamed
over it (:func:`write_atomic`): a reader finds the previous complete state or the new one, never a half-written one.
"""
from __future__ import annotations

import hashlib
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ..core.files import write_text_atomic
from ..errors import TwinInputError
from .multiple_model import MultipleModelObserver
from .observer import DriftObserver, Estimate, FilterState, RecordRunner
from .replay import timestamp

log = logging.getLogger("thermal_twin")

FORMAT = "twin-live-state"
VERSION = 1
#: Wall seconds between two saves of the state while a session runs (besides the first state to keep and the one
#: when it stops): a crash loses at most this much of what the observer learnt, the resume bridges it like any time
#: away, and a save (0.7 MB of JSON for the shipped two hypotheses, ≈ 50 ms) every 30 s costs the session nothing.
SAVE_EVERY_S = 30.0
#: The longest time away a session resumes across, s: twice the disturbances' 4 h correlation time.  By then the
#: load read last is forgotten (e^(−2) of it left) and the unknown inputs' covariance has grown to 98 % of the
#: unknown-past prior's (1 − e^(−4)) (the structure's slowest modes still remember the saved heat, the inputs
#: driving them no longer do), and the start prior can still find the machine at rest (a night or a weekend
#: away), which a bridge cannot.
RESUME_HORIZON_S = 8 * 3600.0


def _members(observer):
    """The :class:`DriftObserver` of each hypothesis of ``observer``."""
    return observer.members if isinstance(observer, MultipleModelObserver) else [observer]


def _digest(*parts):
    """SHA-256 (16 hex) of arrays (their bytes) and JSON-serialisable values, in order."""
    h = hashlib.sha256()
    for part in parts:
        h.update(np.ascontiguousarray(part).tobytes() if isinstance(part, np.ndarray) else json.dumps(part).encode())
    return h.hexdigest()[:16]


def model_identity(observer: DriftObserver | MultipleModelObserver) -> dict:
    """What a state belongs to: the machine, its ROM, the thermometers and the state space of each hypothesis.

    ``machine_digest`` is the ROM's :func:`~twin.rom.reduction.machine_digest` (the machine's matrices: its mesh,
    materials, sources and outputs); ``rom_digest`` hashes the ROM's own arrays, so a ROM built again with other
    modal coordinates (a cache cleared, another library version) is another state space; ``state_layout`` the
    names of every disturbance and the sizes of each hypothesis's state.

    Parameters
    ----------
    observer : DriftObserver or MultipleModelObserver
        The observer.

    Returns
    -------
    dict
        Field → value, JSON-serialisable.
    """
    members = _members(observer)
    rom, model = members[0].rom, members[0].model
    return {"machine": rom.machine, "machine_digest": rom.digest, "rom_order": rom.order,
            "rom_digest": _digest(rom.eigenvalues, rom.input_matrix, rom.output_matrix, rom.feedthrough, rom.offset,
                                  rom.uniform_state, [rom.input_names, rom.output_names]),
            "thermometers": list(observer.thermometers), "sensors": list(model.sensors),
            "hypotheses_W": [m.model.noise.concentrated_W for m in members],
            "state_layout": _digest([[m.model.n, [d.name for d in m.model.disturbances], m.model.offsets]
                                     for m in members])}


# ----------------------------------------------------------------------------- writing
def write_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically and durably, its folder made if missing, after a Ctrl-C too
    (:func:`twin.core.files.write_text_atomic`): saving the state is part of stopping, not a result the Ctrl-C
    cancelled.

    Parameters
    ----------
    path : str or Path
        The file.
    text : str
        The content.

    Returns
    -------
    Path
        ``path``.
    """
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return write_text_atomic(path, text, after_interrupt=True)


def snapshot(observer: DriftObserver | MultipleModelObserver) -> tuple[list, np.ndarray]:
    """Copies of every hypothesis's :class:`~twin.live.observer.FilterState` (None before one is kept) and the
    weights, as they are now: what :func:`state_text` writes.

    Parameters
    ----------
    observer : DriftObserver or MultipleModelObserver
        The observer, between two samples (inside one its hypotheses may stand at different times).

    Returns
    -------
    tuple of (list, numpy.ndarray)
        The filter states and the (m,) weights.
    """
    return [m.state() for m in _members(observer)], np.array(getattr(observer, "weights", np.ones(1)), float)


def state_text(observer: DriftObserver | MultipleModelObserver, kept: tuple[list, np.ndarray] | None = None,
               identity: dict | None = None) -> str | None:
    """The state file's content for ``observer`` now, or for its :func:`snapshot` ``kept`` (see the module docstring).

    Parameters
    ----------
    observer : DriftObserver or MultipleModelObserver
        The observer.
    kept : tuple, optional
        A :func:`snapshot` of it, taken between two samples; default one taken now.
    identity : dict, optional
        Its :func:`model_identity`, constant for a session (a writer that saves often computes it once); default
        computed now.

    Returns
    -------
    str or None
        JSON; None when there is nothing to keep (:meth:`~twin.live.observer.DriftObserver.state`: before the first
        readings and a second sample), or a state that is not finite (a failed filter must not replace the last
        good state).
    """
    states, weights = snapshot(observer) if kept is None else kept
    if any(s is None or not (np.all(np.isfinite(s.mean)) and np.all(np.isfinite(s.covariance))) for s in states):
        return None
    t = states[0].time_s
    return json.dumps({
        "format": FORMAT, "version": VERSION, "saved_utc": timestamp(t).isoformat(), "time_s": t,
        "sample_interval_s": states[0].last_step_s,
        "model": model_identity(observer) if identity is None else identity,
        "weights": np.asarray(weights, float).tolist(),
        "filters": [{"spindle_rpm": s.spindle_rpm, "room_C": s.room_C, "nis": s.nis, "inflation": s.inflation,
                     "mean": s.mean.tolist(), "covariance": s.covariance.tolist()} for s in states]})


def write_state(path: str | Path, observer: DriftObserver | MultipleModelObserver,
                kept: tuple[list, np.ndarray] | None = None, identity: dict | None = None) -> bool:
    """Write ``observer``'s state (or its :func:`snapshot` ``kept``) to ``path`` atomically (:func:`state_text`,
    :func:`write_atomic`).

    Parameters
    ----------
    path : str or Path
        The state file.
    observer : DriftObserver or MultipleModelObserver
        The observer.
    kept : tuple, optional
        A :func:`snapshot` of it; default one taken now.
    identity : dict, optional
        Its :func:`model_identity`; default computed now.

    Returns
    -------
    bool
        Whether it was written (False: nothing to keep yet, or not finite; the file is left as it was).
    """
    text = state_text(observer, kept, identity)
    if text is not None:
        write_atomic(path, text)
    return text is not None


# ----------------------------------------------------------------------------- reading
@dataclass
class SavedState:
    """A state file read and checked against an observer (:func:`read_state`).

    Attributes
    ----------
    path : Path
        The file.
    time_s : float
        Machine time of the last sample fused, s.
    saved_utc : str
        The same time, ISO 8601 UTC.
    sample_interval_s : float
        The interval between its last two samples, s.
    weights : numpy.ndarray
        (m,) the hypotheses' weights, 1.
    filters : list of FilterState
        Each hypothesis's filter.
    """

    path: Path
    time_s: float
    saved_utc: str
    sample_interval_s: float
    weights: np.ndarray
    filters: list


class _Fields:
    """Reads the fields of one JSON object of a state file; every problem an error naming the file and field."""

    def __init__(self, path, data, prefix=""):
        if not isinstance(data, dict):
            raise TwinInputError(f"{path}: {prefix.rstrip('.') or 'the file'} is not a JSON object")
        self.path, self.data, self.prefix = path, data, prefix

    def problem(self, key, text):
        return TwinInputError(f"{self.path}: field {self.prefix}{key} = {_short(self.data.get(key))}: {text}; remove "
                              "the file, or give another --state, to start from the start prior")

    def get(self, key):
        if key not in self.data:
            raise TwinInputError(f"{self.path}: field {self.prefix}{key} missing; not a complete twin live state "
                                 "file")
        return self.data[key]

    def number(self, key):
        value = self.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise self.problem(key, "not a finite number")
        return float(value)

    def array(self, key, shape):
        try:
            value = np.array(self.get(key), dtype=float)
        except (TypeError, ValueError):
            value = None
        if value is None or value.shape != shape or not np.all(np.isfinite(value)):
            raise self.problem(key, f"not {' × '.join(map(str, shape))} finite numbers")
        return value


def _short(value):
    """A field's value for a message: itself, or its start when long (a covariance)."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "…"


def _check_identity(fields, identity):
    """Refuse a state of another machine, ROM, thermometer set or state space (``identity``: the observer's
    :func:`model_identity`), naming the first field that differs."""
    saved = _Fields(fields.path, fields.get("model"), "model.")
    for key, value in identity.items():
        if saved.get(key) != value:
            raise saved.problem(key, f"this observer's is {_short(value)}: the state belongs to another machine, "
                                     "model or set of thermometers")


def _filter(fields, time_s, step_s, size):
    covariance = fields.array("covariance", (size, size))
    # a covariance edited by hand: a filter would go on from it and give bands of no meaning
    if np.abs(covariance - covariance.T).max() > 1e-9 * np.abs(covariance).max() or np.any(np.diag(covariance) < 0):
        raise fields.problem("covariance", "not a symmetric matrix with a non-negative diagonal")
    inflation = fields.number("inflation")
    # the adaptive widening's factor on the process noise only widens it (Adaptation: max(1, NIS average)^power)
    if not inflation >= 1.0:
        raise fields.problem("inflation", "not a factor ≥ 1 (the adaptive widening only widens the process noise)")
    nis = fields.number("nis")
    # an average of NIS values, each ≥ 0: a negative one would hold the factor at 1 (no widening) for hours
    if nis < 0.0:
        raise fields.problem("nis", "not an average NIS ≥ 0 (a negative one would turn the adaptive widening off "
                                    "until it wore away)")
    return FilterState(time_s, step_s, fields.number("spindle_rpm"), fields.number("room_C"),
                       fields.array("mean", (size,)), covariance, nis, inflation)


def read_state(path: str | Path, observer: DriftObserver | MultipleModelObserver,
               identity: dict | None = None) -> SavedState:
    """Read a state file and check that it belongs to ``observer``'s model.

    Parameters
    ----------
    path : str or Path
        The state file.
    observer : DriftObserver or MultipleModelObserver
        The observer that is to go on from it.
    identity : dict, optional
        Its :func:`model_identity` (a session works it out once); default computed now.

    Returns
    -------
    SavedState
        The state.

    Raises
    ------
    TwinInputError
        A file that is not JSON (cut short, another file), not a state file, of another version or model
        (:func:`model_identity`), or with a field of the wrong kind, size or range (an adaptive factor below 1, a
        negative NIS average); the message names the file, the field and its value.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise TwinInputError(f"{path}: not a complete twin live state file ({exc}); remove it, or give another "
                             "--state, to start from the start prior") from None
    fields = _Fields(path, data)
    for key, expected in (("format", FORMAT), ("version", VERSION)):
        if fields.get(key) != expected:
            raise fields.problem(key, f"not a {FORMAT} file of version {VERSION}")
    _check_identity(fields, model_identity(observer) if identity is None else identity)
    members = _members(observer)
    filters = fields.get("filters")
    if not isinstance(filters, list) or len(filters) != len(members):
        raise fields.problem("filters", f"not a list of {len(members)} filters")
    time_s, step_s = fields.number("time_s"), fields.number("sample_interval_s")
    if not step_s > 0:
        raise fields.problem("sample_interval_s", "not a positive number of seconds")
    weights = fields.array("weights", (len(members),))
    if np.any(weights < 0) or not weights.sum() > 0:
        raise fields.problem("weights", "not weights ≥ 0 with a positive sum")
    return SavedState(path, time_s, str(fields.get("saved_utc")), step_s, weights / weights.sum(),
                      [_filter(_Fields(path, f, f"filters[{k}]."), time_s, step_s, m.model.size)
                       for k, (f, m) in enumerate(zip(filters, members))])


# ----------------------------------------------------------------------------- resuming
def _duration(seconds):
    """A time away as people say it: 40 s, 12 min, 9.83 min, 2.5 h."""
    if seconds < 60.0:
        return f"{seconds:.3g} s"
    return f"{seconds / 60:.3g} min" if seconds < 7200.0 else f"{seconds / 3600:.1f} h"


def resume(observer: DriftObserver | MultipleModelObserver, saved: SavedState, time_s: float) -> str:
    """Go on from ``saved`` at the first sample of a session, at ``time_s`` (s), or say why not.

    The last sample interval before the sample is the observer's ordinary step, with the sample's inputs (a record's
    samples hold left limits); the time away before it is bridged with the inputs unknown
    (:meth:`~twin.live.observer.DriftObserver.bridge`), so the band widens with it.  No time away (the session goes
    on with the sample after the saved one) resumes exactly as if it had not stopped.  A state saved
    more than :data:`RESUME_HORIZON_S` before the sample, or not before it (the clocks disagree), is not resumed:
    the observer starts from its start prior.

    Parameters
    ----------
    observer : DriftObserver or MultipleModelObserver
        A new observer of the state's model, not started.
    saved : SavedState
        The state (:func:`read_state`).
    time_s : float
        Machine time of the session's first sample, s.

    Returns
    -------
    str
        Which start the observer takes, and why, for the session's notices.
    """
    away = float(time_s) - saved.time_s
    where = f"{saved.path} (saved {saved.saved_utc}, t = {saved.time_s:.15g} s)"
    if not away > 0:
        return (f"not resumed from {where}: the first sample, t = {time_s:.15g} s, is not after it (the clocks "
                "disagree); started from the start prior")
    if away > RESUME_HORIZON_S:
        return (f"not resumed from {where}: saved {_duration(away)} before the first sample, beyond the "
                f"{_duration(RESUME_HORIZON_S)} horizon; started from the start prior")
    for member, state in zip(_members(observer), saved.filters):
        member.restore(state)
    if isinstance(observer, MultipleModelObserver):
        observer.weights, observer.last_interval_s = saved.weights.copy(), saved.sample_interval_s
    unread = away - saved.sample_interval_s
    if unread > 0:
        observer.bridge(saved.time_s + unread)
    return f"resumed from {saved.path}, saved {_duration(away)} before the first sample" + (
        f"; {_duration(unread)} of it without samples bridged with the spindle and the room air unknown"
        if unread > 0 else "")


class KeptObserver(RecordRunner):
    """An observer whose state is kept in a file: resumed from it at the first sample, written to it as it goes.

    The file, if there, is read and checked when this is made (:func:`read_state`: a file of another model or a
    malformed one raises at once).  At the first sample with a room air the observer resumes from it
    (:func:`resume`), and :attr:`start_note` says which start it took (also a notice).  The state is written at the
    first estimate that has one to keep (the second sample's: :meth:`~twin.live.observer.DriftObserver.state`), then
    every ``every_s`` wall seconds, and by :meth:`save` (``twin live`` calls it when the session ends, a Ctrl-C
    included).

    Parameters
    ----------
    observer : DriftObserver or MultipleModelObserver
        A new observer, not started.
    path : str or Path
        The state file.
    every_s : float
        Wall seconds between saves (default :data:`SAVE_EVERY_S`).
    """

    def __init__(self, observer: DriftObserver | MultipleModelObserver, path: str | Path,
                 every_s: float = SAVE_EVERY_S) -> None:
        self.observer, self.path, self.every_s = observer, Path(path), float(every_s)
        self.thermometers, self.field_names = observer.thermometers, observer.field_names
        # what the state belongs to, checked in the file read and written at every save: the model does not change
        # during a session
        self._identity = model_identity(observer)
        self.saved = read_state(self.path, observer, self._identity) if self.path.exists() else None
        #: which start the observer took, once the first sample with a room air came (None before)
        self.start_note = None
        self._next_save = -np.inf
        self._kept = None               # the state after the last sample fused (snapshot)
        self._read_rpm = np.nan         # a speed read before the first room air

    @property
    def time_s(self) -> float | None:
        """Machine time of the last sample fused, s (None before the start)."""
        return self.observer.time_s

    def step(self, time_s: float, spindle_rpm: float, room_C: float, temperatures_C: ArrayLike) -> Estimate | None:
        """The observer's :meth:`~twin.live.observer.DriftObserver.step`, resuming at the first sample and saving
        when due.

        Parameters
        ----------
        time_s : float
            Machine time of the sample, s.
        spindle_rpm, room_C : float
            Spindle speed (rpm) and room air (°C); NaN keeps that input's last reading.
        temperatures_C : array_like
            (p,) thermometer readings, °C (NaN = missing).

        Returns
        -------
        Estimate or None
            As the observer's.
        """
        if self.start_note is None and self.observer.time_s is None:
            self._read_rpm = spindle_rpm if np.isfinite(spindle_rpm) else self._read_rpm
            if np.isfinite(room_C):
                self.start_note = self._start(float(time_s))
                log.info("live: %s", self.start_note)
                # a speed reported only on change may have come before the room air: the resumed filter's saved
                # speed must not stand in for it
                spindle_rpm = self._read_rpm
        e = self.observer.step(time_s, spindle_rpm, room_C, temperatures_C)
        if e is not None:
            self._kept = snapshot(self.observer)
            if time.monotonic() >= self._next_save:
                self.save()
        return e

    def _start(self, time_s):
        if self.saved is None:
            return f"no state in {self.path} yet: started from the start prior"
        return resume(self.observer, self.saved, time_s)

    def save(self) -> bool:
        """Write the state after the last sample fused (:func:`write_state`; never one caught inside a sample by an
        error or a Ctrl-C); returns whether it was written (the next save is due :attr:`every_s` after one that
        was)."""
        written = self._kept is not None and write_state(self.path, self.observer, self._kept, self._identity)
        if written:
            self._next_save = time.monotonic() + self.every_s
        return written
