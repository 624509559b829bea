"""Isotropic thermal and elastic material properties, assigned per mesh region."""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .errors import FEAInputError, require_positive

if TYPE_CHECKING:
    from .mesh import TetMesh


#: The properties each kind of problem needs, with their units (for messages).
HEAT_PROPERTIES = {"conductivity": "W/(m K)", "density": "kg/m³", "specific_heat": "J/(kg K)"}
ELASTIC_PROPERTIES = {"youngs_modulus": "Pa", "poisson_ratio": "-", "expansion": "1/K"}


@dataclass(frozen=True)
class Material:
    """An isotropic thermo-elastic material.

    Every property is optional here; a problem requires those it uses
    (:class:`~fea.heat.HeatProblem`: conductivity, density, specific heat;
    :class:`~fea.elastic.ElasticProblem`: Young's modulus, Poisson's ratio,
    expansion), so a forgotten one is an error, never a silent default.

    Attributes
    ----------
    conductivity : W/(m K), > 0
    density : kg/m³, > 0
    specific_heat : J/(kg K), > 0
    youngs_modulus : Pa, > 0
    poisson_ratio : dimensionless, in (-1, 0.5)
    expansion : linear thermal expansion coefficient α, 1/K (finite; 0 is a valid value)
    name : label used in messages
    """

    conductivity: float | None = None
    density: float | None = None
    specific_heat: float | None = None
    youngs_modulus: float | None = None
    poisson_ratio: float | None = None
    expansion: float | None = None
    name: str = "material"

    def __post_init__(self):
        for attr in ("conductivity", "density", "specific_heat", "youngs_modulus"):
            if getattr(self, attr) is not None:
                require_positive(f"{self.name}.{attr}", getattr(self, attr))
        if self.poisson_ratio is not None:
            nu = float(self.poisson_ratio)
            if not -1.0 < nu < 0.5:
                raise FEAInputError(f"{self.name}.poisson_ratio must lie in (-1, 0.5), got {nu!r}")
        if self.expansion is not None and not np.isfinite(self.expansion):
            raise FEAInputError(f"{self.name}.expansion must be finite, got {self.expansion!r}")

    def missing(self, properties: Iterable[str]) -> list[str]:
        """The properties this material does not give.

        Parameters
        ----------
        properties : iterable of str
            Property names, e.g. ``"conductivity"``.

        Returns
        -------
        list of str
            Those that are None here.
        """
        return [p for p in properties if getattr(self, p) is None]

    @property
    def volumetric_heat_capacity(self) -> float:
        """ρ c in J/(m³ K)."""
        return self.density * self.specific_heat

    @property
    def lame(self) -> tuple[float, float]:
        """Lamé parameters (λ, μ) in Pa."""
        E, nu = self.youngs_modulus, self.poisson_ratio
        return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))

    @property
    def thermal_stress_modulus(self) -> float:
        """(3λ + 2μ) α in Pa/K: the stress per kelvin of restrained expansion."""
        lam, mu = self.lame
        return (3 * lam + 2 * mu) * self.expansion


CAST_IRON = Material(48.0, 7200.0, 500.0, 110e9, 0.26, 10.5e-6, "cast iron")
STEEL = Material(45.0, 7850.0, 470.0, 210e9, 0.30, 11.5e-6, "steel")


def region_materials(mesh: TetMesh, materials: dict[int | str, Material], required: dict[str, str],
                     problem: str) -> dict[int, Material]:
    """Materials keyed by region id, checked: every region has a :class:`Material` giving what is required.

    Parameters
    ----------
    mesh : TetMesh
        The mesh and its regions.
    materials : dict of int or str to Material
        Region id or name → material.
    required : dict of str to str
        Property name → unit (for messages).
    problem : str
        Names the problem in messages.

    Returns
    -------
    dict of int to Material
        Region id → material.
    """
    table = {}
    for key, material in materials.items():
        if not isinstance(material, Material):
            raise FEAInputError(f"material for region {key!r} is not a Material: {material!r}")
        table[mesh.region_id(key)] = material
    missing = sorted(set(mesh.region_ids().tolist()) - set(table))
    if missing:
        names = [mesh.region_names.get(r, r) for r in missing]
        raise FEAInputError(f"no material given for region(s) {names}")
    for rid, material in sorted(table.items()):
        lacking = material.missing(required)
        if lacking:
            given = ", ".join(f"{p} ({required[p]})" for p in lacking)
            raise FEAInputError(f"material {material.name!r} of region {mesh.region_names.get(rid, rid)!r} "
                                f"gives no {given}, which {problem} needs")
    return table


def per_tet(mesh: TetMesh, materials: dict[int | str, Material], attribute: str) -> np.ndarray:
    """One material property per tetrahedron.

    Parameters
    ----------
    mesh : TetMesh
        The mesh and its regions.
    materials : dict of int or str to Material
        Region id or name → material.
    attribute : str
        The property, e.g. ``"conductivity"``.

    Returns
    -------
    ndarray, shape (n_tets,)
        Its value in each tetrahedron (SI).
    """
    table = {mesh.region_id(key): material for key, material in materials.items()}
    values = {rid: getattr(mat, attribute) for rid, mat in table.items()}
    out = np.empty(mesh.n_tets)
    for rid, value in values.items():
        out[mesh.regions == rid] = value
    return out
