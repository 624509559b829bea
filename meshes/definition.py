"""The geometry part of a machine definition (TOML): parts, their shapes and the mesh settings.

A machine file holds more than geometry (materials, sources, sensors); this
module reads only ``[mesh]`` and ``[[parts]]``.  See
``meshes/machines/vmc_ram.toml`` for the format.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

from .builder import BUILDER_VERSION, MAX_MESH_SIZE_M, MIN_MESH_SIZE_M, mm_hint
from .shapes import Box, Cylinder, HollowBox, StlPart
from .tomlspec import DefinitionError, Table, duplicates, read_toml, resolve_definition

MACHINES_DIR = Path(__file__).resolve().parent / "machines"

#: Target tetrahedron edge length when a definition gives none, m.
DEFAULT_MESH_SIZE_M = 0.045

PART_KEYS = {"name", "shape", "bounds", "wall", "ribs", "base", "axis", "radius", "length",
             "file", "scale", "offset", "material", "label"}


@dataclass(frozen=True)
class Part:
    """A named solid with a shape and (for the twin) a material name."""

    name: str
    shape: object
    material: str
    label: str = ""


@dataclass
class MachineGeometry:
    """Parts in priority order (a later part wins where two overlap) and mesh settings."""

    name: str
    parts: list
    mesh_size_m: float = DEFAULT_MESH_SIZE_M
    envelope_epsilon: float = 1e-4
    stop_energy: float = 10.0
    source: str = ""
    extras: dict = field(default_factory=dict)

    def part_names(self) -> list[str]:
        """The part names, in priority order.

        Returns
        -------
        list of str
            One name per part.
        """
        return [p.name for p in self.parts]

    def digest(self, mesh_size_m: float) -> str:
        """The cache key of the labelled mesh at ``mesh_size_m``: what the mesh is made from.

        That is the parts' names, shapes and STL contents, the mesh size and
        fTetWild settings, and :data:`~meshes.builder.BUILDER_VERSION`.

        Nothing else of a machine enters: not its name, materials, heat sources
        or joints, so a renamed or re-powered copy finds the same mesh.  Part
        names do, as the mesh stores them as region names.  The fTetWild
        version does not: a mesh made by an older fTetWild is still a valid
        mesh of the geometry, and the shipped meshes must stay found after an
        upgrade (``twin mesh --rebuild`` meshes again on purpose).

        Parameters
        ----------
        mesh_size_m : float
            Target tetrahedron edge length, m.

        Returns
        -------
        str
            SHA-256, 64 hex digits.
        """
        payload = {
            "parts": [[p.name, type(p.shape).__name__, _shape_state(p.shape)] for p in self.parts],
            "size": round(float(mesh_size_m), 9),
            "epsilon": self.envelope_epsilon,
            "stop_energy": self.stop_energy,
            "builder": BUILDER_VERSION,
        }
        text = json.dumps(payload, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()


def _shape_state(shape):
    if isinstance(shape, StlPart):
        return {"sha256": shape.file_digest(), "scale": shape.scale, "offset": shape.offset}
    return shape.__dict__


def machine_path(machine: str | Path) -> Path:
    """The TOML file of a machine.

    Parameters
    ----------
    machine : str or Path
        A shipped machine's name (``vmc_ram``) or a path.

    Returns
    -------
    Path
        The machine file.
    """
    return resolve_definition(machine, MACHINES_DIR, "machine")


def available_machines() -> list[str]:
    """The shipped machines.

    Returns
    -------
    list of str
        Names of the TOML files in ``meshes/machines``, sorted.
    """
    return sorted(p.stem for p in MACHINES_DIR.glob("*.toml"))


def parse_part(table: Table, base_dir: Path) -> Part:
    """One ``[[parts]]`` entry as a :class:`Part`.

    Parameters
    ----------
    table : Table
        The entry.
    base_dir : Path
        Folder that a relative STL ``file`` is relative to (the machine file's folder).

    Returns
    -------
    Part
        Name, shape (lengths in m), material name and label.
    """
    table.check_keys(PART_KEYS)
    name = table.string("name")
    kind = table.string("shape", choices={"box", "hollow_box", "cylinder", "stl"})
    if kind == "box":
        shape = Box(_bounds(table))
    elif kind == "hollow_box":
        bounds = _bounds(table)
        wall = table.number("wall", minimum=0.0, strict_minimum=True)
        extents = [bounds[2 * i + 1] - bounds[2 * i] for i in range(3)]
        if 2 * wall >= min(extents):
            raise table.error("wall", f"is too thick for bounds {bounds}", wall)
        ribs = table.raw("ribs", [])
        if not isinstance(ribs, list):
            raise table.error("ribs", "must be an array of [xmin, xmax, ymin, ymax, zmin, zmax] boxes", ribs)
        checked = []
        for i, rib in enumerate(ribs):
            checked.append(_bounds(Table({"rib": rib}, table.file, f"{table.path}.ribs[{i}]"), "rib"))
        shape = HollowBox(bounds, wall, tuple(checked))
    elif kind == "cylinder":
        shape = Cylinder(table.vector("base", 3), table.string("axis", choices=set("xyz")),
                         table.number("radius", minimum=0.0, strict_minimum=True),
                         table.number("length", minimum=0.0, strict_minimum=True))
    else:
        path = Path(table.string("file"))
        if not path.is_absolute():
            path = base_dir / path
        if not path.exists():
            raise table.error("file", "names an STL file that does not exist", str(path))
        shape = StlPart(str(path), table.number("scale", 1.0, minimum=0.0, strict_minimum=True),
                        table.vector("offset", 3, (0.0, 0.0, 0.0)))
    return Part(name, shape, table.string("material", "cast_iron"), table.string("label", ""))


def _bounds(table, key="bounds"):
    b = table.vector(key, 6)
    for i, axis in enumerate("xyz"):
        if b[2 * i + 1] <= b[2 * i]:
            raise table.error(key, f"must have {axis}max > {axis}min", list(b))
    return b


def load_geometry(machine: str | Path) -> MachineGeometry:
    """Read the geometry of a machine definition.

    Parameters
    ----------
    machine : str or Path
        Name of a shipped machine (``vmc_ram``) or path of a machine TOML file.

    Returns
    -------
    MachineGeometry
        The parts and mesh settings; lengths in m.

    Raises
    ------
    DefinitionError
        The file is missing or malformed, or a field holds a bad value (the message names file, field and value).
    """
    path = machine_path(machine)
    return read_geometry(read_toml(path), path)


def _mesh_size(mesh: Table) -> float:
    """``[mesh] size_m`` (m), from :data:`MIN_MESH_SIZE_M` to :data:`MAX_MESH_SIZE_M`; one over the maximum is
    refused with the hint that it reads as mm (:func:`~meshes.builder.mm_hint`): ``size_m = 35`` is 35 mm."""
    size = mesh.number("size_m", DEFAULT_MESH_SIZE_M, minimum=MIN_MESH_SIZE_M)
    if size > MAX_MESH_SIZE_M:
        raise mesh.error("size_m", f"must be ≤ {MAX_MESH_SIZE_M:g}, got {size:g}{mm_hint(size)}")
    return size


def read_geometry(root: Table, path: Path) -> MachineGeometry:
    """The geometry (``[machine].name``, ``[mesh]``, ``[[parts]]``) of an already parsed machine file.

    The one reader of a machine file's geometry: :func:`load_geometry` and the
    twin's full reader (:func:`twin.core.machine_definition.load_machine`) both
    call it, so the file is parsed once and checked by one set of rules.

    Parameters
    ----------
    root : Table
        The file's top-level table (from :func:`~meshes.tomlspec.read_toml`).
    path : Path
        The file; named in errors and kept as :attr:`MachineGeometry.source`.

    Returns
    -------
    MachineGeometry
        The parts in priority order and the mesh settings (m).
    """
    info = root.table("machine")
    name = info.string("name", Path(path).stem)
    mesh = root.table("mesh")
    mesh.check_keys({"size_m", "envelope_epsilon", "stop_energy"})
    parts = [parse_part(t, Path(path).parent) for t in root.tables("parts", required=True)]
    dupes = duplicates([p.name for p in parts])
    if dupes:
        raise DefinitionError(f"{path}: parts: duplicate part name(s) {dupes}")
    return MachineGeometry(
        name=name,
        parts=parts,
        mesh_size_m=_mesh_size(mesh),
        envelope_epsilon=mesh.number("envelope_epsilon", 1e-4, minimum=1e-6, maximum=1e-2),
        stop_energy=mesh.number("stop_energy", 10.0, minimum=3.0),
        source=str(path),
    )
