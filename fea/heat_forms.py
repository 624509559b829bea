"""The weak forms of transient heat conduction (P1), written as scikit-fem forms.

    ρc ∂T/∂t = ∇·(k ∇T) + q        in Ω
    −k ∂T/∂n = h (T − T_amb)        on convective facets
    −k ∂T/∂n = εσ (T⁴ − T_amb⁴)     on radiating facets (kelvin)
"""
from skfem import BilinearForm, LinearForm
from skfem.helpers import dot, grad

#: Stefan–Boltzmann constant, W/(m² K⁴).
STEFAN_BOLTZMANN = 5.670374419e-8
#: Offset between °C and K.
KELVIN = 273.15

# Each form takes scikit-fem's arguments (trial u, test v, and w holding the coefficient fields), not
# values of ours, so it is documented by the integral it assembles, with units, not by numpydoc sections.


@BilinearForm
def conduction(u, v, w):
    """∫ k ∇u·∇v, with k in W/(m K)."""
    return w.conductivity * dot(grad(u), grad(v))


@BilinearForm
def capacity(u, v, w):
    """∫ ρc u v, with ρc in J/(m³ K): the consistent mass matrix."""
    return w.heat_capacity * u * v


@BilinearForm
def convection(u, v, w):
    """∫_Γ h u v, with h in W/(m² K)."""
    return w.convection_coefficient * u * v


@LinearForm
def unit_load(v, w):
    """∫ v: a load of unit density, scaled later by a time-varying input."""
    return v


@LinearForm
def weighted_load(v, w):
    """∫ f v for a given coefficient field f (e.g. h, or h·(z − z_ref))."""
    return w.weight * v


@LinearForm
def radiation_excess(v, w):
    """∫_Γ [εσ(T_K⁴ − T_amb,K⁴) − h_r (T − T_amb)] v: the part of radiation the linearised h_r misses."""
    T, T_amb = w.temperature, w.ambient
    full = w.emissivity * STEFAN_BOLTZMANN * ((T + KELVIN) ** 4 - (T_amb + KELVIN) ** 4)
    return (full - w.radiative_coefficient * (T - T_amb)) * v


@BilinearForm
def radiation_tangent(u, v, w):
    """∫_Γ (4εσ T_K³ − h_r) u v: the Jacobian of :func:`radiation_excess`."""
    slope = 4.0 * w.emissivity * STEFAN_BOLTZMANN * (w.temperature + KELVIN) ** 3
    return (slope - w.radiative_coefficient) * u * v
