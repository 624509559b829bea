"""The library of candidate sim-to-real effects: each one a named, parameterised, bounded change to the twin.

An effect acts on the twin in one of three places (its ``kind``):

``system``
    the thermal matrices: A += a(θ)·dA, B += a(θ)·dB, with dA, dB exact
    differences of two assembled systems (convection coefficients, joint
    conductance).  Nonlinear in θ.
``input``
    the thermal inputs u(t): extra load columns (an unmodelled source, a warm
    air pocket, radiation to the walls) and changes of the existing ones
    (source powers, zone ambients, the vertical gradient).  Linear in θ when
    θ scales a fixed signal (``linear = True``): one basis response per
    parameter and a linear least-squares fit.
``output``
    the sensors: lag, mounting (reading part air), fixture drift of the
    displacement probes.

Each effect has ``hidden`` constants (time constants, exponents) that are
part of its model but not fitted; the blind benchmark's truth uses other
values (:data:`twin.gap.benchmark.TRUTH_HIDDEN`), so the library never
matches the truth exactly.

Every effect documents what it changes in ``how``; ``docs/gap.md`` lists them.
"""
from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from types import MappingProxyType

import numpy as np
import scipy.sparse as sp

from ..core.machine import Machine, reassemble
from ..core.machine_definition import HeatSource, MachineDefinition
from ..errors import TwinInputError
from .drive import Drive, IdleDrive
from .signals import lag
from .structure import RADIATIVE_COEFFICIENT, Structure, facet_table, lumped_facet_load


@dataclass(frozen=True)
class Param:
    """A fitted parameter: nominal value (no effect), bounds, unit; ``log`` fits log10 of it."""

    name: str
    unit: str
    nominal: float
    lower: float
    upper: float
    log: bool = False


class Effect:
    """Base class; see the module docstring.  Subclasses set the class attributes and override hooks."""

    name = ""
    label = ""
    kind = "input"
    linear = True
    params: tuple = ()
    defaults: Mapping[str, object] = MappingProxyType({})  # read-only: shared by every instance
    how = ""

    def __init__(self, **hidden: object):
        unknown = sorted(set(hidden) - set(self.defaults))
        if unknown:
            raise ValueError(f"effect {self.name}: unknown hidden constant(s) {unknown}; known: {sorted(self.defaults)}")
        self.hidden = {**self.defaults, **hidden}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name})"

    def variant(self, **hidden: object) -> Effect:
        """A copy with other hidden constants (the truth of the blind benchmark).

        Parameters
        ----------
        **hidden
            Hidden constants to replace (names of ``defaults``; not checked), in their units.

        Returns
        -------
        Effect
            A shallow copy of this effect with the merged hidden constants.
        """
        out = copy.copy(self)
        out.hidden = {**self.hidden, **hidden}
        return out

    # ---------------------------------------------------------------- parameters
    def parameters(self, machine: Machine) -> tuple[Param, ...]:
        """The parameters with nominals resolved for a machine.

        Parameters
        ----------
        machine : Machine
            The built twin.

        Returns
        -------
        tuple of Param
            The fitted parameters θ, in order (name, unit, nominal, bounds).
        """
        return self.params

    def nominal(self, machine: Machine) -> np.ndarray:
        """The nominal parameter values (the effect off) for a machine.

        Parameters
        ----------
        machine : Machine
            The built twin.

        Returns
        -------
        ndarray, shape (n_params,)
            Nominal θ, in the units of :meth:`parameters`.
        """
        return np.array([p.nominal for p in self.parameters(machine)])

    def applicable(self, machine: Machine) -> bool:
        """True, or False when the machine lacks what the effect acts on (a zone, a joint, a source).

        Parameters
        ----------
        machine : Machine
            The built twin.

        Returns
        -------
        bool
            Whether the effect can act on this machine.
        """
        return True

    # ---------------------------------------------------------------- hooks
    def prepare(self, structure: Structure) -> None:
        """Register extra inputs / system terms on a :class:`~twin.gap.structure.Structure`.

        Parameters
        ----------
        structure : Structure
            Modified in place (the base class registers nothing).
        """

    def coefficients(self, theta: np.ndarray | Sequence[float], structure: Structure) -> dict[str, float]:
        """System-term coefficients {term: a} for parameters θ.

        Parameters
        ----------
        theta : ndarray or sequence of float, shape (n_params,)
            Parameter values θ, in the units of :meth:`parameters`.
        structure : Structure
            The structure the effect was prepared on.

        Returns
        -------
        dict of str to float
            System term → coefficient a (A += a·dA, B += a·dB), dimensionless; empty for non-system effects.
        """
        return {}

    def input_changes(self, theta: np.ndarray | Sequence[float], drive: Drive | IdleDrive,
                      structure: Structure) -> dict[str, np.ndarray]:
        """Input changes {input name: (n,)} on the drive's grid.

        Parameters
        ----------
        theta : ndarray or sequence of float, shape (n_params,)
            Parameter values θ, in the units of :meth:`parameters`.
        drive : Drive or IdleDrive
            Operating conditions on the twin grid (n points, step ``drive.step_s``, s).
        structure : Structure
            The structure the effect was prepared on.

        Returns
        -------
        dict of str to ndarray, shape (n,)
            Input name → change added to that input column, in the input's unit (``power:*`` W,
            ``ambient:*`` °C, ``ambient_gradient`` K/m, ``gap:*`` as the extra column defines it); empty for
            non-input effects.
        """
        return {}

    def thermometer_change(self, theta: np.ndarray | Sequence[float], T: np.ndarray, air: np.ndarray,
                           step_s: float) -> np.ndarray:
        """Surface-thermometer readings (n, k) from true surface temperatures T (n, k) and local air (n, k).

        Parameters
        ----------
        theta : ndarray or sequence of float, shape (n_params,)
            Parameter values θ, in the units of :meth:`parameters`.
        T : ndarray, shape (n, k)
            True surface temperatures at the k thermometers on the grid, °C.
        air : ndarray, shape (n, k)
            Ambient air at each thermometer's surface (zone and height), °C.
        step_s : float
            Grid step, s.

        Returns
        -------
        ndarray, shape (n, k)
            Readings, °C (T itself for effects that do not act on thermometers).
        """
        return T

    def displacement_change(self, theta: np.ndarray | Sequence[float], D: np.ndarray, axes: Sequence[str],
                            drive: Drive) -> np.ndarray:
        """Displacement readings (n, k) from the true drift D (n, k); ``axes`` is 'x'/'y'/'z' per column.

        Parameters
        ----------
        theta : ndarray or sequence of float, shape (n_params,)
            Parameter values θ, in the units of :meth:`parameters`.
        D : ndarray, shape (n, k)
            True drift of the k displacement channels on the grid, µm.
        axes : sequence of str, length k
            Axis ``"x"``, ``"y"`` or ``"z"`` of every column.
        drive : Drive
            Operating conditions on the twin grid (room ambient, °C; step, s).

        Returns
        -------
        ndarray, shape (n, k)
            Readings, µm (D itself for effects that do not act on displacements).
        """
        return D

    def _speed_factor(self, rpm: np.ndarray, feeds: dict[str, np.ndarray]) -> np.ndarray:
        """(|n| / reference_rpm)^exponent of the hidden constants (spindle-driven effects; feeds unused)."""
        return (np.abs(rpm) / self.hidden["reference_rpm"]) ** self.hidden["exponent"]


# ============================================================================= system effects
def scaled_definition(definition: MachineDefinition, groups: Sequence[str] = (), joint: Sequence[str] | None = None,
                      factor: float = 2.0) -> MachineDefinition:
    """A copy of a machine definition with the convection of ``groups`` and the conductance of ``joint`` × factor.

    Parameters
    ----------
    definition : MachineDefinition
        The machine file's content (not modified).
    groups : sequence of str, default ()
        Convection groups whose coefficient h (W/(m²·K)) is scaled.
    joint : sequence of str, optional
        The two part names of the joint whose contact conductance is scaled (either order).
    factor : float, default 2.0
        The scale factor, dimensionless.

    Returns
    -------
    MachineDefinition
        The changed copy.
    """
    convection = [replace(r, coefficient=r.coefficient * factor) if r.name in groups else r
                  for r in definition.convection]
    joints = [(a, b, h * factor) if joint is not None and {a, b} == set(joint) else (a, b, h)
              for a, b, h in definition.joints]
    return replace(definition, convection=convection, joints=joints)


def system_difference(structure: Structure, definition: MachineDefinition) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """(dA, dB): the changes of the thermal stiffness (W/K) and input matrix from reassembling on ``definition``.

    Parameters
    ----------
    structure : Structure
        Holds the nominal machine.
    definition : MachineDefinition
        The changed definition (same inputs).

    Returns
    -------
    dA : sparse matrix, shape (n_nodes, n_nodes)
        Change of the thermal stiffness, W/K.
    dB : sparse matrix, shape (n_nodes, n_machine_inputs)
        Change of the input matrix (nodal load per unit input).

    Raises
    ------
    RuntimeError
        If the change altered the machine's inputs.
    """
    changed = reassemble(structure.machine, definition)
    if list(changed.thermal.input_names) != list(structure.machine.thermal.input_names):
        raise RuntimeError("internal: a system change altered the inputs")
    dA = changed.thermal.stiffness - structure.machine.thermal.stiffness
    dB = changed.thermal.input_matrix - structure.machine.thermal.input_matrix
    return dA, dB


class ConvectionScale(Effect):
    """Convection coefficients of some facet groups mis-scaled by a factor s.

    Parameters
    ----------
    name : str
        Effect name (also its system term's name).
    label : str
        Readable label.
    groups : sequence of str
        The convection groups scaled.
    **hidden
        Other hidden constants (none besides ``groups``).
    """

    kind = "system"
    linear = False
    params = (Param("scale", "×", 1.0, 0.3, 3.0, log=True),)
    defaults = MappingProxyType({"groups": ()})

    def __init__(self, name: str, label: str, groups: Sequence[str], **hidden: object):
        self.name, self.label = name, label
        super().__init__(groups=tuple(groups), **hidden)
        self.how = (f"h of the convection groups {', '.join(self.hidden['groups'])} × s: A += (s−1)·dA, "
                    "B += (s−1)·dB with dA, dB the exact change for doubling h (two assemblies); "
                    "bounded Gauss–Newton on log s")

    def applicable(self, machine: Machine) -> bool:
        return any(r.name in self.hidden["groups"] for r in machine.definition.convection)

    def prepare(self, structure: Structure) -> None:
        d = scaled_definition(structure.machine.definition, groups=self.hidden["groups"])
        structure.add_system_term(self.name, *system_difference(structure, d))

    def coefficients(self, theta: np.ndarray | Sequence[float], structure: Structure) -> dict[str, float]:
        return {self.name: float(theta[0]) - 1.0}


class JointConductance(Effect):
    """Contact conductance of one joint mis-scaled by a factor s (same joint pairs, so same node numbering).

    Parameters
    ----------
    name : str, default "joint_conductance"
        Effect name (also its system term's name).
    label : str, optional
        Readable label; default names the joint.
    **hidden
        Hidden constants: ``joint``, the two part names (default ``("carrier", "ram")``).
    """

    kind = "system"
    linear = False
    params = (Param("factor", "×", 1.0, 0.05, 10.0, log=True),)
    defaults = MappingProxyType({"joint": ("carrier", "ram")})

    def __init__(self, name: str = "joint_conductance", label: str | None = None, **hidden: object):
        self.name = name
        super().__init__(**hidden)
        a, b = self.hidden["joint"]
        self.label = label or f"contact conductance of the {a}–{b} joint"
        self.how = (f"h_c of joint {a}–{b} × s: A += (s−1)·dA, dA the exact interface-matrix change for "
                    "doubling h_c (thermal numbering and output operator unchanged); bounded Gauss–Newton on log s")

    def applicable(self, machine: Machine) -> bool:
        return any({a, b} == set(self.hidden["joint"]) for a, b, _ in machine.definition.joints)

    def prepare(self, structure: Structure) -> None:
        d = scaled_definition(structure.machine.definition, joint=self.hidden["joint"])
        structure.add_system_term(self.name, *system_difference(structure, d))

    def coefficients(self, theta: np.ndarray | Sequence[float], structure: Structure) -> dict[str, float]:
        return {self.name: float(theta[0]) - 1.0}


# ============================================================================= input effects
def _zone_of_group(machine, group):
    return next(r.zone for r in machine.definition.convection if r.name == group)


class RadiationToWalls(Effect):
    """Radiation of the outer surfaces to the walls (mean radiant temperature), not to the air."""

    name = "radiation_walls"
    label = "radiation to the walls (emissivity ε; walls lag the room air)"
    linear = False
    # the walls' lag is as unknown as ε: a fixed one leaves a structured residual that a second effect soaks up
    params = (Param("emissivity", "–", 0.0, 0.0, 1.0), Param("wall_lag_h", "h", 6.0, 0.5, 24.0, log=True))
    defaults = MappingProxyType({"groups": ("outside", "front")})
    how = ("the radiative share ε·h_r (h_r = 4σT³ = 5.7 W/(m² K)) of the exchange of the outer groups sees the "
           "walls, which follow the room air through a first-order lag τ_w, instead of the air: extra inputs "
           "ε·(T_walls − T_zone) on lumped h_r facet loads; ε and τ_w fitted (bounded Gauss–Newton, inputs only)")

    def _groups(self, machine):
        return [r.name for r in machine.definition.convection if r.name in self.hidden["groups"]]

    def applicable(self, machine: Machine) -> bool:
        return bool(self._groups(machine))

    def prepare(self, structure: Structure) -> None:
        _, _, _, groups, _, _ = facet_table(structure.machine)
        for g in self._groups(structure.machine):
            structure.add_input(f"gap:radiation:{g}",
                                lumped_facet_load(structure.machine, groups == g, RADIATIVE_COEFFICIENT))

    def input_changes(self, theta: np.ndarray | Sequence[float], drive: Drive | IdleDrive,
                      structure: Structure) -> dict[str, np.ndarray]:
        walls = lag(drive.room(), drive.step_s, theta[1] * 3600.0)
        amb = drive.zone_ambient()
        return {f"gap:radiation:{g}": theta[0] * (walls - amb[_zone_of_group(structure.machine, g)])
                for g in self._groups(structure.machine)}


class Stratification(Effect):
    """A vertical ambient gradient that follows the room's daily swing (the air under the roof swings more)."""

    name = "stratification"
    label = "ambient vertical stratification growing with the room's swing"
    params = (Param("gain", "K/m per K", 0.0, -0.5, 0.5),)
    how = ("extra vertical gradient g(t) = gain·(T_room(t) − mean T_room) in the convection ambients "
           "(T_amb(z) = zone + g·(z − z_ref)); the zone ambients estimated from air sensors at other "
           "heights move with it; linear in the gain")

    def input_changes(self, theta: np.ndarray | Sequence[float], drive: Drive | IdleDrive,
                      structure: Structure) -> dict[str, np.ndarray]:
        g = theta[0] * drive.room_excursion()
        new, old = drive.zone_ambient(extra_gradient=g), drive.zone_ambient()
        out = {f"ambient:{z}": new[z] - old[z] for z in drive.zones}
        out["ambient_gradient"] = g
        return out


class AirPocket(Effect):
    """A warm air pocket around a heat source that builds up while the spindle runs (Mian et al.)."""

    name = "air_pocket"
    label = "warm air pocket around the spindle motor (builds up with speed)"
    params = (Param("rise_K", "K", 0.0, 0.0, 10.0),)
    defaults = MappingProxyType({"near_source": "spindle_motor", "radius_m": 0.3, "lag_min": 20.0,
                                 "reference_rpm": 9000.0, "exponent": 1.0})
    how = ("the ambient of the convection facets within 0.3 m of the spindle-motor source rises by "
           "rise_K·(n/9000)^1 through a 20 min lag: an extra input on the lumped h·area/3 load of those facets; "
           "linear in rise_K")

    def _source(self, machine):
        return next((s for s in machine.definition.sources if s.name == self.hidden["near_source"]), None)

    def applicable(self, machine: Machine) -> bool:
        return self._source(machine) is not None

    def prepare(self, structure: Structure) -> None:
        machine = structure.machine
        src = self._source(machine)
        tets = machine.mesh.select_tets(region=src.part)
        centre = machine.mesh.points[machine.mesh.tets[tets]].mean(axis=(0, 1))
        _, cents, _, _, h, _ = facet_table(machine)
        mask = np.linalg.norm(cents - centre, axis=1) <= self.hidden["radius_m"]
        structure.add_input("gap:air_pocket", lumped_facet_load(machine, mask, h))

    def input_changes(self, theta: np.ndarray | Sequence[float], drive: Drive | IdleDrive,
                      structure: Structure) -> dict[str, np.ndarray]:
        x = drive.step_mean(self._speed_factor)
        return {"gap:air_pocket": theta[0] * lag(x, drive.step_s, self.hidden["lag_min"] * 60.0)}


class UnmodelledSource(Effect):
    """An unmodelled heat source driven by the spindle (e.g. a belt drive or gearbox), P = P_ref·(n/n_ref)^b."""

    name = "belt_drive"
    label = "unmodelled heat source: belt drive on the carrier top"
    params = (Param("power_W", "W", 0.0, 0.0, 150.0),)
    defaults = MappingProxyType({"part": "carrier", "box": (0.08, 0.18, -0.1, 0.36, 1.50, 1.55),
                                 "reference_rpm": 9000.0, "exponent": 1.0})
    how = ("a volumetric source in the carrier's top plate (x 0.08–0.18 m), P = power_W·(n/9000)^1, added to "
           "the definition and assembled (one extra input column); linear in power_W")

    def applicable(self, machine: Machine) -> bool:
        return self.hidden["part"] in machine.definition.geometry.part_names()

    def prepare(self, structure: Structure) -> None:
        d = structure.machine.definition
        src = HeatSource("gap_belt_drive", self.label, self.hidden["part"], tuple(self.hidden["box"]), "spindle",
                         1.0, self.hidden["reference_rpm"], 1.0)
        changed = reassemble(structure.machine, replace(d, sources=list(d.sources) + [src]))
        B = changed.thermal.input_matrix.tocsc()
        structure.add_input("gap:belt_drive", B[:, changed.thermal.input_index("power:gap_belt_drive")].toarray())

    def input_changes(self, theta: np.ndarray | Sequence[float], drive: Drive | IdleDrive,
                      structure: Structure) -> dict[str, np.ndarray]:
        return {"gap:belt_drive": theta[0] * drive.step_mean(self._speed_factor)}


def _spindle_sources(machine):
    return [s for s in machine.definition.sources if s.driver == "spindle"]


class SpindlePowerScale(Effect):
    """The spindle-driven heat sources (bearings, motor) all mis-scaled by one factor."""

    name = "spindle_power_scale"
    label = "spindle heat powers mis-scaled (bearings and motor)"
    params = (Param("scale", "×", 1.0, 0.5, 2.0),)
    how = "every spindle-driven source power × s: input change (s−1)·P_src(n); linear in s"

    def applicable(self, machine: Machine) -> bool:
        return bool(_spindle_sources(machine))

    def input_changes(self, theta: np.ndarray | Sequence[float], drive: Drive | IdleDrive,
                      structure: Structure) -> dict[str, np.ndarray]:
        return {f"power:{s.name}": (theta[0] - 1.0) * drive.step_mean(s.power_W)
                for s in _spindle_sources(structure.machine)}


class SpeedExponent(Effect):
    """Error of the speed exponent b of the spindle-driven power models P = c·(n/n_ref)^b."""

    name = "speed_exponent"
    label = "heat-power speed-exponent error"
    linear = False
    params = (Param("delta_b", "–", 0.0, -0.8, 0.8),)
    how = ("b → b + δ for every spindle-driven source (power unchanged at its reference speed): input change "
           "P(n; b+δ) − P(n; b); nonlinear in δ (bounded Gauss–Newton, inputs only)")

    def applicable(self, machine: Machine) -> bool:
        return bool(_spindle_sources(machine))

    def input_changes(self, theta: np.ndarray | Sequence[float], drive: Drive | IdleDrive,
                      structure: Structure) -> dict[str, np.ndarray]:
        out = {}
        for s in _spindle_sources(structure.machine):
            exponent = s.exponent + theta[0]
            out[f"power:{s.name}"] = drive.step_mean(lambda n, f, s=s, b=exponent: s.power_W(n, f, 1.0, b)
                                                     - s.power_W(n, f))
        return out


class DoorDraft(Effect):
    """The cold draft of an open door reaches the air inside the enclosure directly (not only through its lag)."""

    name = "door_draft"
    label = "door-opening draft into the enclosure"
    params = (Param("share", "–", 0.0, 0.0, 1.5),)
    defaults = MappingProxyType({"door_zone": "front", "inner_zone": "enclosure", "lag_min": 0.0})
    how = ("enclosure ambient += share·(T_front − T_room): the door zone's departure from the room (the door "
           "events seen by the front air sensor) enters the enclosure; linear in share")

    def applicable(self, machine: Machine) -> bool:
        z = machine.definition.zones
        return self.hidden["door_zone"] in z and self.hidden["inner_zone"] in z

    def input_changes(self, theta: np.ndarray | Sequence[float], drive: Drive | IdleDrive,
                      structure: Structure) -> dict[str, np.ndarray]:
        amb = drive.zone_ambient()
        # (a constant part, e.g. the air sensors' offsets, shifts the outputs by a constant: the offsets take it)
        signal = amb[self.hidden["door_zone"]] - amb[drive.room_zone]
        signal = lag(signal, drive.step_s, self.hidden["lag_min"] * 60.0)
        return {f"ambient:{self.hidden['inner_zone']}": theta[0] * signal}


class EnclosureLag(Effect):
    """Wrong time constant of the enclosure air's lag behind the room."""

    name = "enclosure_lag"
    label = "enclosure air lag error"
    linear = False
    defaults = MappingProxyType({"zone": "enclosure"})
    how = ("the enclosure ambient follows the room through a lag τ instead of the machine's (3 h): input change "
           "lag(T_room, τ) − lag(T_room, τ₀); nonlinear in τ (bounded Gauss–Newton on log τ)")

    def parameters(self, machine: Machine) -> tuple[Param, ...]:
        tau = machine.definition.zone_lags_s.get(self.hidden["zone"], 3 * 3600.0) / 3600.0
        return (Param("lag_h", "h", tau, 0.25, 12.0, log=True),)

    def applicable(self, machine: Machine) -> bool:
        return self.hidden["zone"] in machine.definition.zone_lags_s

    def input_changes(self, theta: np.ndarray | Sequence[float], drive: Drive | IdleDrive,
                      structure: Structure) -> dict[str, np.ndarray]:
        z = self.hidden["zone"]
        new = drive.zone_ambient(lags_s={z: float(theta[0]) * 3600.0})[z]
        return {f"ambient:{z}": new - drive.zone_ambient()[z]}


# ============================================================================= output effects
class SensorLag(Effect):
    """Surface thermometers read the surface through a first-order lag (mounting pad, adhesive, magnet)."""

    name = "sensor_lag"
    label = "thermometer lag (mounting thermal resistance)"
    kind = "output"
    linear = False
    params = (Param("tau_s", "s", 0.0, 0.0, 3600.0),)
    defaults = MappingProxyType({"spread": 0.0, "seed": 0})
    how = "every surface thermometer reads lag(T, τ); nonlinear in τ (bounded Gauss–Newton)"

    def thermometer_change(self, theta: np.ndarray | Sequence[float], T: np.ndarray, air: np.ndarray,
                           step_s: float) -> np.ndarray:
        tau = float(theta[0])
        if tau <= 0:
            return T
        if not self.hidden["spread"]:
            return lag(T, step_s, tau)
        rng = np.random.default_rng(self.hidden["seed"])
        taus = tau * (1 + self.hidden["spread"] * rng.uniform(-1, 1, T.shape[1]))
        return np.column_stack([lag(T[:, j], step_s, taus[j]) for j in range(T.shape[1])])


class SensorMounting(Effect):
    """Surface thermometers read partly the air around them (poor contact, no insulation)."""

    name = "sensor_mounting"
    label = "thermometer mounting: readings mix in the local air"
    kind = "output"
    params = (Param("air_share", "–", 0.0, 0.0, 0.6),)
    how = ("every surface thermometer reads (1−κ)·T_surface + κ·T_air, T_air the ambient of the zone (and "
           "height) of the surface it sits on; linear in κ")

    def thermometer_change(self, theta: np.ndarray | Sequence[float], T: np.ndarray, air: np.ndarray,
                           step_s: float) -> np.ndarray:
        return T + theta[0] * (air - T)


class FixtureDrift(Effect):
    """Thermal drift of the displacement-probe fixture, following the room air through a lag."""

    name = "fixture_drift"
    label = "thermal drift of the measurement fixture"
    kind = "output"
    linear = False
    params = (Param("k_x", "µm/K", 0.0, -10.0, 10.0), Param("k_y", "µm/K", 0.0, -10.0, 10.0),
              Param("k_z", "µm/K", 0.0, -10.0, 10.0), Param("lag_min", "min", 30.0, 1.0, 240.0, log=True))
    how = ("each displacement reading += k_axis·(T_fix − T_fix(0)), T_fix the room air through a lag τ_f "
           "(the probe nest and its stand); k_x, k_y, k_z and τ_f fitted (bounded Gauss–Newton, outputs only)")

    def displacement_change(self, theta: np.ndarray | Sequence[float], D: np.ndarray, axes: Sequence[str],
                            drive: Drive) -> np.ndarray:
        fix = lag(drive.room(), drive.step_s, theta[3] * 60.0)
        fix = fix - fix[0]
        k = {"x": theta[0], "y": theta[1], "z": theta[2]}
        return D + np.column_stack([k[a] * fix for a in axes]) if D.size else D


# ============================================================================= the library
def default_library() -> list[Effect]:
    """The candidate effects of the diagnosis (14), in a fixed order.

    Returns
    -------
    list of Effect
        New instances with their default hidden constants.
    """
    return [
        ConvectionScale("convection_enclosure", "convection mis-scaled inside the enclosure", ("enclosure",)),
        ConvectionScale("convection_room", "convection mis-scaled on the outer surfaces (room, door side)",
                        ("outside", "front")),
        RadiationToWalls(),
        JointConductance("joint_ram_guides", "contact conductance of the ram guides (carrier–ram joint)",
                         joint=("carrier", "ram")),
        Stratification(),
        AirPocket(),
        UnmodelledSource(),
        SpindlePowerScale(),
        SpeedExponent(),
        SensorLag(),
        SensorMounting(),
        DoorDraft(),
        FixtureDrift(),
        EnclosureLag(),
    ]


def library_by_name(names: Sequence[str] | None = None, library: list[Effect] | None = None) -> list[Effect]:
    """Effects of the library by name (all without names); unknown names raise a clear error.

    Parameters
    ----------
    names : sequence of str, optional
        Effect names; None or empty for the whole library.
    library : list of Effect, optional
        The candidates; default (also when empty) :func:`default_library`.

    Returns
    -------
    list of Effect
        The effects, in the order of ``names`` (the library itself without names).

    Raises
    ------
    TwinInputError
        If a name is not in the library.
    """
    library = library or default_library()
    if not names:
        return library
    known = {e.name: e for e in library}
    bad = [n for n in names if n not in known]
    if bad:
        raise TwinInputError(f"unknown effect(s) {bad}; effects: {list(known)}")
    return [known[n] for n in names]
