"""Isotropic thermal and elastic material properties, assigned per mesh region."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import FEAInputError, require_positive


@dataclass(frozen=True)
class Material:
    """An isotropic thermo-elastic material.

    Attributes
    ----------
    conductivity : W/(m K)
    density : kg/m³
    specific_heat : J/(kg K)
    youngs_modulus : Pa
    poisson_ratio : dimensionless, in (-1, 0.5)
    expansion : linear thermal expansion coefficient α, 1/K
    name : label used in messages
    """

    conductivity: float
    density: float
    specific_heat: float
    youngs_modulus: float = 1.0
    poisson_ratio: float = 0.0
    expansion: float = 0.0
    name: str = "material"

    def __post_init__(self):
        for attr in ("conductivity", "density", "specific_heat", "youngs_modulus"):
            require_positive(f"{self.name}.{attr}", getattr(self, attr))
        nu = float(self.poisson_ratio)
        if not -1.0 < nu < 0.5:
            raise FEAInputError(f"{self.name}.poisson_ratio must lie in (-1, 0.5), got {nu!r}")
        if not np.isfinite(self.expansion):
            raise FEAInputError(f"{self.name}.expansion must be finite, got {self.expansion!r}")

    @property
    def volumetric_heat_capacity(self):
        """ρ c in J/(m³ K)."""
        return self.density * self.specific_heat

    @property
    def lame(self):
        """Lamé parameters (λ, μ) in Pa."""
        E, nu = self.youngs_modulus, self.poisson_ratio
        return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))

    @property
    def thermal_stress_modulus(self):
        """(3λ + 2μ) α in Pa/K: the stress per kelvin of restrained expansion."""
        lam, mu = self.lame
        return (3 * lam + 2 * mu) * self.expansion


CAST_IRON = Material(48.0, 7200.0, 500.0, 110e9, 0.26, 10.5e-6, "cast iron")
STEEL = Material(45.0, 7850.0, 470.0, 210e9, 0.30, 11.5e-6, "steel")


def per_tet(mesh, materials, attribute):
    """Array of one material attribute per tetrahedron.

    ``materials`` maps region ids or region names to :class:`Material`; every
    region of the mesh must have one.
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
    values = {rid: getattr(mat, attribute) for rid, mat in table.items()}
    out = np.empty(mesh.n_tets)
    for rid, value in values.items():
        out[mesh.regions == rid] = value
    return out
