"""The C sources of the dependency-free FMU: fixed files shipped with the package plus one generated header.

The machine-independent C lives in real files under ``twin/fmu/c/`` (package data):

- ``model.c`` — the model core both APIs share (state, inputs → powers, outputs, input checks,
  initialisation, the exact zero-order-hold step, logging, FMU-state copies);
- ``fmi2.c`` / ``fmi3.c`` — the FMI 2.0 / 3.0 Co-Simulation APIs over that core (each becomes
  ``sources/thermal_twin_rom.c`` in the FMU and includes ``model.c``);
- ``fmi3_unsupported.c`` — the FMI 3.0 functions this FMU does not provide, returning ``fmi3Error``.

Only ``model_data.h`` is generated (:func:`model_data_header`): the ROM in reduced modal
coordinates and the interface.  The step is the exact zero-order hold of each first-order mode,

    z ← a ⊙ z + g ⊙ (B u),   a = e^{−λh},  g = (1 − e^{−λh})/λ,

with (a, g) computed for the first step size and recomputed whenever the master changes it.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core.machine_definition import room_zone

if TYPE_CHECKING:
    from ..rom.reduction import ReducedModel
    from .spec import Variable

C_DIR = Path(__file__).with_name("c")
#: The C files of each FMI version: the API file first (shipped as ``thermal_twin_rom.c``), then what it includes.
C_FILES = {2: ("fmi2.c", "model.c"), 3: ("fmi3.c", "model.c", "fmi3_unsupported.c")}


def c_sources(fmi_version: int) -> dict[str, str]:
    """``{file name: text}`` of the fixed C sources for FMI ``fmi_version`` (2 or 3), API file first.

    Parameters
    ----------
    fmi_version : int
        2 or 3.

    Returns
    -------
    dict of str to str
        File name → C text, in :data:`C_FILES` order.
    """
    return {name: (C_DIR / name).read_text(encoding="utf-8") for name in C_FILES[int(fmi_version)]}


def _c_array(values):
    values = np.asarray(values, float).ravel()
    return "{" + ", ".join(f"{v:.17g}" for v in values) + "}"


def _c_matrix(matrix):
    matrix = np.atleast_2d(np.asarray(matrix, float))
    return "{\n    " + ",\n    ".join(_c_array(row) for row in matrix) + "\n}"


def _c_string(s):
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


DRIVERS = {"constant": 0, "spindle": 1, "feed_x": 2, "feed_y": 3, "feed_z": 4, "feed_xy": 5, "feed_xyz": 6}


def _parameter_lines(variables, params, inputs, outputs):
    """Value references, starts and bounds of the parameters, and the first input and output references."""
    factor, t_initial = params["spindle_factor"], params["T_initial"]
    return [
        f"#define VR_T_INITIAL {params['T_initial'].vr}", f"#define VR_STEADY_START {params['steady_start'].vr}",
        f"#define VR_INPUT0 {inputs[0].vr}", f"#define VR_OUTPUT0 {outputs[0].vr}",
        f"#define T_INITIAL_START {t_initial.start:.17g}",
        f"#define T_INITIAL_MIN {t_initial.min:.17g}", f"#define T_INITIAL_MAX {t_initial.max:.17g}",
        f"#define VR_SPINDLE_FACTOR {factor.vr}",
        f"#define SPINDLE_FACTOR_START {factor.start:.17g}",
        f"#define SPINDLE_FACTOR_MIN {factor.min:.17g}",
        f"#define SPINDLE_FACTOR_MAX {factor.max:.17g}",
        f"#define STEADY_START_START {1 if params['steady_start'].start else 0}",
        f"#define VR_TIME {max(v.vr for v in variables) + 1}",
    ]


def _input_lines(rom, inputs):
    """The FMU inputs (names, starts, bounds), which ROM input each feeds, and the lagged zones' air."""
    role_index = {v.role: i for i, v in enumerate(inputs)}
    u_from = [role_index.get(n if n.startswith("ambient:") else ("gradient" if n == "ambient_gradient" else ""), -1)
              for n in rom.input_names]
    lagged = rom.lagged_zones    # their air is a state (LAG_*), driven by the room's input IN_ROOM
    lag_columns = [str(rom.input_names.index(f"ambient:{z}")) for z in lagged]
    return [
        f"#define IN_RPM {role_index['rpm']}", f"#define IN_FEED_X {role_index['feed_x']}",
        f"#define IN_FEED_Y {role_index['feed_y']}", f"#define IN_FEED_Z {role_index['feed_z']}",
        f"static const char *const INPUT_NAME[N_FMU_INPUTS] = {{{', '.join(_c_string(v.name) for v in inputs)}}};",
        f"static const double INPUT_START[N_FMU_INPUTS] = {_c_array([v.start for v in inputs])};",
        f"static const double INPUT_MIN[N_FMU_INPUTS] = {_c_array([v.min for v in inputs])};",
        f"static const double INPUT_MAX[N_FMU_INPUTS] = {_c_array([v.max for v in inputs])};",
        f"static const int U_FROM_INPUT[NU] = {{{', '.join(str(i) for i in u_from)}}};",
        f"#define IN_ROOM {role_index['ambient:' + room_zone(rom.zones)]}",
        f"#define NLAG {len(lagged)}", f"#define NLAG_ALLOC {max(len(lagged), 1)}",
        f"static const int LAG_U_INDEX[NLAG_ALLOC] = {{{', '.join(lag_columns) or '0'}}};",
        f"static const double LAG_MU[NLAG_ALLOC] = {_c_array([1.0 / rom.zone_lags_s[z] for z in lagged] or [1.0])};",
    ]


def _source_lines(rom):
    """The heat sources' input columns, drivers and speed laws (one dummy entry when there are none)."""
    src = rom.sources
    if not src:
        return ["static const int SRC_U_INDEX[1] = {0};", "static const int SRC_DRIVER[1] = {0};",
                "static const double SRC_COEF[1] = {0}, SRC_REF[1] = {1}, SRC_EXP[1] = {0};"]
    columns = ", ".join(str(rom.input_names.index("power:" + s["name"])) for s in src)
    return [
        f"static const int SRC_U_INDEX[N_SOURCES] = {{{columns}}};",
        f"static const int SRC_DRIVER[N_SOURCES] = {{{', '.join(str(DRIVERS[s['driver']]) for s in src)}}};",
        f"static const double SRC_COEF[N_SOURCES] = {_c_array([s['coefficient_W'] for s in src])};",
        f"static const double SRC_REF[N_SOURCES] = {_c_array([s['reference'] for s in src])};",
        f"static const double SRC_EXP[N_SOURCES] = {_c_array([s['exponent'] for s in src])};",
    ]


def model_data_header(rom: ReducedModel, variables: Sequence[Variable], guid: str, rows: Sequence[int]) -> str:
    """``model_data.h`` for a ROM, its FMU variables (twin.fmu.spec) and the kept output rows.

    Parameters
    ----------
    rom : ReducedModel
        The machine's ROM (all outputs).
    variables : sequence of Variable
        The FMU's variables (:func:`twin.fmu.spec.interface`).
    guid : str
        The GUID or FMI 3 instantiation token.
    rows : sequence of int
        The ROM outputs exported.

    Returns
    -------
    str
        The C header: sizes, value references, input bounds, source laws and the ROM matrices (17 digits).
    """
    params = {v.role: v for v in variables if v.causality == "parameter"}
    inputs = [v for v in variables if v.causality == "input"]
    outputs = [v for v in variables if v.causality == "output"]
    return "\n".join([
        ("/* Generated by thermal-twin: the reduced model of machine "
         f"{rom.machine!r} ({rom.method}, order {rom.order}, digest {rom.digest}). */"),
        "#ifndef MODEL_DATA_H", "#define MODEL_DATA_H",
        f"#define MODEL_GUID {_c_string(guid)}",
        f"#define NZ {rom.order}", f"#define NU {rom.n_inputs}", f"#define NY {len(rows)}",
        f"#define N_FMU_INPUTS {len(inputs)}", f"#define N_SOURCES {len(rom.sources)}",
        *_parameter_lines(variables, params, inputs, outputs),
        *_input_lines(rom, inputs),
        *_source_lines(rom),
        f"static const double LAMBDA[NZ] = {_c_array(rom.eigenvalues)};",
        f"static const double UNIFORM[NZ] = {_c_array(rom.uniform_state)};",
        f"static const double BZ[NZ][NU] = {_c_matrix(rom.input_matrix)};",
        f"static const double CZ[NY][NZ] = {_c_matrix(rom.output_matrix[rows])};",
        f"static const double DZ[NY][NU] = {_c_matrix(rom.feedthrough[rows])};",
        f"static const double OFFSET[NY] = {_c_array(rom.offset[rows])};",
        "#endif", "",
    ])
