"""Reading a machine definition (TOML under ``meshes/machines``): materials, joints, convection,
heat sources, supports, sensors, camera and tool-centre point.

The file is parsed once: its geometry (parts, mesh settings) is read by
:func:`meshes.definition.read_geometry` (which the mesher uses too, as
``meshes`` must not import ``twin``); this module reads everything the twin
adds on top, validating every field.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fea import Material
from meshes.definition import machine_path, read_geometry
from meshes.tomlspec import DefinitionError, Table, duplicates, read_toml

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

    def power_W(self, spindle_rpm: np.ndarray, feed_mm_min: dict[str, np.ndarray], scale: float = 1.0,
                exponent: float | None = None) -> np.ndarray:
        """The source's power for operating conditions.

        Parameters
        ----------
        spindle_rpm : ndarray
            Spindle speed, rpm.
        feed_mm_min : dict of str to ndarray
            Axis → feed, mm/min (unused by spindle and constant sources).
        scale : float
            Factor on the power.
        exponent : float, optional
            Replaces the source's speed exponent.

        Returns
        -------
        ndarray
            Power, W, shape of ``spindle_rpm`` (or of the feeds).
        """
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

    def spots(self) -> np.ndarray:
        """The camera spots on the face.

        Returns
        -------
        ndarray, shape (n_u · n_v, 3)
            Coordinates, m, row-major over v then u.
        """
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

    def sensor(self, name: str) -> Sensor:
        """A sensor by name.

        Parameters
        ----------
        name : str
            Sensor name.

        Returns
        -------
        Sensor
            Its kind, position (m) or line ends (m), zone.

        Raises
        ------
        DefinitionError
            Unknown name (the message lists the sensors).
        """
        for s in self.sensors:
            if s.name == name:
                return s
        raise DefinitionError(f"{self.source}: unknown sensor {name!r}; sensors: {[s.name for s in self.sensors]}")

    def part_material(self, part_name: str) -> Material:
        """The material of a part.

        Parameters
        ----------
        part_name : str
            Part name.

        Returns
        -------
        Material
            Its conductivity, density, heat capacity and elastic properties (SI).
        """
        for p in self.geometry.parts:
            if p.name == part_name:
                return self.materials[p.material]
        raise DefinitionError(f"{self.source}: unknown part {part_name!r}")


TOP_LEVEL_KEYS = {"machine", "mesh", "materials", "parts", "joints", "convection", "sources", "supports", "tcp",
                  "sensors", "camera", "zones"}
MACHINE_KEYS = {"name", "description", "max_spindle_rpm", "max_feed_mm_min", "reference_temperature_C",
                "elastic_degree", "snap_distance_m", "ambient_reference_height_m"}


def load_machine(machine: str | Path) -> MachineDefinition:
    """Read and validate a machine definition: geometry and physics, from one parse of the file.

    The geometry (``[mesh]``, ``[[parts]]``) is read by
    :func:`meshes.definition.read_geometry`, the same reader the mesher uses,
    so the mesh cache keys do not depend on which package read the file.

    Parameters
    ----------
    machine : str or Path
        Name of a shipped machine (``vmc_ram``) or path of a machine TOML file.

    Returns
    -------
    MachineDefinition
        Everything the file says, in SI units (m, W, W/(m² K), s).

    Raises
    ------
    DefinitionError
        One line naming the file, the field and the bad value.
    """
    path = machine_path(machine)
    root = read_toml(path)
    geometry = read_geometry(root, path)
    root.check_keys(TOP_LEVEL_KEYS)
    info = root.table("machine")
    info.check_keys(MACHINE_KEYS)
    parts = _PartNames(geometry.part_names())
    materials = _read_materials(root.table("materials"))
    for i, part in enumerate(geometry.parts):
        if part.material not in materials:
            raise DefinitionError(f"{path}: parts[{i}].material names an unknown material {part.material!r}; "
                                  f"materials: {sorted(materials)}")
    joints = _read_joints(root.tables("joints"), parts)
    convection = _read_convection(root.tables("convection", required=True), parts)
    _check_unique(path, "convection", [r.name for r in convection])
    zones = sorted({r.zone for r in convection})
    zone_lags_s = _read_zone_lags(root.tables("zones"), zones)
    sources = _read_sources(root.tables("sources"), parts)
    _check_unique(path, "sources", [s.name for s in sources])
    sensors = [_read_sensor(t, zones) for t in root.tables("sensors")]
    _check_unique(path, "sensors", [s.name for s in sensors])
    camera = _read_camera(root.table("camera"), parts) if "camera" in root else None
    tcp = root.table("tcp")
    tcp.check_keys({"tool_point", "workpiece_point", "tilt_probe_offset"})
    support_points = _read_supports(root.table("supports"))
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


class _PartNames:
    """The machine's part names, to check a field that names a part."""

    def __init__(self, names):
        self.names = set(names)

    def check(self, table, key, name):
        """``name`` if it is a part; else a :class:`DefinitionError` naming ``table.key`` and the value."""
        if name not in self.names:
            raise table.error(key, f"names an unknown part; parts: {sorted(self.names)}", name)
        return name


def _read_materials(mats):
    materials = {}
    for key in mats.keys():  # noqa: SIM118 - Table is not iterable
        m = mats.table(key)
        m.check_keys({"conductivity", "density", "specific_heat", "youngs_modulus", "poisson_ratio", "expansion"})
        values = {k: m.number(k, minimum=0.0, strict_minimum=True)
                  for k in ("conductivity", "density", "specific_heat", "youngs_modulus", "expansion")}
        materials[key] = Material(values["conductivity"], values["density"], values["specific_heat"],
                                  values["youngs_modulus"], m.number("poisson_ratio", minimum=0.0, maximum=0.49),
                                  values["expansion"], key)
    return materials


def _read_joints(tables, parts):
    joints = []
    for t in tables:
        t.check_keys({"parts", "conductance"})
        pair = t.strings("parts")
        if len(pair) != 2:
            raise t.error("parts", "must name exactly two parts", pair)
        for name in pair:
            parts.check(t, "parts", name)
        joints.append((pair[0], pair[1], t.number("conductance", minimum=0.0, strict_minimum=True)))
    return joints


def _read_convection(tables, parts):
    convection = []
    for t in tables:
        t.check_keys({"name", "parts", "coefficient", "zone", "facing", "inside"})
        names = t.strings("parts")
        for name in names:
            parts.check(t, "parts", name)
        convection.append(ConvectionRule(t.string("name"), tuple(names),
                                         t.number("coefficient", minimum=0.0, strict_minimum=True),
                                         t.string("zone", "room"), t.vector("facing", 3, None),
                                         t.boolean("inside", False)))
    return convection


def _read_zone_lags(tables, zones):
    zone_lags_s = {}
    for t in tables:
        t.check_keys({"name", "lag_h", "label"})
        name = t.string("name")
        if name not in zones:
            raise t.error("name", f"is not a convection zone; zones: {zones}", name)
        zone_lags_s[name] = t.number("lag_h", minimum=0.0, strict_minimum=True) * 3600.0
    return zone_lags_s


def _read_sources(tables, parts):
    sources = []
    for t in tables:
        t.check_keys({"name", "label", "part", "box", "driver", "coefficient_W", "reference", "exponent"})
        sources.append(HeatSource(t.string("name"), t.string("label", ""), parts.check(t, "part", t.string("part")),
                                  t.vector("box", 6, None), t.string("driver", choices=DRIVERS),
                                  t.number("coefficient_W", minimum=0.0), t.number("reference", 1.0,
                                                                                    minimum=0.0, strict_minimum=True),
                                  t.number("exponent", 1.0, minimum=0.0)))
    return sources


def _read_sensor(t, zones):
    t.check_keys({"name", "kind", "label", "position", "start", "end", "zone"})
    kind = t.string("kind", choices=SENSOR_KINDS)
    if kind == "strain":
        return Sensor(t.string("name"), kind, t.string("label", ""), start=t.vector("start", 3),
                      end=t.vector("end", 3))
    zone = t.string("zone", "room") if kind == "air" else None
    if zone is not None and zone not in zones:
        raise t.error("zone", f"is not a convection zone; zones: {zones}", zone)
    return Sensor(t.string("name"), kind, t.string("label", ""), position=t.vector("position", 3), zone=zone)


def _read_camera(c, parts):
    c.check_keys({"part", "face_axis", "face_value", "u_range", "v_range", "grid", "position"})
    grid = c.raw("grid")
    if not (isinstance(grid, list) and len(grid) == 2 and all(isinstance(g, int) and g > 0 for g in grid)):
        raise c.error("grid", "must be two positive integers [n_u, n_v]", grid)
    return Camera(parts.check(c, "part", c.string("part")), c.string("face_axis", choices=set("xyz")),
                  c.number("face_value"), c.vector("u_range", 2), c.vector("v_range", 2), tuple(grid),
                  c.vector("position", 3))


def _read_supports(supports):
    supports.check_keys({"kind", "points"})
    supports.string("kind", choices={"kinematic"})
    points = supports.raw("points")
    if not (isinstance(points, list) and len(points) == 3):
        raise supports.error("points", "must list three [x, y, z] points for the 3-2-1 mount", points)
    return [Table({f"points[{i}]": p}, supports.file, "supports").vector(f"points[{i}]", 3)
            for i, p in enumerate(points)]


def _check_unique(path, table, names):
    dupes = duplicates(names)
    if dupes:
        raise DefinitionError(f"{path}: {table}: duplicate names {dupes}")


def room_zone(zones: list[str]) -> str:
    """The zone whose ambient is "the room" (the scenario's ambient).

    Parameters
    ----------
    zones : list of str
        A machine's convection zones, sorted.

    Returns
    -------
    str
        ``room`` if there is one, else the first.
    """
    return "room" if "room" in zones else zones[0]
