"""PythonFMU slave of the thermal twin (copied into the FMU; needs only numpy for the ROM engine).

Resources next to this script:
- ``interface.json``: the FMU variables (see ``twin.fmu.spec``), the engine and its options;
- ``rom.npz``: the reduced model (``twin.rom.reduction`` format, no pickle) for ``engine = "rom"``.

Engines: ``rom`` integrates the ROM exactly for inputs held over each
communication step (zero-order hold in reduced modal coordinates, any step
size); ``fe`` rebuilds the full finite-element twin from the ``twin`` package
of the importing Python (slow, for reference) and integrates it by backward
Euler with the inputs held over the step.
"""
import json
import math
import os

import numpy as np
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Initial, Fmi2Status


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
        self.checks = []                 # (name, min, max) of the inputs
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
            if v["causality"] == "input" or v["variability"] == "tunable":    # checked at each step
                self.checks.append((name, v.get("min"), v.get("max")))
            if v["causality"] == "input":
                self.input_roles[v["role"]] = name
        self.parameters = {v["name"] for v in config["variables"]        # fixed: settable until initialised
                           if v["causality"] == "parameter" and v["variability"] == "fixed"}
        self.spindle_factor = next(v["name"] for v in config["variables"] if v["role"] == "spindle_factor")
        self._cache = None
        self._phase = "instantiated"     # → initialization → step → terminated
        self._start_key = None

    # -------------------------------------------------------------- helpers
    def _set(self, name, value):
        if name in self.parameters and self._phase not in ("instantiated", "initialization"):
            self.log(f"{name} is a fixed parameter: it can only be set before initialisation ends",
                     Fmi2Status.error)
            raise ValueError(f"{name} cannot be set after initialisation")
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

    def _bad_inputs(self):
        bad = []
        for name, lo, hi in self.checks:
            x = float(self.values[name])
            if not math.isfinite(x):
                bad.append(f"{name} = {x} is not a finite number")
            elif (lo is not None and x < lo) or (hi is not None and x > hi):
                bad.append(f"{name} = {x:g} is outside [{lo:g}, {hi:g}]")
        return bad

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
        return state

    def _set_fmu_state(self, state):
        state = dict(state)
        self.engine.set_state(state.pop("__engine__"))
        self._phase = state.pop("__phase__")
        self.values.update(state)
        self._cache = None

    # -------------------------------------------------------------- FMI
    def exit_initialization_mode(self) -> bool:
        """fmi2ExitInitializationMode: check the inputs, set the start state (uniform or steady).

        Returns
        -------
        bool
            False (fmi2Error, logged) if an input is out of range.
        """
        bad = self._bad_inputs()
        if bad:
            self.log("initial inputs out of range: " + "; ".join(bad), Fmi2Status.error)
            return False
        self._start()
        self._phase = "step"
        self._cache = None
        return True

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
            Time at the start of the step, s.
        step_size : float
            Step, s (> 0).

        Returns
        -------
        bool
            False (fmi2Error, logged) before initialisation, for an input out of range or a step ≤ 0.
        """
        if self._phase != "step":
            self.log(f"doStep at t = {current_time:g} s: the FMU is {self._phase}, not initialised for stepping",
                     Fmi2Status.error)
            return False
        bad = self._bad_inputs()
        if bad:
            self.log(f"doStep at t = {current_time:g} s rejected: " + "; ".join(bad), Fmi2Status.error)
            return False
        if not step_size > 0:
            self.log(f"doStep at t = {current_time:g} s: step size {step_size!r} must be positive",
                     Fmi2Status.error)
            return False
        self.engine.step(self._u(), float(step_size))
        self._cache = None
        return True
