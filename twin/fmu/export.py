"""FMI 2.0 (and, for the native kind, 3.0) Co-Simulation export of the thermal twin.

Two kinds, one interface (:mod:`twin.fmu.spec`):

``python``
    Built with PythonFMU: the slave (``thermal_twin_slave.py``) and the ROM
    matrices (``resources/rom.npz``, no pickle) travel inside the FMU; the
    importing process needs Python with numpy (and the ``twin`` package for
    ``engine="fe"``, the full finite-element model).
``native``
    C (``sources/``: ``thermal_twin_rom.c`` and ``model.c`` from the package's
    ``c/`` folder, the generated ``model_data.h``, the official FMI 2 headers)
    compiled with the machine's C compiler into
    ``binaries/linux64/thermal_twin_rom.so``; needs nothing at run time.
    ``modelDescription.xml`` lists the sources so other platforms can rebuild.
    ``fmi_version=3`` makes an FMI 3.0 FMU instead (``binaries/x86_64-linux``,
    ``sources/buildDescription.xml``).

Both integrate the ROM exactly for inputs held over each communication step
(zero-order hold, any step size) and are checked by :func:`validate` (fmpy).
Their inputs are what a plant measures (speed, feeds, the measured zones' air):
a zone whose air lags the room (the enclosure) is a state of the model
(:meth:`twin.rom.reduction.ReducedModel.plant_state_space`).
"""
from __future__ import annotations

import hashlib
import json
import re
import shutil
import subprocess
import tempfile
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal
from xml.dom.minidom import parseString
from xml.etree.ElementTree import Element, SubElement, fromstring, tostring

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.interrupt import raise_if_interrupted
from ..core.machine_definition import room_zone
from ..core.scenario import Scenario, load_scenario
from ..infra.cli_common import check_distinct
from ..rom.reduction import ReducedModel, scenario_conditions
from . import spec
from .native_source import c_sources, model_data_header
from .spec import FMUError, Variable

KINDS = ("python", "native")
ENGINES = ("rom", "fe")
NATIVE_IDENTIFIER = "thermal_twin_rom"
PYTHON_IDENTIFIER = "ThermalTwin"
C_FILE = "thermal_twin_rom.c"


def _output_rows(rom, outputs):
    if outputs is None:
        return list(range(rom.n_outputs))
    check_distinct("outputs", list(outputs), "output")    # one variable per name, or the FMU is invalid
    return [rom.output_index(n) for n in outputs]


def _subset(rom, rows):
    """A shallow view of the ROM restricted to some outputs (for the interface only)."""
    import copy

    view = copy.copy(rom)
    view.output_names = [rom.output_names[i] for i in rows]
    view.output_units = [rom.output_units[i] for i in rows]
    view.output_kinds = [rom.output_kinds[i] for i in rows]
    view.output_labels = [rom.output_labels[i] for i in rows] if rom.output_labels else []
    view.output_matrix, view.feedthrough, view.offset = rom.output_matrix[rows], rom.feedthrough[rows], rom.offset[rows]
    return view


def model_name(rom: ReducedModel, engine: str) -> str:
    """What an FMU of ``rom`` with ``engine`` runs, in words: ``krylov ROM of order 80`` or the full FE model.

    Parameters
    ----------
    rom : ReducedModel
        The machine's ROM (for the FE engine, only its machine matters).
    engine : str
        ``rom`` or ``fe``.

    Returns
    -------
    str
    """
    return "full finite-element model" if engine == "fe" else f"{rom.method} ROM of order {rom.order}"


def _description(rom, engine):
    """The model description's text; it names what the FMU runs, read back by :func:`fmu_identity`."""
    return (f"Thermal twin of machine {json.dumps(rom.machine)} ({model_name(rom, engine)}; machine digest "
            f"{rom.digest}): spindle speed, feeds and ambient in; temperatures (degC), TCP drift (um) and strains "
            "(ue) out")


#: :func:`_description` read back; the machine's name is a JSON string (any name a TOML file can give).
_IDENTITY = re.compile(r'^Thermal twin of machine (?P<machine>"(?:[^"\\]|\\.)*") \((?:full finite-element model|'
                       r"(?P<method>\w+) ROM of order (?P<order>\d+)); machine digest (?P<digest>[0-9a-f]+)\)")


@dataclass(frozen=True)
class FMUIdentity:
    """What a twin FMU runs, from its model description."""

    machine: str            #: the machine's name
    digest: str             #: :func:`twin.rom.reduction.machine_digest` of the machine the FMU was built from
    method: str | None      #: the ROM's reduction method; None for the full FE engine
    order: int | None       #: the ROM's order; None for the full FE engine

    def __str__(self):
        what = "the full FE model" if self.order is None else f"a {self.method} ROM of order {self.order}"
        return f"{what} of machine {self.machine!r} (digest {self.digest})"


def fmu_identity(path: Path | str) -> FMUIdentity:
    """The machine, ROM and machine digest an FMU exported by this version runs.

    Parameters
    ----------
    path : Path or str
        The FMU file.

    Returns
    -------
    FMUIdentity

    Raises
    ------
    FMUError
        The FMU's description is not one this version writes (another tool's FMU, or an older export).
    """
    from fmpy import read_model_description

    try:
        text = read_model_description(str(path), validate=False).description or ""
    except (KeyError, ValueError, SyntaxError, OSError, zipfile.BadZipFile) as exc:   # lxml's errors: SyntaxError
        raise FMUError(f"{path}: not an FMU ({type(exc).__name__}: {exc})") from None
    found = _IDENTITY.match(text)
    if found is None:
        raise FMUError(f"{path}: not a thermal-twin FMU of this version (its description does not name the "
                       f"machine digest: {text[:80]!r}); export it again with twin fmu export")
    order = found["order"]
    return FMUIdentity(json.loads(found["machine"]), found["digest"], found["method"],
                       None if order is None else int(order))


def export_fmu(rom: ReducedModel, out: Path | str, kind: Literal["python", "native"] = "python",
               engine: Literal["rom", "fe"] = "rom", outputs: Sequence[str] | None = None,
               default_temperature_C: float = 20.0, step_s: float = spec.DEFAULT_STEP_S,
               fe_options: dict | None = None, compiler: str = "cc", fmi_version: int = 2) -> Path:
    """Write an FMI 2.0 Co-Simulation FMU of ``rom`` to ``out``; return its path.

    The file is written as ``<out>.fmu.partial``, checked by :func:`validate` and renamed only when complete and
    valid; a failed export leaves neither file behind.  Its folder is created.

    Parameters
    ----------
    rom : the machine's :class:`~twin.rom.reduction.ReducedModel`
    out : the ``.fmu`` file
    kind : ``"python"`` (PythonFMU) or ``"native"`` (compiled C)
    engine : ``"rom"`` or, for the Python kind only, ``"fe"`` (the full model; slow)
    outputs : ROM output names to expose, each once (default: all of the ROM's)
    default_temperature_C : start value of ``T_initial`` and the ambient inputs
    step_s : the DefaultExperiment step size (any step works)
    fe_options : for ``engine="fe"``: dict(machine=name or TOML path, mesh_size_m=..., max_step_s=...)
    compiler : C compiler command for the native kind
    fmi_version : 2 (both kinds) or 3 (native kind only: FMI 3.0 Co-Simulation)

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    FMUError
        An unknown kind or engine, a combination not offered, a name not ending in ``.fmu``, a failed build
        (compiler missing or failing), or an FMU in which :func:`validate` finds a problem.
    TwinInputError
        ``outputs`` empty or naming an output twice.
    """
    _check_options(kind, engine, step_s, default_temperature_C, fmi_version)
    out = Path(out)
    if out.suffix != ".fmu":
        raise FMUError(f"{out}: the FMU file name must end in .fmu")
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = _output_rows(rom, outputs)
    view = _subset(rom, rows)
    variables = spec.interface(view, default_temperature_C)
    partial = out.with_suffix(".fmu.partial")
    try:
        if kind == "python":
            _export_python(rom, view, variables, partial, engine, step_s, fe_options or {})
        elif int(fmi_version) == 3:
            _export_native3(rom, view, variables, rows, partial, step_s, compiler)
        else:
            _export_native(rom, view, variables, rows, partial, step_s, compiler)
        problems = validate(partial)
        if problems:
            raise FMUError(f"{out}: not written: the exported FMU has {len(problems)} problem(s): "
                           + " | ".join(problems))
        raise_if_interrupted()           # no FMU after a Ctrl-C, even one a library swallowed
    except BaseException:                 # an interrupted or refused export leaves no file that looks valid
        partial.unlink(missing_ok=True)
        raise
    partial.replace(out)
    return out


def _check_options(kind, engine, step_s, default_temperature_C, fmi_version):
    """Refuse an export option the FMU cannot be built or run with (FMUError, naming the option)."""
    if kind not in KINDS:
        raise FMUError(f"unknown FMU kind {kind!r}; kinds: {list(KINDS)}")
    if not 0.0 < step_s < np.inf:
        raise FMUError(f"step_s (--step) {step_s:g}: the default experiment's step size must be a positive number "
                       "of seconds")
    low, high = spec.AMBIENT_RANGE_C
    if not low <= default_temperature_C <= high:
        raise FMUError(f"default_temperature_C (--initial-temperature) {default_temperature_C:g}: must be in "
                       f"[{low:g}, {high:g}] °C, the range of T_initial and of the ambient inputs it starts")
    if engine not in ENGINES:
        raise FMUError(f"unknown FMU engine {engine!r}; engines: {list(ENGINES)}")
    if kind == "native" and engine != "rom":
        raise FMUError("the native FMU runs the ROM only; use --kind python for --engine fe")
    if int(fmi_version) not in (2, 3) or (kind == "python" and int(fmi_version) != 2):
        raise FMUError(f"FMI version {fmi_version!r} is not available for the {kind} kind "
                       f"(python: 2; native: 2 or 3)")


# ----------------------------------------------------------------------------- model description
def _default_experiment(step_s):
    return Element("DefaultExperiment", startTime="0.0", stopTime=repr(spec.DEFAULT_STOP_S),
                   stepSize=repr(float(step_s)))


def _append_units_logs_experiment(root, variables, step_s, fmi_version=2):
    """Append UnitDefinitions, LogCategories and DefaultExperiment (step ``step_s`` in s) to ``root``.

    (and TypeDefinitions between the first two).  The native FMUs of FMI 2.0 and 3.0 declare these alike, and both
    standards place them in this order between CoSimulation and
    ModelVariables.  The categories are the ones the C sources log under.
    """
    root.append(spec.unit_definitions({v.unit for v in variables if v.unit}))
    root.append(spec.type_definitions({v.unit for v in variables if v.unit}, fmi_version))
    cats = SubElement(root, "LogCategories")
    for name, text in (("logStatusError", "errors: rejected inputs or calls"), ("logAll", "all messages")):
        SubElement(cats, "Category", name=name, description=text)
    root.append(_default_experiment(step_s))


def documentation_html(view: ReducedModel, variables: Sequence[Variable], engine: str, note: str = "") -> str:
    """``documentation/index.html``: what the FMU is, and a table of its variables (name, causality, unit,
    range, start, description).

    Parameters
    ----------
    view : ReducedModel
        The ROM restricted to the exported outputs.
    variables : sequence of Variable
        The FMU's variables.
    engine : str
        ``rom`` or ``fe``.
    note : str, default ""
        HTML appended to the description.

    Returns
    -------
    str
        The HTML page.
    """
    from html import escape

    def cell(x):
        return "" if x is None else escape(spec._fmt(x) if isinstance(x, float) else str(x))

    rows = "".join(
        f"<tr><td><code>{escape(v.name)}</code></td><td>{v.causality}</td><td>{cell(v.unit)}</td>"
        f"<td>{cell(v.min)}</td><td>{cell(v.max)}</td><td>{cell(v.start)}</td><td>{escape(v.description)}</td></tr>\n"
        for v in variables)
    return ("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>Thermal twin FMU</title></head><body>\n"
            f"<h1>Thermal twin FMU: machine {escape(view.machine)}</h1>\n<p>{escape(_description(view, engine))}."
            f" {note}</p>\n<table border=\"1\">\n<tr><th>variable</th><th>causality</th><th>unit</th><th>min</th>"
            f"<th>max</th><th>start</th><th>description</th></tr>\n{rows}</table>\n</body></html>\n")


def _pretty(root):
    return parseString(tostring(root, "UTF-8")).toprettyxml(encoding="UTF-8")


def _native_model_description(view, variables, guid, step_s):
    root = Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": f"thermal_twin_{view.machine}", "guid": guid,
        "description": _description(view, "rom"), "generationTool": "thermal-twin",
        "variableNamingConvention": "structured", "numberOfEventIndicators": "0"})
    cs = SubElement(root, "CoSimulation", {
        "modelIdentifier": NATIVE_IDENTIFIER, "canHandleVariableCommunicationStepSize": "true",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
        "canNotUseMemoryManagementFunctions": "false", "canInterpolateInputs": "false"})
    files = SubElement(cs, "SourceFiles")
    SubElement(files, "File", name=C_FILE)
    _append_units_logs_experiment(root, variables, step_s)
    mv = SubElement(root, "ModelVariables")
    for v in variables:
        mv.append(spec.scalar_variable(v))
    root.append(spec.model_structure(variables))
    return _pretty(root)


def _patch_python_description(xml_bytes, view, variables, step_s, guid, engine):
    """Declare units, ranges, InitialUnknowns, the default experiment and what ``engine`` runs in PythonFMU's
    description.

    ``guid`` replaces PythonFMU's (a new uuid1 on every build) with one derived from the content.
    """
    root = fromstring(xml_bytes)
    root.set("description", _description(view, engine))
    root.set("guid", guid)
    by_name = {v.name: v for v in variables}
    mv = root.find("ModelVariables")
    for sv in mv.findall("ScalarVariable"):
        v = by_name[sv.get("name")]
        if int(sv.get("valueReference")) != v.vr:
            raise FMUError(f"PythonFMU numbered {v.name!r} {sv.get('valueReference')}, expected {v.vr}")
        sv.set("description", v.description)
        child = sv.find(v.type)
        if v.type == "Real":
            for key, value in spec.real_type_attributes(v).items():
                child.set(key, value)
            for key in ("min", "max"):
                value = getattr(v, key)
                if value is not None:
                    child.set(key, spec._fmt(value))
    cs = root.find("CoSimulation")       # the slave saves and restores its whole state (model, lags, inputs)
    cs.set("canGetAndSetFMUstate", "true")
    cs.set("canSerializeFMUstate", "true")
    children = list(root)
    position = [c.tag for c in children].index("CoSimulation") + 1
    root.insert(position, spec.unit_definitions({v.unit for v in variables if v.unit}))
    root.insert(position + 1, spec.type_definitions({v.unit for v in variables if v.unit}))
    old = root.find("DefaultExperiment")
    if old is not None:
        root.remove(old)
    root.insert([c.tag for c in list(root)].index("ModelVariables"), _default_experiment(step_s))
    root.remove(root.find("ModelStructure"))
    root.append(spec.model_structure(variables))
    return _pretty(root)


# ----------------------------------------------------------------------------- python kind
def _export_python(rom, view, variables, partial, engine, step_s, fe_options):
    """Build the Python FMU into the file ``partial``."""
    from pythonfmu.builder import FmuBuilder

    config = {"engine": engine, "description": _description(view, engine), "outputs": view.output_names,
              "room": room_zone(rom.zones),
              "lags": [{"zone": z, "tau_s": float(rom.zone_lags_s[z])} for z in rom.lagged_zones],
              "variables": [dict(name=v.name, vr=v.vr, type=v.type, causality=v.causality,
                                 variability=v.variability, description=v.description, start=v.start,
                                 initial=v.initial, min=v.min, max=v.max, role=v.role) for v in variables]}
    if engine == "fe":
        if "machine" not in fe_options:
            raise FMUError("engine 'fe' needs fe_options['machine'] (machine name or TOML path)")
        config["fe"] = dict(machine=str(fe_options["machine"]), mesh_size_m=fe_options.get("mesh_size_m"),
                            max_step_s=float(fe_options.get("max_step_s", 60.0)), sources=rom.sources)
    with tempfile.TemporaryDirectory(prefix="twin_fmu_") as tmp:
        tmp = Path(tmp)
        script = tmp / "thermal_twin_slave.py"
        shutil.copy2(Path(__file__).with_name("thermal_twin_slave.py"), script)
        (tmp / "interface.json").write_text(json.dumps(config, indent=1), encoding="utf-8")
        files = [tmp / "interface.json"]
        if engine == "rom":
            rom.save(tmp / "rom.npz")
            files.append(tmp / "rom.npz")
        built = Path(FmuBuilder.build_FMU(script, dest=tmp / "build", project_files=files))
        # A stable GUID: the ROM, the kind, the slave's code and its configuration (not the build time).
        content = hashlib.sha256(script.read_bytes() + json.dumps(config, sort_keys=True).encode()).hexdigest()
        guid = spec.guid(view, f"python|{engine}|{content}")
        with zipfile.ZipFile(built) as zin, zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zout:
            for item in zin.infolist():
                data = zin.read(item.filename)
                if item.filename == "modelDescription.xml":
                    data = _patch_python_description(data, view, variables, step_s, guid, engine)
                zout.writestr(item.filename, data)
            if "documentation/index.html" not in zin.namelist():
                zout.writestr("documentation/index.html", documentation_html(view, variables, engine))


# ----------------------------------------------------------------------------- native kind
def fmi_headers_dir() -> Path:
    """The official FMI 2 headers shipped with fmpy.

    Returns
    -------
    Path
        fmpy's ``c-code`` folder (it holds the FMI 3 headers too).

    Raises
    ------
    FMUError
        If the headers are missing.
    """
    import fmpy

    path = Path(fmpy.__file__).parent / "c-code"
    if not (path / "fmi2Functions.h").exists():
        raise FMUError(f"the FMI 2 headers are not in {path}; reinstall fmpy")
    return path


FMI2_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")


def write_native_sources(rom: ReducedModel, variables: Sequence[Variable], rows: Sequence[int],
                         folder: Path | str, guid: str, fmi_version: int = 2) -> Path:
    """Write the C sources of the native FMU into ``folder``; return the C file to compile.

    The official FMI headers (from fmpy), the generated ``model_data.h``, and the package's
    fixed C files (:mod:`twin.fmu.native_source`), the API file renamed ``thermal_twin_rom.c``.

    Parameters
    ----------
    rom : ReducedModel
        The machine's ROM.
    variables : sequence of Variable
        The FMU's variables.
    rows : sequence of int
        The ROM outputs exported.
    folder : Path or str
        Created if needed.
    guid : str
        The GUID (FMI 2) or instantiation token (FMI 3).
    fmi_version : int, default 2
        2 or 3.

    Returns
    -------
    Path
        ``folder/thermal_twin_rom.c``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for name in (FMI2_HEADERS if int(fmi_version) == 2 else FMI3_HEADERS):
        shutil.copy2(fmi_headers_dir() / name, folder / name)
    (folder / "model_data.h").write_text(model_data_header(rom, variables, guid, rows), encoding="utf-8")
    for i, (name, text) in enumerate(c_sources(fmi_version).items()):
        (folder / (C_FILE if i == 0 else name)).write_text(text, encoding="utf-8")
    return folder / C_FILE


def compile_native(source: Path | str, library: Path | str, compiler: str = "cc") -> Path | str:
    """Compile the C source into a shared library; raise :class:`FMUError` with the compiler's message.

    Parameters
    ----------
    source : Path or str
        The C file; its folder is on the include path.
    library : Path or str
        The shared library to write.
    compiler : str, default "cc"
        The C compiler command.

    Returns
    -------
    Path or str
        ``library``.
    """
    cmd = [compiler, "-shared", "-fPIC", "-O2", "-std=c99", "-Wall", "-I", str(Path(source).parent), str(source),
           "-o", str(library), "-lm"]
    try:
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    except FileNotFoundError:
        raise FMUError(f"C compiler {compiler!r} not found; install gcc or pass --compiler") from None
    if run.returncode != 0:
        raise FMUError(f"compiling the native FMU failed ({' '.join(cmd)}):\n{run.stderr.strip()}")
    return library


def _zip_fmu(folder, partial):
    """Zip every file below ``folder`` (paths relative to it) into ``partial`` (renamed by :func:`export_fmu`).

    Files are added in sorted order, so the archive lists them the same way on every run.
    """
    with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as z:
        for f in sorted(folder.rglob("*")):
            if f.is_file():
                z.write(f, f.relative_to(folder).as_posix())


def _export_native(rom, view, variables, rows, partial, step_s, compiler):
    guid = spec.guid(view, "native")
    with tempfile.TemporaryDirectory(prefix="twin_fmu_native_") as tmp:
        tmp = Path(tmp)
        source = write_native_sources(rom, variables, rows, tmp / "sources", guid)
        (tmp / "binaries" / "linux64").mkdir(parents=True)
        compile_native(source, tmp / "binaries" / "linux64" / f"{NATIVE_IDENTIFIER}.so", compiler)
        (tmp / "modelDescription.xml").write_bytes(_native_model_description(view, variables, guid, step_s))
        (tmp / "documentation").mkdir()
        (tmp / "documentation" / "index.html").write_text(documentation_html(view, variables, "rom", (
            "Rebuild on another platform: <code>cc -shared -fPIC -O2 -I sources sources/" + C_FILE +
            " -o binaries/&lt;platform&gt;/" + NATIVE_IDENTIFIER + ".&lt;so|dll|dylib&gt; -lm</code>.")),
            encoding="utf-8")
        _zip_fmu(tmp, partial)


# ----------------------------------------------------------------------------- native kind, FMI 3.0
FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
FMI3_PLATFORM = "x86_64-linux"


def _native_model_description3(view, variables, token, step_s):
    root = Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": f"thermal_twin_{view.machine}", "instantiationToken": token,
        "description": _description(view, "rom"), "generationTool": "thermal-twin",
        "variableNamingConvention": "structured"})
    SubElement(root, "CoSimulation", {
        "modelIdentifier": NATIVE_IDENTIFIER, "canHandleVariableCommunicationStepSize": "true",
        "canGetAndSetFMUState": "true", "canSerializeFMUState": "true", "hasEventMode": "false",
        "providesIntermediateUpdate": "false", "canReturnEarlyAfterIntermediateUpdate": "false"})
    _append_units_logs_experiment(root, variables, step_s, fmi_version=3)
    mv = SubElement(root, "ModelVariables")
    SubElement(mv, "Float64", name="time", valueReference=str(max(v.vr for v in variables) + 1),
               causality="independent", variability="continuous", description="simulation time")
    for v in variables:
        attrib = {"name": v.name, "valueReference": str(v.vr), "description": v.description,
                  "causality": v.causality, "variability": v.variability}
        if v.initial:
            attrib["initial"] = v.initial
        if v.type == "Real":
            attrib.update(spec.real_type_attributes(v))
            for key in ("min", "max"):
                value = getattr(v, key)
                if value is not None:
                    attrib[key] = spec._fmt(value)
            if v.start is not None:
                attrib["start"] = spec._fmt(v.start)
            SubElement(mv, "Float64", attrib)
        else:
            attrib["start"] = "true" if v.start else "false"
            SubElement(mv, "Boolean", attrib)
    ms = SubElement(root, "ModelStructure")
    outputs = [v for v in variables if v.causality == "output"]
    vr = {v.name: v.vr for v in variables}
    for v in outputs:
        SubElement(ms, "Output", valueReference=str(v.vr),
                   dependencies=" ".join(str(vr[n]) for n in v.depends_on))
    for v in outputs:
        SubElement(ms, "InitialUnknown", valueReference=str(v.vr))
    return _pretty(root)


def _build_description3():
    root = Element("fmiBuildDescription", fmiVersion="3.0")
    config = SubElement(root, "BuildConfiguration", modelIdentifier=NATIVE_IDENTIFIER)
    files = SubElement(config, "SourceFileSet", language="C99")
    SubElement(files, "SourceFile", name=C_FILE)
    SubElement(config, "Library", name="m", description="the C maths library (libm)")
    return _pretty(root)


def _export_native3(rom, view, variables, rows, partial, step_s, compiler):
    token = spec.guid(view, "native-fmi3")
    with tempfile.TemporaryDirectory(prefix="twin_fmu_native3_") as tmp:
        tmp = Path(tmp)
        src = tmp / "sources"
        write_native_sources(rom, variables, rows, src, token, fmi_version=3)
        (src / "buildDescription.xml").write_bytes(_build_description3())
        (tmp / "binaries" / FMI3_PLATFORM).mkdir(parents=True)
        compile_native(src / C_FILE, tmp / "binaries" / FMI3_PLATFORM / f"{NATIVE_IDENTIFIER}.so", compiler)
        (tmp / "modelDescription.xml").write_bytes(_native_model_description3(view, variables, token, step_s))
        (tmp / "documentation").mkdir()
        (tmp / "documentation" / "index.html").write_text(documentation_html(view, variables, "rom"), encoding="utf-8")
        _zip_fmu(tmp, partial)


# ----------------------------------------------------------------------------- checks and runs
def validate(path: Path | str) -> list[str]:
    """Problems fmpy finds in the FMU, else the parts it lacks to run here (:func:`missing_parts`); empty when valid.

    Parameters
    ----------
    path : Path or str
        The FMU.

    Returns
    -------
    list of str
    """
    from fmpy.validation import validate_fmu

    problems = list(validate_fmu(str(path)))
    return problems or missing_parts(path)


#: the Python slave's variables and engine, in the FMU archive
INTERFACE = "resources/interface.json"


def missing_parts(path: Path | str) -> list[str]:
    """What a readable FMU needs to run on this platform and does not hold, one line each (empty when complete).

    Its shared library for this platform (fmpy's ``binaries/<platform>/<modelIdentifier>.so`` …) and, for a
    thermal-twin Python FMU, the slave, its interface and, for the ROM engine, the ROM data.

    Parameters
    ----------
    path : Path or str
        The FMU (its model description must read).

    Returns
    -------
    list of str
        ``"<member> is missing: <what it is>"``, or ``"<member> is unreadable: …"``.
    """
    from fmpy import (
        platform,
        platform_tuple,
        read_model_description,
        sharedLibraryExtension,
    )

    md = read_model_description(str(path), validate=False)
    folder = platform_tuple if md.fmiVersion.startswith("3") else platform
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
        rebuild = "; its sources/ can rebuild it" if any(n.startswith("sources/") for n in names) else ""
        needed = {f"binaries/{folder}/{kind.modelIdentifier}{sharedLibraryExtension}":
                  f"the shared library for this platform ({folder}){rebuild}"
                  for kind in (md.coSimulation, md.modelExchange) if kind is not None}
        python = md.coSimulation is not None and md.coSimulation.modelIdentifier == PYTHON_IDENTIFIER
        if python:
            needed.update(_python_resources(z, names))
        unreadable = [f"{INTERFACE} is unreadable: not a JSON object naming the slave's engine"] \
            if python and INTERFACE in names and _engine(z) is None else []
    return [f"{name} is missing: {what}" for name, what in needed.items() if name not in names] + unreadable


def _python_resources(z, names):
    """Member → what it is, for the resources the Python slave of the open FMU archive ``z`` reads."""
    needed = {"resources/slavemodule.txt": "PythonFMU's name of the slave module",
              "resources/thermal_twin_slave.py": "the Python slave",
              INTERFACE: "the slave's variables and engine"}
    if INTERFACE in names and _engine(z) == "rom":
        needed["resources/rom.npz"] = "the reduced model the slave runs"
    return needed


def _engine(z):
    """The engine the Python slave's interface names (``rom``, ``fe``), or None when it names none or does not read."""
    try:
        interface = json.loads(z.read(INTERFACE))
    except ValueError:          # not JSON, or not UTF-8
        return None
    return interface.get("engine") if isinstance(interface, dict) else None


def input_table(rom: ReducedModel, scenario: Scenario | Path | str, times: ArrayLike | None = None) -> np.ndarray:
    """A structured array (``time`` + FMU input names) driving the FMU through a scenario.

    Two rows hold the conditions at initialisation — those at t₀, with the
    machine idle for a steady start (as :func:`twin.core.simulate.simulate` does) —
    at t₀ − 1 s (before the start, only so that fmpy sees the event at t₀) and
    at t₀.  A row at the same time t₀ follows — an input event, which fmpy
    applies after initialisation, for the first step — and then row i (at tᵢ)
    holds what the master sets for the step to tᵢ₊₁: the scenario's conditions
    at tᵢ₊₁ (left limits, :func:`twin.rom.reduction.held_conditions`).  So the FMU
    reproduces :func:`simulate_table` exactly, initial state and feedthrough included.
    Only the measured zones have a column: the FMU lags the enclosure's air itself,
    from the room's (a scenario event that reaches a lagged zone but not the room
    cannot be fed to it and is refused).

    Parameters
    ----------
    rom : ReducedModel
        The machine's ROM.
    scenario : Scenario, Path or str
        The scenario (object, TOML path or name).
    times : array_like, optional
        Step times, s (default the scenario's samples).

    Returns
    -------
    ndarray
        Structured, ``len(times) + 2`` rows: ``time`` (s), ``spindle_speed`` (rpm), ``feed_x/y/z`` (mm/min),
        ``ambient_<zone>`` (°C) of the measured zones, ``ambient_gradient`` (K/m).

    Raises
    ------
    FMUError
        For an event that reaches a lagged zone but not the room.
    """
    scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    for i, ev in enumerate(scenario.events):
        inside = [z for z in (ev.zones or ()) if z in rom.lagged_zones]
        if inside and room_zone(rom.zones) not in ev.zones:
            raise FMUError(f"{scenario.source}: events[{i}] reaches zone(s) {inside} but not the room: the FMU's "
                           f"{inside[0]!r} air follows the room, so no input can drive it")
    t = scenario.times() if times is None else np.asarray(times, float)
    cond = scenario_conditions(scenario, rom.measured_zones, t)    # the lagged zones' air is a state of the FMU
    rpm, feeds, ambient = cond.spindle_rpm, cond.feed_mm_min, cond.ambient_C
    # at initialisation: the conditions a steady start is computed for, else those at t₀
    rpm0, feed0, amb0 = (scenario.idle_start({z: a[:1] for z, a in ambient.items()})
                         if scenario.initial["kind"] == "steady" else (rpm, feeds, ambient))

    def held(values, first):
        return np.r_[first, first, values[1:], values[-1]]

    cols = [("time", np.r_[t[0] - 1.0, t[0], t]), ("spindle_speed", held(rpm, rpm0[0]))]
    cols += [(f"feed_{a}", held(feeds[a], feed0[a][0])) for a in "xyz"]
    cols += [(f"ambient_{z}", held(ambient[z], amb0[z][0])) for z in rom.measured_zones]
    cols += [("ambient_gradient", held(cond.gradient_K_per_m, cond.gradient_K_per_m[0]))]
    table = np.zeros(len(t) + 2, dtype=[(name, np.float64) for name, _ in cols])
    for name, values in cols:
        table[name] = values
    return table


def scenario_start(rom: ReducedModel, scenario: Scenario | Path | str) -> tuple[float, bool]:
    """FMU start parameters ``(T_initial, steady_start)`` for a scenario's initial state.

    A steady start is the steady state for the inputs set at initialisation
    (the first row of :func:`input_table`).

    Parameters
    ----------
    rom : ReducedModel
        The machine's ROM.
    scenario : Scenario, Path or str
        The scenario (object, TOML path or name).

    Returns
    -------
    T_initial : float
        °C: the scenario's uniform temperature, else the room's air at t = 0 (20.0, unused, for a steady start).
    steady_start : bool
    """
    scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    init = scenario.initial
    if init["kind"] == "steady":
        return 20.0, True
    value = init.get("temperature_C")
    if value is None:
        value = scenario_conditions(scenario, rom.zones, [0.0], rom.zone_lags_s).ambient_C[room_zone(rom.zones)][0]
    return float(value), False


def table_inputs(rom: ReducedModel, table: np.ndarray) -> NDArray[np.float64]:
    """Plant inputs (k, m_p) of the ROM (``rom.plant_input_names``) for an FMU input table.

    Parameters
    ----------
    rom : ReducedModel
        The machine's ROM.
    table : ndarray
        Structured input table (see :func:`input_table`).

    Returns
    -------
    ndarray, shape (k, m_p)
        Plant inputs (°C, K/m, W).
    """
    feeds = {a: table[f"feed_{a}"] for a in "xyz"}
    ambient = {z: table[f"ambient_{z}"] for z in rom.measured_zones}
    return rom.plant_inputs_from_conditions(table["spindle_speed"], feeds, ambient, table["ambient_gradient"])


def _start_index(t):
    """Index of the initialisation row: the row before the first repeated time, else 0."""
    same = np.flatnonzero(np.diff(t) == 0)
    return int(same[0]) if len(same) else 0


def simulate_table(rom: ReducedModel, table: np.ndarray, T_initial: float = 20.0, steady_start: bool = False,
                   outputs: Sequence[str] | None = None) -> NDArray[np.float64]:
    """The in-process twin (ROM, ZOH) on an FMU input table: outputs (k, p) at the table's distinct times.

    Semantics of fmpy's co-simulation loop: a row at the same time as the one
    before it is an input event (the first row initialises, the second drives
    the first step); row i is held over [tᵢ, tᵢ₊₁); an output at tᵢ uses the
    inputs last set (those of the step just made).

    Parameters
    ----------
    rom : ReducedModel
        The machine's ROM.
    table : ndarray
        Structured input table (see :func:`input_table`).
    T_initial : float, default 20.0
        Uniform start temperature, °C (without ``steady_start``).
    steady_start : bool, default False
        Start in equilibrium with the initialisation row.
    outputs : sequence of str, optional
        ROM outputs returned (default all).

    Returns
    -------
    ndarray, shape (k, p)
        Outputs in their units (°C, µm, µε).
    """
    t = np.asarray(table["time"], float)
    U = table_inputs(rom, table)
    k = _start_index(t)
    init = U[k]
    if k + 1 < len(t) and t[k + 1] == t[k]:
        k += 1
    t, U = t[k:], U[k:]
    room = rom.plant_input_names.index(f"ambient:{room_zone(rom.zones)}")
    x0 = rom.plant_steady_state(init) if steady_start else rom.plant_uniform(T_initial, init[room])
    X = rom.plant_states(t, U, x0)
    applied = np.vstack([init[None, :], U[:-1]])
    return rom.plant_outputs(X, applied)[:, _output_rows(rom, outputs)]


def simulate(path: Path | str, table: np.ndarray, T_initial: float = 20.0, steady_start: bool = False,
             outputs: Sequence[str] | None = None, **kwargs: object) -> np.ndarray:
    """Run an FMU in fmpy on an input table (output interval = the table's step); return fmpy's result.

    Parameters
    ----------
    path : Path or str
        The FMU.
    table : ndarray
        Structured input table (see :func:`input_table`).
    T_initial : float, default 20.0
        Start value of ``T_initial``, °C.
    steady_start : bool, default False
        Start value of ``steady_start``.
    outputs : sequence of str, optional
        Outputs recorded (default fmpy's: all).
    **kwargs
        Passed to :func:`fmpy.simulate_fmu` (by default its log goes to the error message only, with debug
        logging on, as a Python FMU forwards its messages only then).

    Returns
    -------
    ndarray
        Structured: ``time`` (s) and one field per output (°C, µm, µε).

    Raises
    ------
    FMUError
        The FMU refused a call (a value out of its range, say), with the errors it logged.
    """
    from fmpy import simulate_fmu
    from fmpy.fmi1 import FMICallException

    errors = []

    def keep_errors(*args):               # FMI 2 passes (env, instance, status, category, message), FMI 3 no instance
        status, message = args[-3], args[-1]
        if status >= 3:                   # Error, Fatal: what the error message needs
            errors.append(" ".join(message.decode(errors="replace").split()))

    kwargs = {"debug_logging": True, "logger": keep_errors, **kwargs}
    t = np.asarray(table["time"], float)
    t = np.unique(t[_start_index(t):])
    step = float(t[1] - t[0])
    try:
        return simulate_fmu(str(path), start_time=float(t[0]), stop_time=float(t[-1]), output_interval=step,
                            input=table, output=outputs, validate=True,
                            start_values={"T_initial": T_initial, "steady_start": bool(steady_start)}, **kwargs)
    except FMICallException as exc:
        raise FMUError(f"{path}: {exc}" + (" The FMU logged: " + " | ".join(errors) if errors else "")) from None
