"""3-D views of a run: temperature field and deformed shape, rendered off-screen without noise, from a field
that agrees with the drift channels.

The small test machine (``tests/data/mini_machine.toml``, here with P2
displacements) is run through ``twin run`` in a subprocess, so what a user
sees on the console is checked too; its elastic problem is small enough for a
direct solve.  The default machine's check (iterative solves at the picture
tolerance) is marked slow.
"""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from twin.core.deformation import PICTURE_TOLERANCE, displacement_fields
from twin.core.machine import build_machine, elastic_problem
from twin.core.scenario import load_scenario
from twin.core.simulate import simulate
from twin.infra.render import deformation_scale

DATA = Path(__file__).parent / "data"
VIEW_TIMES_H = (1.0, 2.0)
SCENARIO = f"""
[scenario]
name = "mini_views"
machine = "{{machine}}"
duration_h = 3
sample_interval_s = 600.0
time_step_s = 600.0
[ambient]
kind = "constant"
temperature_C = 20.0
[[segments]]
duration_h = 2
spindle_rpm = 10000
[outputs]
camera_images_at_h = {list(VIEW_TIMES_H)}
"""


@pytest.fixture(scope="module")
def mini(tmp_path_factory):
    """The mini machine with P2 displacements and a scenario asking for pictures at 1 h and 2 h."""
    root = tmp_path_factory.mktemp("views")
    text = (DATA / "mini_machine.toml").read_text().replace("elastic_degree = 1", "elastic_degree = 2")
    assert "elastic_degree = 2" in text
    (root / "mini_machine.toml").write_text(text)
    shutil.copy(DATA / "pedestal_mm.stl", root)
    (root / "mini_views.toml").write_text(SCENARIO.replace("{machine}", (root / "mini_machine.toml").as_posix()))
    return root


@pytest.fixture(scope="module")
def run(mini):
    """``twin run`` of the scenario in a subprocess without a display: (result folder, stderr)."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "VTK_DEFAULT_OPENGL_WINDOW")}
    env.update(THERMAL_TWIN_CACHE=str(mini / "cache"), OPENBLAS_NUM_THREADS="1")
    out = mini / "run"
    done = subprocess.run([sys.executable, "-m", "twin.cli", "run", str(mini / "mini_views.toml"), "--out", str(out)],
                          env=env, capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stderr
    return out, done.stderr


def test_run_renders_off_screen_without_x_server_noise(run):
    _, stderr = run
    assert "X server" not in stderr and "vtkXOpenGLRenderWindow" not in stderr, stderr[-2000:]


@pytest.mark.parametrize("kind", ["temperature_3d", "deformed"])
def test_run_writes_3d_views_at_the_picture_times(run, kind):
    out, _ = run
    for hours in VIEW_TIMES_H:
        image = np.asarray(Image.open(out / f"{kind}_{hours:.2f}h.png").convert("RGB"), np.int64)
        assert image.shape[0] >= 600 and image.shape[1] >= 800
        assert image.std() > 20.0                                  # not a blank picture
        # the colour-mapped machine: many distinct colours, not only background, edges and text
        assert len(np.unique(image @ np.array([65536, 256, 1]))) > 500


def test_deformed_field_agrees_with_the_drift_channels(mini, monkeypatch):
    """The forward-solved field at the tool and table points equals the adjoint-operator drift channels."""
    monkeypatch.setenv("THERMAL_TWIN_CACHE", str(mini / "cache"))
    sc = load_scenario(mini / "mini_views.toml")
    machine = build_machine(sc.machine)
    times = [3600.0 * h for h in VIEW_TIMES_H]
    result = simulate(sc, machine, fields=times, noise=False)
    fields = displacement_fields(machine, {t: result.fields[t] for t in times})
    d = machine.definition
    elastic = elastic_problem(d, machine.mesh)
    assert elastic.space.degree == 2
    probe = np.asarray(d.tool_point) + np.asarray(d.tilt_probe_offset)
    points = [d.tool_point, d.workpiece_point, probe, d.workpiece_point]
    checked = 0
    for t, u in fields.items():
        assert u.shape == (elastic.space.n_nodes, 3)
        for k, axis in enumerate("xyz"):
            rows = elastic.point_rows(points, axis * 4, snap_distance=d.snap_distance_m)
            tool, table, top, table_again = 1e6 * (rows @ u.ravel())          # µm
            i = np.searchsorted(result.dataset.time_s, t)
            channel = result.dataset[axis.upper()][i]
            assert tool - table == pytest.approx(channel, rel=1e-7, abs=1e-9)
            if axis == "y":
                assert top - table_again == pytest.approx(result.dataset["Y_top"][i], rel=1e-7, abs=1e-9)
            checked += abs(channel) > 0.1
    assert checked >= 2                                   # a real drift was compared, not zeros


def test_deformation_scale_is_round_and_shows_the_largest_displacement_at_about_the_fraction():
    u = [np.array([[0.0, 0.0, 3e-5]]), np.array([[4e-5, 0.0, 0.0]])]
    scale = deformation_scale(u, size_m=2.0, fraction=0.08)
    assert scale == 2000.0                                   # 0.08 · 2 m / 40 µm = 4000 → 2 × 10³
    assert 0.02 <= scale * 4e-5 / 2.0 <= 0.08
    assert deformation_scale([np.zeros((3, 3))], 1.0) == 1.0


@pytest.mark.slow
def test_default_machine_field_at_the_picture_tolerance_matches_the_drift_channels(machine):
    """vmc_ram (P2, AMG-CG stopped at PICTURE_TOLERANCE): the field reproduces X, Y, Z to 0.5 % or 0.1 µm."""
    sc = load_scenario("heat_cool_9000")
    times = [3600.0, 7200.0, 10800.0]
    result = simulate(sc, machine, fields=times, noise=False)
    fields = displacement_fields(machine, {t: result.fields[t] for t in times}, PICTURE_TOLERANCE)
    d = machine.definition
    elastic = elastic_problem(d, machine.mesh)
    for t, u in fields.items():
        i = np.searchsorted(result.dataset.time_s, t)
        for axis in "xyz":
            rows = elastic.point_rows([d.tool_point, d.workpiece_point], axis * 2, snap_distance=d.snap_distance_m)
            tool, table = 1e6 * (rows @ u.ravel())
            channel = result.dataset[axis.upper()][i]
            assert axis == "x" or abs(channel) > 5.0
            assert tool - table == pytest.approx(channel, rel=5e-3, abs=0.1)


def test_categorical_points_get_a_legend_and_scores_a_colour_bar(mini, monkeypatch):
    """The chosen-sensors picture (``twin place``) labels its axis categories in a legend, not on a colour bar."""
    from twin.infra.render import machine_scene

    monkeypatch.setenv("THERMAL_TWIN_CACHE", str(mini / "cache"))
    machine = build_machine(mini / "mini_machine.toml")
    points = [[0.2, 0.15, 0.5], [0.2, 0.15, 0.3], [0.3, 0.15, 0.45]]
    plotter = machine_scene(machine, points=points, point_labels=["Z1", "Z2", "Y1"],
                            point_categories=["Z drift: greedy-loso, K = 2", "Z drift: greedy-loso, K = 2",
                                              "Y drift: qr-drift, K = 1"])
    try:
        assert len(plotter.scalar_bars) == 0
        legend = plotter.legend
        assert [legend.GetEntryString(i) for i in range(legend.GetNumberOfEntries())] == \
            ["Z drift: greedy-loso, K = 2", "Y drift: qr-drift, K = 1"]
    finally:
        plotter.close()
    plotter = machine_scene(machine, points=points, point_values=[0.1, 0.2, 0.3], point_label="residual (K)")
    try:
        assert list(plotter.scalar_bars.keys()) == ["residual (K)"] and plotter.legend is None
    finally:
        plotter.close()
