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


class _RomEngine:
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
        self._h = None

    def start(self, T_initial, steady, u):
        self.z = (self.B @ u) / self.lam if steady else T_initial * self.uniform

    def step(self, u, h):
        if h != self._h:
            self._a = np.exp(-self.lam * h)
            self._g = -np.expm1(-self.lam * h) / self.lam
            self._h = h
        self.z = self._a * self.z + self._g * (self.B @ u)

    def outputs(self, u):
        return (self.C @ self.z + self.D @ u + self.c)[self.rows]


class _FeEngine:
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

    def start(self, T_initial, steady, u):
        n = self.machine.thermal.n_nodes
        self.T = self.solver.steady_state(u) if steady else np.full(n, float(T_initial))

    def step(self, u, h):
        k = max(1, int(math.ceil(h / self.max_step - 1e-9)))
        for _ in range(k):
            self.T = self.solver.step(self.T, u, u, h / k)

    def outputs(self, u):
        fe = self.machine.outputs.apply(self.T)
        return self.machine.channel_values(fe[None, :], u[None, :])[0][self.rows]


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
        variability = {"fixed": Fmi2Variability.fixed, "continuous": Fmi2Variability.continuous}
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
            if v["causality"] == "input":
                self.checks.append((name, v.get("min"), v.get("max")))
                self.input_roles[v["role"]] = name
        self._cache = None
        self.engine.start(float(self.values["T_initial"]), False, self._u())

    # -------------------------------------------------------------- helpers
    def _set(self, name, value):
        self.values[name] = value
        self._cache = None

    def _u(self):
        names = self.engine.input_names
        r = self.input_roles
        u = np.zeros(len(names))
        rpm = float(self.values[r["rpm"]])
        feed = {a: float(self.values[r[f"feed_{a}"]]) for a in "xyz"}
        for i, n in enumerate(names):
            if n.startswith("ambient:"):
                u[i] = float(self.values[r[n]])
            elif n == "ambient_gradient":
                u[i] = float(self.values[r["gradient"]])
        for src in self.engine.sources:
            u[names.index("power:" + src["name"])] = _source_power(src, rpm, feed)
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
            self._cache = self.engine.outputs(self._u())
        return self._cache

    # -------------------------------------------------------------- FMI
    def exit_initialization_mode(self):
        bad = self._bad_inputs()
        if bad:
            self.log("initial inputs out of range: " + "; ".join(bad), Fmi2Status.error)
            return False
        self.engine.start(float(self.values["T_initial"]), bool(self.values["steady_start"]), self._u())
        self._cache = None
        return True

    def do_step(self, current_time, step_size):
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
