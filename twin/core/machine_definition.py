"""Reading a machine definition (TOML under ``meshes/machines``): materials, joints, convection,
heat sources, supports, sensors, camera and tool-centre point.

The geometry (parts, mesh settings) is read by :mod:`meshes.definition`; this
module reads everything the twin adds on top, validating every field.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fea import Material
from meshes.definition import load_geometry, machine_path
from meshes.tomlspec import DefinitionError, Table, read_toml

DRIVERS = {"spindle", "feed_x", "feed_y", "feed_z", "feed_xy", "feed_xyz", "constant"}
SENSOR_KINDS = {"temperature", "air", "strain"}


@dataclass(frozen=True)
class HeatSource:
    """A heat source with power ``P = coefficient_W · (n / reference)^exponent`` in W.

    ``driver`` says what n is: the spindle speed (rpm), an axis feed
    (mm/min; ``feed_xy`` is the larger of X and Y), or ``constant`` (P =
    coefficient_W whenever the machine is powered).  The heat is released
    uniformly in the tetrahedra of ``part`` whose centroid lies in ``box``
    (the whole part without a box).
    """

    name: str
    label: str
    part: str
    box: tuple | None
    driver: str
    coefficient_W: float
    reference: float
    exponent: float

    def power_W(self, spindle_rpm, feed_mm_min, scale=1.0, exponent=None):
        """Power in W for arrays of spindle speed (rpm) and feeds (dict axis → mm/min)."""
        b = self.exponent if exponent is None else exponent
        if self.driver == "constant":
            n = np.ones_like(np.asarray(spindle_rpm, float))
            return scale * self.coefficient_W * n
        if self.driver == "spindle":
            n = np.abs(np.asarray(spindle_rpm, float))
        elif self.driver == "feed_xy":
            n = np.maximum(np.abs(feed_mm_min["x"]), np.abs(feed_mm_min["y"]))
        elif self.driver == "feed_xyz":
            n = np.maximum.reduce([np.abs(feed_mm_min[a]) for a in "xyz"])
        else:
            n = np.abs(np.asarray(feed_mm_min[self.driver[-1]], float))
        return scale * self.coefficient_W * (n / self.reference) ** b


@dataclass(frozen=True)
class ConvectionRule:
    """Facets of ``parts`` (optionally only cavity facets, or those facing a direction) get h and an ambient zone."""

    name: str
    parts: tuple
    coefficient: float
    zone: str
    facing: tuple | None = None
    inside: bool = False


@dataclass(frozen=True)
class Sensor:
    """A virtual sensor: a surface thermometer, an air thermometer (reads its zone) or a strain line."""

    name: str
    kind: str
    label: str
    position: tuple | None = None
    start: tuple | None = None
    end: tuple | None = None
    zone: str | None = None


@dataclass(frozen=True)
class Camera:
    """A grid of virtual thermal-camera spots on one planar face of a part."""

    part: str
    face_axis: str
    face_value: float
    u_range: tuple
    v_range: tuple
    grid: tuple
    position: tuple

    def spots(self):
        """Spot coordinates (n_u · n_v, 3) in m, row-major over v then u."""
        k = "xyz".index(self.face_axis)
        others = [i for i in range(3) if i != k]
        u = np.linspace(*self.u_range, self.grid[0])
        v = np.linspace(*self.v_range, self.grid[1])
        V, U = np.meshgrid(v, u, indexing="ij")
        pts = np.zeros((U.size, 3))
        pts[:, k] = self.face_value
        pts[:, others[0]] = U.ravel()
        pts[:, others[1]] = V.ravel()
        return pts


@dataclass
class MachineDefinition:
    """Everything a machine file says, validated."""

    name: str
    description: str
    source: str
    geometry: object
    materials: dict
    joints: list
    convection: list
    sources: list
    sensors: list
    camera: Camera | None
    tool_point: tuple
    workpiece_point: tuple
    tilt_probe_offset: tuple
    support_points: list
    max_spindle_rpm: float
    max_feed_mm_min: float
    reference_temperature_C: float
    elastic_degree: int
    snap_distance_m: float
    ambient_reference_height_m: float
    zones: list = field(default_factory=list)
    zone_lags_s: dict = field(default_factory=dict)

    def sensor(self, name):
        for s in self.sensors:
            if s.name == name:
                return s
        raise DefinitionError(f"{self.source}: unknown sensor {name!r}; sensors: {[s.name for s in self.sensors]}")

    def part_material(self, part_name):
        for p in self.geometry.parts:
            if p.name == part_name:
                return self.materials[p.material]
        raise DefinitionError(f"{self.source}: unknown part {part_name!r}")


def load_machine(machine):
    """Read and validate a machine definition by name (``vmc_ram``) or path."""
    path = machine_path(machine)
    geometry = load_geometry(path)
    root = read_toml(path)
    root.check_keys({"machine", "mesh", "materials", "parts", "joints", "convection", "sources",
                     "supports", "tcp", "sensors", "camera", "zones"})
    info = root.table("machine")
    info.check_keys({"name", "description", "max_spindle_rpm", "max_feed_mm_min", "reference_temperature_C",
                     "elastic_degree", "snap_distance_m", "ambient_reference_height_m"})
    part_names = set(geometry.part_names())

    def check_part(table, key, name):
        if name not in part_names:
            raise table.error(key, f"names an unknown part; parts: {sorted(part_names)}", name)
        return name

    materials = {}
    mats = root.table("materials")
    for key in mats.keys():
        m = mats.table(key)
        m.check_keys({"conductivity", "density", "specific_heat", "youngs_modulus", "poisson_ratio", "expansion"})
        values = {k: m.number(k, minimum=0.0, strict_minimum=True)
                  for k in ("conductivity", "density", "specific_heat", "youngs_modulus", "expansion")}
        materials[key] = Material(values["conductivity"], values["density"], values["specific_heat"],
                                  values["youngs_modulus"], m.number("poisson_ratio", minimum=0.0, maximum=0.49),
                                  values["expansion"], key)
    for i, part in enumerate(geometry.parts):
        if part.material not in materials:
            raise DefinitionError(f"{path}: parts[{i}].material names an unknown material {part.material!r}; "
                                  f"materials: {sorted(materials)}")

    joints = []
    for t in root.tables("joints"):
        t.check_keys({"parts", "conductance"})
        pair = t.strings("parts")
        if len(pair) != 2:
            raise t.error("parts", "must name exactly two parts", pair)
        for name in pair:
            check_part(t, "parts", name)
        joints.append((pair[0], pair[1], t.number("conductance", minimum=0.0, strict_minimum=True)))

    convection = []
    for t in root.tables("convection", required=True):
        t.check_keys({"name", "parts", "coefficient", "zone", "facing", "inside"})
        parts = t.strings("parts")
        for name in parts:
            check_part(t, "parts", name)
        convection.append(ConvectionRule(t.string("name"), tuple(parts),
                                         t.number("coefficient", minimum=0.0, strict_minimum=True),
                                         t.string("zone", "room"), t.vector("facing", 3, None),
                                         t.boolean("inside", False)))
    _check_unique(path, "convection", [r.name for r in convection])
    zones = sorted({r.zone for r in convection})
    zone_lags_s = {}
    for t in root.tables("zones"):
        t.check_keys({"name", "lag_h", "label"})
        name = t.string("name")
        if name not in zones:
            raise t.error("name", f"is not a convection zone; zones: {zones}", name)
        zone_lags_s[name] = t.number("lag_h", minimum=0.0, strict_minimum=True) * 3600.0

    sources = []
    for t in root.tables("sources"):
        t.check_keys({"name", "label", "part", "box", "driver", "coefficient_W", "reference", "exponent"})
        sources.append(HeatSource(t.string("name"), t.string("label", ""), check_part(t, "part", t.string("part")),
                                  t.vector("box", 6, None), t.string("driver", choices=DRIVERS),
                                  t.number("coefficient_W", minimum=0.0), t.number("reference", 1.0,
                                                                                    minimum=0.0, strict_minimum=True),
                                  t.number("exponent", 1.0, minimum=0.0)))
    _check_unique(path, "sources", [s.name for s in sources])

    sensors = []
    for t in root.tables("sensors"):
        t.check_keys({"name", "kind", "label", "position", "start", "end", "zone"})
        kind = t.string("kind", choices=SENSOR_KINDS)
        if kind == "strain":
            sensor = Sensor(t.string("name"), kind, t.string("label", ""), start=t.vector("start", 3),
                            end=t.vector("end", 3))
        else:
            zone = t.string("zone", "room") if kind == "air" else None
            if zone is not None and zone not in zones:
                raise t.error("zone", f"is not a convection zone; zones: {zones}", zone)
            sensor = Sensor(t.string("name"), kind, t.string("label", ""), position=t.vector("position", 3),
                            zone=zone)
        sensors.append(sensor)
    _check_unique(path, "sensors", [s.name for s in sensors])

    camera = None
    if "camera" in root:
        c = root.table("camera")
        c.check_keys({"part", "face_axis", "face_value", "u_range", "v_range", "grid", "position"})
        grid = c.raw("grid")
        if not (isinstance(grid, list) and len(grid) == 2 and all(isinstance(g, int) and g > 0 for g in grid)):
            raise c.error("grid", "must be two positive integers [n_u, n_v]", grid)
        camera = Camera(check_part(c, "part", c.string("part")), c.string("face_axis", choices=set("xyz")),
                        c.number("face_value"), c.vector("u_range", 2), c.vector("v_range", 2), tuple(grid),
                        c.vector("position", 3))

    tcp = root.table("tcp")
    tcp.check_keys({"tool_point", "workpiece_point", "tilt_probe_offset"})
    supports = root.table("supports")
    supports.check_keys({"kind", "points"})
    supports.string("kind", choices={"kinematic"})
    points = supports.raw("points")
    if not (isinstance(points, list) and len(points) == 3):
        raise supports.error("points", "must list three [x, y, z] points for the 3-2-1 mount", points)
    support_points = [Table({f"points[{i}]": p}, supports.file, "supports").vector(f"points[{i}]", 3)
                      for i, p in enumerate(points)]
    elastic_degree = info.integer("elastic_degree", 1, minimum=1)
    if elastic_degree not in (1, 2):
        raise info.error("elastic_degree", "must be 1 or 2 (P1 or P2 displacements)", elastic_degree)

    return MachineDefinition(
        name=geometry.name,
        description=info.string("description", ""),
        source=str(path),
        geometry=geometry,
        materials=materials,
        joints=joints,
        convection=convection,
        sources=sources,
        sensors=sensors,
        camera=camera,
        tool_point=tcp.vector("tool_point", 3),
        workpiece_point=tcp.vector("workpiece_point", 3),
        tilt_probe_offset=tcp.vector("tilt_probe_offset", 3, (0.0, 0.0, 0.1)),
        support_points=support_points,
        max_spindle_rpm=info.number("max_spindle_rpm", minimum=0.0, strict_minimum=True),
        max_feed_mm_min=info.number("max_feed_mm_min", 30000.0, minimum=0.0, strict_minimum=True),
        reference_temperature_C=info.number("reference_temperature_C", 20.0),
        elastic_degree=elastic_degree,
        snap_distance_m=info.number("snap_distance_m", 0.003, minimum=0.0),
        ambient_reference_height_m=info.number("ambient_reference_height_m", 1.0),
        zones=zones,
        zone_lags_s=zone_lags_s,
    )


def _check_unique(path, table, names):
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise DefinitionError(f"{path}: {table}: duplicate names {dupes}")


def room_zone(zones):
    """The zone whose ambient is "the room" (the scenario's ambient): ``room`` if there is one, else the first."""
    return "room" if "room" in zones else zones[0]
