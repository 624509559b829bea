"""The FMU interface of a ROM: variables, units, ranges and the model description pieces both FMU kinds share.

Variables (value references are unique across types, in this order):

- parameter ``T_initial`` (°C): uniform start temperature;
- parameter ``steady_start`` (Boolean): start instead from the steady state for the inputs set at
  initialisation (as the ``kind = "steady"`` scenarios do);
- inputs ``spindle_speed`` (rpm), ``feed_x``/``feed_y``/``feed_z`` (mm/min), ``ambient_<zone>`` (°C)
  per convection zone, ``ambient_gradient`` (K/m);
- outputs: the ROM's channels — surface and air thermometers (°C), TCP drift X/Y/Z and Y_top (µm),
  strain lines (µε).

Outputs are ``initial="calculated"`` and listed in ``ModelStructure/InitialUnknowns`` (they depend
on ``T_initial`` and, for air sensors and a steady start, on the inputs), so ``fmpy.validate_fmu``
reports no problem.
"""
from __future__ import annotations

import hashlib
import math
import uuid
from dataclasses import dataclass
from xml.etree.ElementTree import Element, SubElement

from ..errors import TwinInputError

#: FMU unit name → (base-unit exponents, factor, offset) as in FMI 2.0 §2.2.2.
UNITS = {
    "degC": ({"K": 1}, 1.0, 273.15),
    "K/m": ({"K": 1, "m": -1}, 1.0, 0.0),
    "um": ({"m": 1}, 1e-6, 0.0),
    "ue": ({}, 1e-6, 0.0),
    "rpm": ({"rad": 1, "s": -1}, 2 * math.pi / 60.0, 0.0),
    "mm/min": ({"m": 1, "s": -1}, 1e-3 / 60.0, 0.0),
}
#: ROM output unit tokens (twin.core.dataset) → FMU unit names.
OUTPUT_UNITS = {"degC": "degC", "um": "um", "ue": "ue"}
AMBIENT_RANGE_C = (-50.0, 100.0)
GRADIENT_RANGE_K_PER_M = (-50.0, 50.0)
DEFAULT_STEP_S = 10.0


class FMUError(TwinInputError):
    """An FMU cannot be exported or used as asked."""


@dataclass(frozen=True)
class Variable:
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


def interface(rom, default_temperature_C=20.0):
    """The FMU variables of a ROM, value references from 0 in declaration order."""
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
    add(name="spindle_speed", type="Real", causality="input", variability="continuous", unit="rpm",
        description="spindle speed", start=0.0, min=0.0, max=limits["max_spindle_rpm"], role="rpm")
    for axis in "xyz":
        add(name=f"feed_{axis}", type="Real", causality="input", variability="continuous", unit="mm/min",
            description=f"{axis.upper()} axis feed (sign = direction)", start=0.0,
            min=-limits["max_feed_mm_min"], max=limits["max_feed_mm_min"], role=f"feed_{axis}")
    for zone in rom.zones:
        add(name=f"ambient_{zone}", type="Real", causality="input", variability="continuous", unit="degC",
            description=f"ambient temperature of convection zone {zone!r}", start=float(default_temperature_C),
            min=AMBIENT_RANGE_C[0], max=AMBIENT_RANGE_C[1], role=f"ambient:{zone}")
    add(name="ambient_gradient", type="Real", causality="input", variability="continuous", unit="K/m",
        description="vertical ambient temperature gradient", start=0.0, min=GRADIENT_RANGE_K_PER_M[0],
        max=GRADIENT_RANGE_K_PER_M[1], role="gradient")
    kinds = {"temperature": "surface thermometer", "air": "air thermometer", "displacement": "TCP drift",
             "strain": "strain line", "camera": "thermal camera spot"}
    for name, unit, kind in zip(rom.output_names, rom.output_units, rom.output_kinds):
        add(name=name, type="Real", causality="output", variability="continuous", unit=OUTPUT_UNITS[unit],
            description=f"{kinds.get(kind, kind)} {name}", initial="calculated", role="output")
    return rows


def guid(rom, kind):
    """A GUID that changes with the ROM and the FMU kind (stable for the same ROM)."""
    h = hashlib.sha256(f"{rom.digest}|{rom.method}|{rom.order}|{kind}|{rom.output_names}".encode()).digest()
    return "{" + str(uuid.UUID(bytes=h[:16])) + "}"


def unit_definitions(used):
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
    return node


def _fmt(value):
    return f"{value:.17g}"


def scalar_variable(v):
    """The FMI 2 ``ScalarVariable`` element of a :class:`Variable`."""
    attrib = {"name": v.name, "valueReference": str(v.vr), "description": v.description,
              "causality": v.causality, "variability": v.variability}
    if v.initial:
        attrib["initial"] = v.initial
    node = Element("ScalarVariable", attrib)
    inner = {}
    if v.type == "Real":
        if v.unit:
            inner["unit"] = v.unit
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


def model_structure(variables):
    """``ModelStructure`` with every output in Outputs and InitialUnknowns (1-based indices)."""
    node = Element("ModelStructure")
    outputs = SubElement(node, "Outputs")
    initial = SubElement(node, "InitialUnknowns")
    for i, v in enumerate(variables):
        if v.causality == "output":
            SubElement(outputs, "Unknown", index=str(i + 1))
            SubElement(initial, "Unknown", index=str(i + 1))
    return node
