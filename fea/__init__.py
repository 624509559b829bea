"""A general tetrahedral finite-element solver for transient heat conduction and thermo-elasticity.

It knows meshes, regions, boundary groups and materials, not machines.
SI units throughout: m, s, W, J, Pa; temperatures in °C.
"""
from .elastic import ElasticProblem, rigid_body_modes
from .errors import FEAInputError
from .heat import HeatProblem, ThermalSystem
from .inputs import InputSchedule, SampledSeries
from .linsolve import available_backends, factorize
from .materials import CAST_IRON, STEEL, Material
from .mesh import TetMesh
from .outputs import (AxialStrain, OutputOperator, PointDisplacement, PointTemperature,
                      RelativeDisplacement, build_output_operator)
from .selection import Box, Everything, Facing, Plane, Predicate
from .transient import ThermalSolver, TransientResult
from .vtk_io import write_time_series, write_vtu

__all__ = [
    "AxialStrain", "Box", "CAST_IRON", "ElasticProblem", "Everything", "FEAInputError", "Facing",
    "HeatProblem", "InputSchedule", "Material", "OutputOperator", "Plane", "PointDisplacement",
    "PointTemperature", "Predicate", "RelativeDisplacement", "STEEL", "SampledSeries", "TetMesh",
    "ThermalSolver", "ThermalSystem", "TransientResult", "available_backends", "build_output_operator",
    "factorize", "rigid_body_modes", "write_time_series", "write_vtu",
]
