"""The FMU interface of a ROM: variables, units, ranges and the model description pieces both FMU kinds share.

Variables (value references are unique across types, in this order):

- parameter ``T_initial`` (°C): uniform start temperature;
- parameter ``steady_start`` (Boolean): start instead from the steady state for the inputs set at
  initialisation (as the ``kind = "steady"`` scenarios do);
- tunable parameter ``spindle_power_factor``: a factor on the spindle-driven sources' power model;
- inputs — what a plant measures: ``spindle_speed`` (rpm), ``feed_x``/``feed_y``/``feed_z`` (mm/min),
  ``ambient_<zone>`` (°C) per measured convection zone, ``ambient_gradient`` (K/m).  A zone whose air
  lags the room (``[[zones]] lag_h``, e.g. the enclosure) has no input: its air is a state of the model;
- outputs: the ROM's channels — surface and air thermometers (°C), TCP drift X/Y/Z and Y_top (µm),
  strain lines (µε).

Outputs are ``initial="calculated"`` and listed in ``ModelStructure/InitialUnknowns`` (they depend
on ``T_initial`` and, for air sensors and a steady start, on the inputs), so ``fmpy.validate_fmu``
reports no problem; ``ModelStructure/Outputs`` lists as ``dependencies`` only the inputs with a
non-zero feedthrough (:func:`direct_inputs`).  Real variables carry a ``declaredType`` and ``quantity``
(:data:`QUANTITIES`).
"""
from __future__ import annotations

import hashlib
import math
import uuid
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING
from xml.etree.ElementTree import Element, SubElement

from ..core.machine_definition import room_zone
from ..errors import TwinInputError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..rom.reduction import ReducedModel

#: FMU unit name → (base-unit exponents, factor, offset) as in FMI 2.0 §2.2.2.
UNITS = {
    "degC": ({"K": 1}, 1.0, 273.15),
    "K/m": ({"K": 1, "m": -1}, 1.0, 0.0),
    "um": ({"m": 1}, 1e-6, 0.0),
    "ue": ({}, 1e-6, 0.0),
    "rpm": ({"rad": 1, "s": -1}, 2 * math.pi / 60.0, 0.0),
    "mm/min": ({"m": 1, "s": -1}, 1e-3 / 60.0, 0.0),
}
#: FMU unit name → (type definition name, physical quantity): every Real variable declares its type.
QUANTITIES = {
    "degC": ("Temperature", "ThermodynamicTemperature"),
    "K/m": ("TemperatureGradient", "TemperatureGradient"),
    "um": ("Displacement", "Length"),
    "ue": ("Strain", "Strain"),
    "rpm": ("RotationalSpeed", "AngularVelocity"),
    "mm/min": ("FeedRate", "Velocity"),
}
#: Display units offered per unit: (name, factor, offset), displayed = factor · value + offset.
DISPLAY_UNITS = {"degC": [("degF", 1.8, 32.0)], "um": [("mm", 1e-3, 0.0)], "mm/min": [("m/min", 1e-3, 0.0)]}
#: ROM output unit tokens (twin.core.dataset) → FMU unit names.
OUTPUT_UNITS = {"degC": "degC", "um": "um", "ue": "ue"}
AMBIENT_RANGE_C = (-50.0, 100.0)
GRADIENT_RANGE_K_PER_M = (-50.0, 50.0)
DEFAULT_STEP_S = 10.0
#: Upper bound of the tunable ``spindle_power_factor`` (a calibration factor, 1 = the machine's model).
SPINDLE_FACTOR_MAX = 10.0
#: DefaultExperiment stopTime (s): one day, the scale of a warm-up or an ETVE run (any stop time works).
DEFAULT_STOP_S = 86400.0


class FMUError(TwinInputError):
    """An FMU cannot be exported or used as asked."""


@dataclass(frozen=True)
class Variable:
    """One FMU variable, as both kinds declare it.

    Attributes
    ----------
    name : str
    vr : int
        Value reference (unique across types).
    type : str
        ``Real`` or ``Boolean``.
    causality, variability : str
        FMI causality (``parameter``, ``input``, ``output``) and variability.
    unit : str or None
        FMU unit name (a key of :data:`UNITS`), None for unitless ones.
    description : str
    start : float, bool or None
    initial : str or None
        FMI ``initial`` (``exact``, ``calculated``).
    min, max : float or None
        Range, in ``unit``.
    role : str
        What it is to the FMU code: ``T_initial``, ``steady_start``, ``spindle_factor``, ``rpm``,
        ``feed_<axis>``, ``ambient:<zone>``, ``gradient`` or ``output``.
    depends_on : tuple of str
        Outputs: the inputs with a direct (feedthrough) effect on it, by name.
    """

    name: str
    vr: int
    type: str                 # Real | Boolean
    causality: str            # parameter | input | output
    variability: str
    unit: str | None
    description: str
    start: float | bool | None = None
    initial: str | None = None
    min: float | None = None
    max: float | None = None
    role: str = ""            # T_initial | steady_start | rpm | feed_x.. | ambient:<zone> | gradient | output
    depends_on: tuple = ()    # outputs: the inputs with a direct (feedthrough) effect on it, by name


def interface(rom: ReducedModel, default_temperature_C: float = 20.0) -> list[Variable]:
    """The FMU variables of a ROM, value references from 0 in declaration order.

    Parameters
    ----------
    rom : ReducedModel
        The ROM (or its view restricted to the exported outputs).
    default_temperature_C : float, default 20.0
        Start value of ``T_initial`` and of the ambient inputs, °C.

    Returns
    -------
    list of Variable
        Parameters, inputs, then outputs (see the module docstring).
    """
    limits = rom.limits
    rows = []

    def add(**kw):
        rows.append(Variable(vr=len(rows), **kw))

    add(name="T_initial", type="Real", causality="parameter", variability="fixed", unit="degC",
        description="uniform initial temperature of the machine", start=float(default_temperature_C),
        initial="exact", min=AMBIENT_RANGE_C[0], max=AMBIENT_RANGE_C[1], role="T_initial")
    add(name="steady_start", type="Boolean", causality="parameter", variability="fixed", unit=None,
        description="start from the steady state for the inputs at initialisation instead of T_initial",
        start=False, initial="exact", role="steady_start")
    add(name="spindle_power_factor", type="Real", causality="parameter", variability="tunable", unit=None,
        description="factor on the power of the spindle-driven heat sources, P = factor · c (n / n_ref)^b "
                    "(calibration of the spindle power model; tunable between steps)",
        start=1.0, initial="exact", min=0.0, max=SPINDLE_FACTOR_MAX, role="spindle_factor")
    add(name="spindle_speed", type="Real", causality="input", variability="continuous", unit="rpm",
        description="spindle speed", start=0.0, min=0.0, max=limits["max_spindle_rpm"], role="rpm")
    for axis in "xyz":
        add(name=f"feed_{axis}", type="Real", causality="input", variability="continuous", unit="mm/min",
            description=f"{axis.upper()} axis feed (sign = direction)", start=0.0,
            min=-limits["max_feed_mm_min"], max=limits["max_feed_mm_min"], role=f"feed_{axis}")
    for zone in rom.measured_zones:
        add(name=f"ambient_{zone}", type="Real", causality="input", variability="continuous", unit="degC",
            description=ambient_description(rom, zone), start=float(default_temperature_C),
            min=AMBIENT_RANGE_C[0], max=AMBIENT_RANGE_C[1], role=f"ambient:{zone}")
    add(name="ambient_gradient", type="Real", causality="input", variability="continuous", unit="K/m",
        description="vertical ambient temperature gradient", start=0.0, min=GRADIENT_RANGE_K_PER_M[0],
        max=GRADIENT_RANGE_K_PER_M[1], role="gradient")
    kinds = {"temperature": "surface thermometer", "air": "air thermometer", "displacement": "TCP drift",
             "strain": "strain line", "camera": "thermal camera spot"}
    inputs = {v.role: v.name for v in rows if v.causality == "input"}
    for j, (name, unit, kind) in enumerate(zip(rom.output_names, rom.output_units, rom.output_kinds)):
        add(name=name, type="Real", causality="output", variability="continuous", unit=OUTPUT_UNITS[unit],
            description=f"{kinds.get(kind, kind)} {name}" + (f": {rom.output_labels[j]}" if rom.output_labels else ""),
            initial="calculated", role="output",
            depends_on=direct_inputs(rom, rom.feedthrough[j], inputs))
    return rows


#: FMU input roles a heat source's power depends on, by driver (twin.core.machine_definition.HeatSource).
DRIVER_ROLES = {"constant": (), "spindle": ("rpm",), "feed_x": ("feed_x",), "feed_y": ("feed_y",),
                "feed_z": ("feed_z",), "feed_xy": ("feed_x", "feed_y"), "feed_xyz": ("feed_x", "feed_y", "feed_z")}


def direct_inputs(rom: ReducedModel, d_row: ArrayLike, inputs: Mapping[str, str]) -> tuple[str, ...]:
    """Names of the FMU inputs with a non-zero direct feedthrough on an output (row ``d_row`` of D over u).

    A lagged zone's ambient is a state, not an input; a source's power depends on the inputs of its driver.
    ``inputs``: FMU input role → name.

    Parameters
    ----------
    rom : ReducedModel
        The ROM (or its view restricted to the exported outputs).
    d_row : array_like, shape (m,)
        One output's row of the feedthrough D over the thermal inputs.
    inputs : mapping of str to str
        FMU input role → name.

    Returns
    -------
    tuple of str
        Input names, in the order of ``inputs``.
    """
    roles = []
    drivers = {f"power:{s['name']}": s["driver"] for s in rom.sources}
    for name, d in zip(rom.input_names, d_row):
        if d == 0.0:
            continue
        if name in drivers:
            roles += DRIVER_ROLES[drivers[name]]
        else:
            roles.append("gradient" if name == "ambient_gradient" else name)
    names = {inputs[r] for r in roles if r in inputs}
    return tuple(n for n in inputs.values() if n in names)



def ambient_description(rom: ReducedModel, zone: str) -> str:
    """What the ambient input of a measured zone is, naming the lagged zones that follow it inside the model.

    Parameters
    ----------
    rom : ReducedModel
        The ROM (or its view restricted to the exported outputs).
    zone : str
        A measured zone.

    Returns
    -------
    str
    """
    text = f"measured air temperature of convection zone {zone!r}"
    if zone == room_zone(rom.zones) and rom.lagged_zones:
        lags = ", ".join(f"{z!r} ({rom.zone_lags_s[z] / 3600.0:g} h)" for z in rom.lagged_zones)
        text += f"; the air of zone(s) {lags} follows it through a first-order lag, a state of the model"
    return text


def guid(rom: ReducedModel, kind: str) -> str:
    """A GUID that changes with the ROM and the FMU kind (stable for the same ROM).

    Parameters
    ----------
    rom : ReducedModel
        The ROM (or its view restricted to the exported outputs).
    kind : str
        Distinguishes the FMU kinds (and, for the Python kind, its content).

    Returns
    -------
    str
        ``{8-4-4-4-12}`` hex digits from a SHA-256 of the ROM digest, method, order, kind and output names.
    """
    h = hashlib.sha256(f"{rom.digest}|{rom.method}|{rom.order}|{kind}|{rom.output_names}".encode()).digest()
    return "{" + str(uuid.UUID(bytes=h[:16])) + "}"


def unit_definitions(used: Iterable[str]) -> Element:
    """``UnitDefinitions``: each unit used in SI base units (:data:`UNITS`) with its display units.

    Parameters
    ----------
    used : iterable of str
        FMU unit names.

    Returns
    -------
    Element
    """
    node = Element("UnitDefinitions")
    for name in sorted(used):
        exps, factor, offset = UNITS[name]
        unit = SubElement(node, "Unit", name=name)
        attrib = {k: str(v) for k, v in exps.items()}
        if factor != 1.0:
            attrib["factor"] = repr(factor)
        if offset != 0.0:
            attrib["offset"] = repr(offset)
        SubElement(unit, "BaseUnit", attrib)
        for display, d_factor, d_offset in DISPLAY_UNITS.get(name, ()):
            SubElement(unit, "DisplayUnit", name=display, factor=repr(d_factor), offset=repr(d_offset))
    return node


def type_definitions(used: Iterable[str], fmi_version: int = 2) -> Element:
    """``TypeDefinitions``: one Real (FMI 2 ``SimpleType``) / ``Float64Type`` (FMI 3) per unit used.

    Parameters
    ----------
    used : iterable of str
        FMU unit names.
    fmi_version : int, default 2
        2 or 3.

    Returns
    -------
    Element
    """
    node = Element("TypeDefinitions")
    for unit in sorted(used):
        name, quantity = QUANTITIES[unit]
        if int(fmi_version) == 3:
            SubElement(node, "Float64Type", name=name, quantity=quantity, unit=unit)
        else:
            SubElement(SubElement(node, "SimpleType", name=name), "Real", quantity=quantity, unit=unit)
    return node


def real_type_attributes(v: Variable) -> dict[str, str]:
    """``declaredType``, ``quantity`` and ``unit`` of a Real variable (empty for unitless ones).

    Parameters
    ----------
    v : Variable

    Returns
    -------
    dict of str to str
    """
    if not v.unit:
        return {}
    name, quantity = QUANTITIES[v.unit]
    return {"declaredType": name, "quantity": quantity, "unit": v.unit}


def _fmt(value):
    return f"{value:.17g}"


def scalar_variable(v: Variable) -> Element:
    """The FMI 2 ``ScalarVariable`` element of a :class:`Variable`.

    Parameters
    ----------
    v : Variable

    Returns
    -------
    Element
    """
    attrib = {"name": v.name, "valueReference": str(v.vr), "description": v.description,
              "causality": v.causality, "variability": v.variability}
    if v.initial:
        attrib["initial"] = v.initial
    node = Element("ScalarVariable", attrib)
    inner = {}
    if v.type == "Real":
        inner.update(real_type_attributes(v))
        if v.min is not None:
            inner["min"] = _fmt(v.min)
        if v.max is not None:
            inner["max"] = _fmt(v.max)
        if v.start is not None:
            inner["start"] = _fmt(v.start)
    elif v.start is not None:
        inner["start"] = "true" if v.start else "false"
    SubElement(node, v.type, inner)
    return node


def model_structure(variables: Sequence[Variable]) -> Element:
    """``ModelStructure`` (FMI 2, 1-based indices): every output in Outputs and InitialUnknowns.

    An output's ``dependencies`` list only the inputs with a non-zero feedthrough (air thermometers
    on their zone's ambient); the others depend on the state alone (``dependencies=""``), so a master
    sees no algebraic loop through them.  InitialUnknowns keep the default (all knowns: a steady
    start depends on every input).

    Parameters
    ----------
    variables : sequence of Variable
        Every FMU variable, in value-reference order (the indices are their positions + 1).

    Returns
    -------
    Element
    """
    node = Element("ModelStructure")
    outputs = SubElement(node, "Outputs")
    initial = SubElement(node, "InitialUnknowns")
    index = {v.name: i + 1 for i, v in enumerate(variables)}
    for i, v in enumerate(variables):
        if v.causality == "output":
            SubElement(outputs, "Unknown", index=str(i + 1),
                       dependencies=" ".join(str(index[n]) for n in v.depends_on))
            SubElement(initial, "Unknown", index=str(i + 1))
    return node
