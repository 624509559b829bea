"""PythonFMU slave of the thermal twin (copied into the FMU; needs only numpy for the ROM engine).

Resources next to this script:
- ``interface.json``: the FMU variables (see ``twin.fmu.spec``), the engine and its options;
- ``rom.npz``: the reduced model (``twin.rom.reduction`` format, no pickle) for ``engine = "rom"``.

Engines: ``rom`` integrates the ROM exactly for inputs held over each
communication step (zero-order hold in reduced modal coordinates, any step
size); ``fe`` rebuilds the full finite-element twin from the ``twin`` package
of the importing Python (slow, for reference) and integrates it by backward
Euler with the inputs held over the step.

Refusals (a value out of range or not finite, a fixed parameter set after initialisation, a step that is
not positive and finite or does not start at the FMU's time) raise :class:`Refused`: PythonFMU 0.7
reports any exception as fmi2Fatal, the only failing status it lets a Python slave return besides a
doStep's fmi2Discard — which it pairs with fmi2Terminated, so that masters end the run early without
an error.  The instance is left as it was and stays usable (see :func:`_keeping_alive`).
"""
import ctypes
import json
import math
import os

import numpy as np
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Initial, Fmi2Status

#: Values this far outside a bound, relative to the range, are rounding — fmpy's interpolation of a
#: constant 12000 rpm gives 12000.000000000002 — and are taken as the bound.
RANGE_TOLERANCE = 1e-9


class Refused(Exception):
    """A call the FMU refuses; the message names the variable and the value (logged first)."""


def _exact(x):
    """``x`` in as few digits as read back to it (15, else 17), as the native FMU prints it."""
    text = f"{x:.15g}"
    return text if float(text) == x else f"{x:.17g}"


def _range_problem(name, x, lo, hi):
    """What is wrong with value ``x`` of variable ``name`` (range [lo, hi], its unit); None if within rounding."""
    if not math.isfinite(x):
        return f"{name} = {_exact(x)} is not a finite number"
    margin = RANGE_TOLERANCE * (hi - lo)
    if not lo - margin <= x <= hi + margin:
        return f"{name} = {_exact(x)} is outside [{_exact(lo)}, {_exact(hi)}]"
    return None


def _at_current_time(t, now, h):
    """Whether a step of ``h`` s may start at ``t`` s when the FMU is at ``now`` s.

    The slack is rounding in the master's own sum of steps: 1e-6 of the step, and 1e-12 of t for long runs.
    """
    return abs(t - now) <= 1e-6 * h + 1e-12 * abs(now)


#: What PythonFMU 0.7 calls on a slave instance (any of them may raise).
_ENTRY_POINTS = ("setup_experiment", "enter_initialization_mode", "exit_initialization_mode", "do_step",
                 "terminate", "set_real", "set_integer", "set_boolean", "set_string", "get_real", "get_integer",
                 "get_boolean", "get_string", "_get_fmu_state", "_set_fmu_state")


def _keeping_alive(cls):
    """``cls`` whose entry points, when they raise, give back the references PythonFMU 0.7 then drops.

    Its exception handler releases the slave instance, its class and its log queue, yet keeps using them
    and releases them again when the instance is freed: the next call, or the garbage collector, touched
    freed memory (a segfault after two refused sets).  ``Py_IncRef`` restores the reference the C++ side
    still counts on; a Python container holding them instead would be one owner too many for the
    collector, which then frees them under it.
    """
    def guarded(method):
        def call(self, *args, **kwargs):
            try:
                return method(self, *args, **kwargs)
            except BaseException:       # Ctrl-C in a long FE step takes the same handler
                for obj in (self, type(self), self.log_queue):
                    ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))
                raise
        return call

    for name in _ENTRY_POINTS:
        setattr(cls, name, guarded(getattr(cls, name)))
    return cls


def _source_power(src, rpm, feed):
    driver = src["driver"]
    if driver == "constant":
        return src["coefficient_W"]
    if driver == "spindle":
        n = abs(rpm)
    elif driver == "feed_xy":
        n = max(abs(feed["x"]), abs(feed["y"]))
    elif driver == "feed_xyz":
        n = max(abs(feed["x"]), abs(feed["y"]), abs(feed["z"]))
    else:
        n = abs(feed[driver[-1]])
    return src["coefficient_W"] * (n / src["reference"]) ** src["exponent"]


class _Lags:
    """Zones whose air follows the room through a first-order lag: their air ``w`` (°C) is a state.

    ``config["lags"]`` lists ``{"zone", "tau_s"}``; ``config["room"]`` names the room zone.  The
    thermal input of a lagged zone's ambient is ``w``, never an FMU input.
    """

    def _init_lags(self, config):
        names = self.input_names
        self.lag_cols = [names.index("ambient:" + lag["zone"]) for lag in config["lags"]]
        self.mu = np.array([1.0 / lag["tau_s"] for lag in config["lags"]])
        self.room_col = names.index("ambient:" + config["room"])
        self.w = np.zeros(len(self.lag_cols))

    def _lags_at_room(self, u):
        self.w = np.full(len(self.lag_cols), float(u[self.room_col]))

    def _with_lags(self, u, w=None):
        u = np.array(u, float)
        u[self.lag_cols] = self.w if w is None else w
        return u


class _RomEngine(_Lags):
    def __init__(self, resources, config):
        data = np.load(os.path.join(resources, "rom.npz"), allow_pickle=False)
        meta = json.loads(str(data["meta"]))
        self.input_names = meta["input_names"]
        self.sources = meta["sources"]
        self.lam = np.array(data["eigenvalues"])
        self.B = np.array(data["input_matrix"])
        self.C = np.array(data["output_matrix"])
        self.D = np.array(data["feedthrough"])
        self.c = np.array(data["offset"])
        self.uniform = np.array(data["uniform_state"])
        names = meta["output_names"]
        self.rows = np.array([names.index(n) for n in config["outputs"]], dtype=int)
        self.z = np.zeros(len(self.lam))
        self._init_lags(config)
        self._h = None

    def start(self, T_initial, steady, u):
        self._lags_at_room(u)
        self.z = (self.B @ self._with_lags(u)) / self.lam if steady else T_initial * self.uniform

    def step(self, u, h):
        """Exact ZOH step (as ``twin.rom.reduction.ReducedModel.plant_states``); the lagged air follows the room."""
        if h != self._h:
            lam = self.lam
            self._a = np.exp(-lam * h)
            self._g = -np.expm1(-lam * h) / lam
            d = np.abs(lam[:, None] - self.mu[None, :])
            slow = np.minimum(lam[:, None], self.mu[None, :])
            with np.errstate(invalid="ignore", divide="ignore"):
                self._E = np.where(d == 0.0, h, -np.expm1(-d * h) / d) * np.exp(-slow * h)
            self._e = np.exp(-self.mu * h)
            self._h = h
        room = float(u[self.room_col])
        cross = (self._E * self.B[:, self.lag_cols]) @ (self.w - room)
        self.z = self._a * self.z + self._g * (self.B @ self._with_lags(u, room)) + cross
        self.w = room + (self.w - room) * self._e

    def outputs(self, u):
        return (self.C @ self.z + self.D @ self._with_lags(u) + self.c)[self.rows]

    def get_state(self):
        return {"z": self.z.tolist(), "w": self.w.tolist()}

    def set_state(self, state):
        self.z, self.w = np.array(state["z"]), np.array(state["w"])


class _FeEngine(_Lags):
    """The full FE twin (needs the ``twin`` package in the importing Python)."""

    def __init__(self, resources, config):
        # here, not at the top: the slave runs inside an FMU, and only this engine needs the twin installed
        import fea
        from twin.core.machine import build_machine

        fe = config["fe"]
        self.machine = build_machine(fe["machine"], fe.get("mesh_size_m"))
        self.solver = fea.ThermalSolver(self.machine.thermal, theta=1.0)
        self.max_step = float(fe.get("max_step_s", 60.0))
        self.input_names = list(self.machine.thermal.input_names)
        self.sources = fe["sources"]
        chans = [c.name for c in self.machine.channels]
        self.rows = np.array([chans.index(n) for n in config["outputs"]], dtype=int)
        self.T = None
        self._init_lags(config)

    def start(self, T_initial, steady, u):
        n = self.machine.thermal.n_nodes
        self._lags_at_room(u)
        self.T = self.solver.steady_state(self._with_lags(u)) if steady else np.full(n, float(T_initial))

    def step(self, u, h):
        """Backward Euler sub-steps ≤ max_step; the lagged air (exact for the held room) enters at their ends."""
        k = max(1, int(math.ceil(h / self.max_step - 1e-9)))
        room = float(u[self.room_col])
        for _ in range(k):
            self.w = room + (self.w - room) * np.exp(-self.mu * h / k)
            uk = self._with_lags(u)
            self.T = self.solver.step(self.T, uk, uk, h / k)

    def outputs(self, u):
        u = self._with_lags(u)
        fe = self.machine.outputs.apply(self.T)
        return self.machine.channel_values(fe[None, :], u[None, :])[0][self.rows]

    def get_state(self):
        return {"T": self.T.tolist(), "w": self.w.tolist()}

    def set_state(self, state):
        self.T, self.w = np.array(state["T"]), np.array(state["w"])


@_keeping_alive
class ThermalTwin(Fmi2Slave):
    """Thermal twin of a machine tool: heat sources and ambients in, temperatures and TCP drift out."""

    author = "thermal-twin"
    description = "Thermal digital twin of a CNC machine tool (reduced-order model)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        with open(os.path.join(self.resources, "interface.json"), encoding="utf-8") as f:
            config = json.load(f)
        self.description = config["description"]
        self.config = config
        self.engine = (_FeEngine if config["engine"] == "fe" else _RomEngine)(self.resources, config)
        self.values = {}
        self.ranges = {}                 # name → (min, max) of the parameters and inputs that have one
        self.input_roles = {}
        self.output_vars = []
        causality = {"parameter": Fmi2Causality.parameter, "input": Fmi2Causality.input,
                     "output": Fmi2Causality.output}
        variability = {"fixed": Fmi2Variability.fixed, "tunable": Fmi2Variability.tunable,
                       "continuous": Fmi2Variability.continuous}
        initial = {"exact": Fmi2Initial.exact, "calculated": Fmi2Initial.calculated, None: None}
        for v in config["variables"]:
            name = v["name"]
            kw = dict(causality=causality[v["causality"]], variability=variability[v["variability"]],
                      description=v["description"], initial=initial[v.get("initial")])
            if v["causality"] == "output":
                index = len(self.output_vars)
                self.output_vars.append(name)
                getter = (lambda i=index: float(self._outputs()[i]))
                self.register_variable(Real(name, getter=getter, **kw))
                continue
            self.values[name] = v["start"]
            getter = (lambda n=name: self.values[n])
            setter = (lambda value, n=name: self._set(n, value))
            cls = Boolean if v["type"] == "Boolean" else Real
            self.register_variable(cls(name, start=v["start"], getter=getter, setter=setter, **kw))
            if v.get("min") is not None:
                self.ranges[name] = (v["min"], v["max"])
            if v["causality"] == "input":
                self.input_roles[v["role"]] = name
        self.parameters = {v["name"] for v in config["variables"]        # fixed: settable until initialised
                           if v["causality"] == "parameter" and v["variability"] == "fixed"}
        self.spindle_factor = next(v["name"] for v in config["variables"] if v["role"] == "spindle_factor")
        self._cache = None
        self._phase = "instantiated"     # → initialization → step → terminated
        self._start_key = None
        self._time = 0.0                 # s: where the next step starts

    # -------------------------------------------------------------- helpers
    def _refuse(self, message):
        """Log ``message`` as an error and raise :class:`Refused`: the call fails, the FMU is unchanged."""
        self.log(message, Fmi2Status.error)
        raise Refused(message)

    def _set(self, name, value):
        """Set a parameter or input, refusing a fixed parameter after initialisation and a value out of range
        (one within rounding of a bound is taken as the bound)."""
        api = "fmi2SetBoolean" if isinstance(value, bool) else "fmi2SetReal"
        if name in self.parameters and self._phase not in ("instantiated", "initialization"):
            self._refuse(f"{api}: {name} is a fixed parameter: it can only be set before initialisation ends")
        if name in self.ranges:
            lo, hi = self.ranges[name]
            problem = _range_problem(name, float(value), lo, hi)
            if problem:
                self._refuse(f"{api}: {problem}")
            value = min(max(float(value), lo), hi)
        self.values[name] = value
        self._cache = None

    def _start(self):
        """Set the engine to the start state the parameters and inputs imply (once per distinct setting)."""
        key = (float(self.values["T_initial"]), bool(self.values["steady_start"]), tuple(self._u()))
        if key != self._start_key:
            self.engine.start(key[0], key[1], self._u())
            self._start_key = key

    def _u(self):
        names = self.engine.input_names
        r = self.input_roles
        u = np.zeros(len(names))
        rpm = float(self.values[r["rpm"]])
        feed = {a: float(self.values[r[f"feed_{a}"]]) for a in "xyz"}
        for i, n in enumerate(names):
            if n in r:                       # a measured zone's ambient (lagged zones: a state, set by the engine)
                u[i] = float(self.values[r[n]])
            elif n == "ambient_gradient":
                u[i] = float(self.values[r["gradient"]])
        factor = float(self.values[self.spindle_factor])
        for src in self.engine.sources:
            u[names.index("power:" + src["name"])] = _source_power(src, rpm, feed) * (
                factor if src["driver"] == "spindle" else 1.0)
        return u

    def _outputs(self):
        if self._cache is None:
            if self._phase in ("instantiated", "initialization"):
                self._start()            # Initialization Mode: the outputs of the state the parameters imply
            self._cache = self.engine.outputs(self._u())
        return self._cache

    def _get_fmu_state(self):
        state = {name: self.values[name] for name in self.values}
        state["__engine__"] = self.engine.get_state()
        state["__phase__"] = self._phase
        state["__time__"] = self._time
        return state

    def _set_fmu_state(self, state):
        problem = self._state_problem(state)
        if problem:
            self._refuse(f"fmi2SetFMUstate: {problem}; the instance is left as it was")
        state = dict(state)
        self.engine.set_state(state.pop("__engine__"))
        self._phase = state.pop("__phase__")
        self._time = state.pop("__time__")
        self.values.update(state)
        self._cache = None

    def _state_problem(self, state):
        """Why ``state`` is not one :meth:`_get_fmu_state` of this FMU gave, or None (checked before any of it
        is applied)."""
        ours = self._get_fmu_state()
        if not isinstance(state, dict) or set(state) != set(ours):
            return "not a state of this FMU (unreadable bytes, or the state of another FMU)"
        engine, mine = state["__engine__"], ours["__engine__"]
        if not isinstance(engine, dict) or set(engine) != set(mine) or any(
                np.shape(engine[k]) != np.shape(mine[k]) for k in mine):
            return "its model state does not have this FMU's shape"
        return None

    @staticmethod
    def _fmu_state_from_bytes(state: bytes):
        # PythonFMU calls this on the class, where _keeping_alive cannot give back the references its exception
        # handler drops: it must not raise, so bytes that are no state become one _set_fmu_state refuses
        try:
            return json.loads(bytes(state).decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            return None

    # -------------------------------------------------------------- FMI
    def setup_experiment(self, start_time: float, stop_time: "float | None" = None,
                         tolerance: "float | None" = None) -> None:
        """fmi2SetupExperiment: the first step starts at ``start_time``.

        Parameters
        ----------
        start_time : float
            s.
        stop_time : float or None
            s (unused: any stop time works).
        tolerance : float or None
            Unused: each step is exact for inputs held over it.
        """
        self._time = float(start_time)

    def exit_initialization_mode(self) -> None:
        """fmi2ExitInitializationMode: set the start state (uniform or steady); each value was checked when set."""
        self._start()
        self._phase = "step"
        self._cache = None

    def enter_initialization_mode(self) -> None:
        """fmi2EnterInitializationMode: parameters and inputs may now be set for the start."""
        self._phase = "initialization"

    def terminate(self) -> None:
        """fmi2Terminate: no further step is accepted."""
        self._phase = "terminated"

    def do_step(self, current_time: float, step_size: float) -> bool:
        """fmi2DoStep: advance by ``step_size`` with the inputs held over the step.

        Parameters
        ----------
        current_time : float
            Time at the start of the step, s: the FMU's time (where the last step ended, or that of a
            restored FMU state).
        step_size : float
            Step, s (positive and finite).

        Returns
        -------
        bool
            True; a refused step (before initialisation or after termination, a step size that is not positive
            and finite, a ``current_time`` that is not the FMU's) raises :class:`Refused`, logged.
        """
        when = f"fmi2DoStep at t = {_exact(current_time)} s"
        if self._phase != "step":
            self._refuse(f"{when}: the FMU is {self._phase}, not initialised for stepping")
        if not (step_size > 0 and math.isfinite(step_size)):
            self._refuse(f"{when}: step size {_exact(step_size)} must be positive and finite")
        if not _at_current_time(current_time, self._time, step_size):
            self._refuse(f"{when}: the FMU is at t = {_exact(self._time)} s; a step starts where the last one "
                         "ended (or at the time of a state restored with SetFMUstate)")
        self.engine.step(self._u(), float(step_size))
        self._time = current_time + step_size
        self._cache = None
        return True
