"""The functions behind the CLI's ``run``, ``mesh`` and ``report`` commands (callable from Python too)."""
from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import fea
from meshes.builder import build_mesh, mesh_statistics
from meshes.cachefiles import SHIPPED_CACHE, sidecar
from meshes.definition import load_geometry

from ..core.dataset import Dataset, sidecar_path
from ..core.deformation import DisplacementJob
from ..core.machine import build_machine, convection_summary
from ..core.machine_definition import load_machine
from ..core.scenario import load_scenario
from ..core.simulate import simulate
from ..infra import plots
from ..infra.outdir import atomic_directory, check_output_folder
from ..infra.render import render_deformed_views, render_machine, render_temperature_views, render_thermal_image
from .summary import format_summary, run_summary


@dataclass
class RunOutput:
    """What :func:`run_scenario` wrote: the result folder, the run summary and the dataset CSV."""

    out_dir: Path
    summary: dict
    dataset_path: Path


def run_scenario(scenario: str | Path, machine: str | Path | None = None, mesh_size_m: float | None = None,
                 out_dir: str | Path | None = None, fields: bool = False,
                 progress: Callable[[int, int], None] | None = None, camera: bool | None = None,
                 overwrite: bool = False, views: bool = True) -> RunOutput:
    """Simulate a scenario and write the dataset, plots, summary (and fields/images) to ``out_dir``.

    Parameters
    ----------
    scenario : str or Path
        Scenario name or path.
    machine : str or Path, optional
        Machine name or path overriding the scenario's.
    mesh_size_m : float, optional
        Mesh size override, m.
    out_dir : str or Path, optional
        Result folder (default ``runs/<scenario>``); checked before the
        simulation, written atomically (see :mod:`twin.infra.outdir`).
    fields : bool
        Also write VTK temperature fields at the scenario's ``fields_at_h`` times.
    progress : callable, optional
        ``progress(done, total)``.
    camera : bool, optional
        Record the camera spots in the dataset (default: as the scenario says).
    overwrite : bool
        Write into a non-empty folder that is not a twin output (its files are kept).
    views : bool
        At the scenario's ``camera_images_at_h`` times, also render 3-D views of the temperature
        field and of the deformed shape (one elastic solve per time, set up in a worker during the run).

    Returns
    -------
    RunOutput
        The folder, the summary (drift in µm, temperatures in °C) and the dataset path.
    """
    sc = load_scenario(scenario)
    if machine is not None:
        sc.machine = str(machine)
    if camera is not None:
        sc.record_camera = bool(camera)
    definition = load_machine(machine) if machine is not None else sc.machine_definition()
    sc.check_machine(definition)      # fail on bad speeds before any meshing
    out_dir = Path(out_dir or Path("runs") / sc.name)
    check_output_folder(out_dir, overwrite, inputs=(sc.source, definition.source))
    model = build_machine(sc.machine, mesh_size_m, definition=definition)
    deformation = DisplacementJob(model) if views and sc.camera_image_times_s else None
    try:
        result = simulate(sc, model, fields=bool(fields), progress=progress, step_error=True)
        view_fields = {t: result.fields[t] for t in sc.camera_image_times_s if t in result.fields}
        if deformation is not None:
            deformation.submit(view_fields)
        summary = _write_run(sc, model, result, out_dir, overwrite, fields, view_fields, deformation)
    finally:
        if deformation is not None:
            deformation.cancel()        # only stops a worker still running (after an error)
    return RunOutput(out_dir, summary, out_dir / f"{sc.name}.csv")


def _write_run(sc, model, result, out_dir, overwrite, fields, view_fields, deformation):
    """Write the result folder of :func:`run_scenario`; returns the run summary."""
    summary = run_summary(result.dataset, result.wall_seconds,
                          float(np.linalg.norm(model.definition.tilt_probe_offset)), sc.iso_test)
    with atomic_directory(out_dir, overwrite) as tmp:
        data_path = tmp / f"{sc.name}.csv"
        result.dataset.write(data_path)
        plots.plot_temperatures(result.dataset, tmp / "temperatures.png")
        plots.plot_drift(result.dataset, tmp / "drift.png")
        plots.plot_strains(result.dataset, tmp / "strains.png")
        if model.definition.camera is not None:
            for t, T in view_fields.items():
                render_thermal_image(model, T, tmp / f"thermal_{t / 3600:.2f}h.png",
                                     title=f"{sc.name}  t = {t / 3600:.2f} h")
        if fields and result.fields:
            frames = {t: {"temperature_degC": model.thermal.nodal_field(T)} for t, T in result.fields.items()}
            fea.write_time_series(tmp / "fields.pvd", model.mesh, frames)
        (tmp / "summary.json").write_text(json.dumps(summary, indent=1))
        (tmp / "summary.md").write_text(format_summary(summary))
        if deformation is not None:          # the worker solves the elastic fields meanwhile
            render_temperature_views(model, view_fields, tmp, sc.name)
            render_deformed_views(model, deformation.result(), tmp, sc.name)
    return summary


def report_dataset(path: str | Path, out_dir: str | Path | None = None, column_map: dict[str, str] | None = None,
                   nan_policy: str = "error", probe_spacing_m: float = 0.1, iso_test: str | None = None,
                   overwrite: bool = False) -> tuple[dict, Path]:
    """Plots and a readable summary of an existing dataset (a twin run or measured data).

    Measured CSVs without a sidecar go through the validated import; the
    import report (gaps, NaNs) is written beside the summary.

    Parameters
    ----------
    path : str or Path
        The dataset CSV.
    out_dir : str or Path, optional
        Result folder (default ``runs/report_<name>``).
    column_map, nan_policy
        As :meth:`~twin.core.dataset.Dataset.from_measured_csv`.
    probe_spacing_m : float
        Distance of the two Y probes, m (for the tilt).
    iso_test : str, optional
        ``"spindle"`` or ``"etve"``.
    overwrite : bool
        As in :func:`run_scenario`.

    Returns
    -------
    summary : dict
        From :func:`~twin.run.summary.run_summary`.
    out_dir : Path
        The result folder.
    """
    path = Path(path)
    out_dir = Path(out_dir or Path("runs") / f"report_{path.stem}")
    check_output_folder(out_dir, overwrite, inputs=(path, sidecar_path(path)))
    if column_map or not sidecar_path(path).exists():
        dataset = Dataset.from_measured_csv(path, column_map=column_map, nan_policy=nan_policy)
    else:
        dataset = Dataset.read(path)
    dataset.metadata.setdefault("scenario", path.stem)
    summary = run_summary(dataset, None, probe_spacing_m, iso_test)
    with atomic_directory(out_dir, overwrite) as tmp:
        if dataset.names_of_kind("temperature", "air"):
            plots.plot_temperatures(dataset, tmp / "temperatures.png")
        if dataset.names_of_kind("displacement"):
            plots.plot_drift(dataset, tmp / "drift.png")
        plots.plot_strains(dataset, tmp / "strains.png")
        (tmp / "summary.json").write_text(json.dumps(summary, indent=1))
        (tmp / "summary.md").write_text(format_summary(summary))
        if "import" in dataset.metadata:
            (tmp / "import_report.json").write_text(json.dumps(dataset.metadata["import"], indent=1))
    return summary, out_dir


def mesh_machine(machine: str | Path = "vmc_ram", mesh_size_m: float | None = None,
                 out_dir: str | Path | None = None, rebuild: bool = False, ship: bool = False,
                 overwrite: bool = False) -> tuple[dict, Path]:
    """Build (or load) and describe a machine's mesh; write statistics and an off-screen render.

    Parameters
    ----------
    machine : str or Path
        Machine name or path.
    mesh_size_m : float, optional
        Target tetrahedron edge length, m (default: the definition's).
    out_dir : str or Path, optional
        Folder for statistics and render (default ``runs/mesh_<machine>``).
    rebuild : bool
        Mesh again even if cached.
    ship : bool
        Copy the mesh and the machine's output operator into the package's
        shipped cache (``meshes/cache``), for committing with the definition
        so a fresh clone needs neither meshing nor elastic solves.
    overwrite : bool
        As in :func:`run_scenario`.

    Returns
    -------
    stats : dict
        Counts, volumes (m³), edge lengths (m), quality, convection areas (m²), timings (s).
    out_dir : Path
        The folder.
    """
    geometry = load_geometry(machine)
    out_dir = Path(out_dir or Path("runs") / f"mesh_{geometry.name}")
    check_output_folder(out_dir, overwrite, inputs=(geometry.source,))
    start = time.perf_counter()
    mesh, info = build_mesh(geometry, mesh_size_m, rebuild=rebuild)
    stats = mesh_statistics(mesh)
    stats.update(cache_file=str(info.path), from_cache=info.from_cache,
                 seconds=round(time.perf_counter() - start, 2))
    model = build_machine(machine, mesh_size_m)
    rows, adiabatic = convection_summary(model)
    stats["convection_groups"] = [{"name": n, "area_m2": a, "coefficient_W_m2K": h, "zone": z}
                                  for n, a, h, z in rows]
    stats["adiabatic_area_m2"] = adiabatic
    stats["thermal_nodes"] = model.thermal.n_nodes
    if ship:
        SHIPPED_CACHE.mkdir(exist_ok=True)
        for path in (model.mesh_path, model.operator_path):
            if path.parent != SHIPPED_CACHE:
                shutil.copy2(sidecar(path), SHIPPED_CACHE / sidecar(path).name)
                shutil.copy2(path, SHIPPED_CACHE / path.name)
        stats["shipped"] = [model.mesh_path.name, model.operator_path.name]
    with atomic_directory(out_dir, overwrite) as tmp:
        (tmp / "mesh_statistics.json").write_text(json.dumps(stats, indent=1))
        render_machine(model, tmp / f"{geometry.name}.png", title=f"{geometry.name}: {mesh.n_tets} tetrahedra")
    return stats, out_dir
