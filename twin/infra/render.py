"""Off-screen 3-D pictures of a machine (pyvista): parts, fields, deformed shapes, marked sensors, camera views."""
from __future__ import annotations

import ctypes.util
import os
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING


def _prefer_headless_backend():
    """Without a display on Linux, ask VTK for its EGL window at once.

    VTK otherwise tries X first and prints ``vtkXOpenGLRenderWindow ... bad X
    server connection`` before falling back to EGL.  A user's own
    ``VTK_DEFAULT_OPENGL_WINDOW`` wins; without libEGL nothing is changed.
    """
    headless = sys.platform.startswith("linux") and not os.environ.get("DISPLAY") \
        and not os.environ.get("WAYLAND_DISPLAY")
    if headless and ctypes.util.find_library("EGL"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


_prefer_headless_backend()

import numpy as np  # noqa: E402
import pyvista as pv  # noqa: E402

pv.OFF_SCREEN = True

if TYPE_CHECKING:
    from ..core.machine import Machine

#: Colours of categorical point sets (matplotlib's tab10).
CATEGORY_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
                    "#bcbd22", "#17becf")


def _plotter(window_size=(1200, 900)):
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    plotter.set_background("white")
    return plotter


def _screenshot(plotter, path):
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.partial.png")
    plotter.screenshot(str(tmp))
    plotter.close()
    tmp.replace(path)
    return path


def _iso_view(plotter):
    plotter.camera_position = "iso"
    plotter.camera.azimuth = 35
    plotter.reset_camera()
    plotter.camera.zoom(1.15)


#: An upright colour bar on the right of a 3-D view.
UPRIGHT_BAR = {"vertical": True, "position_x": 0.84, "position_y": 0.2, "height": 0.6, "width": 0.06,
               "color": "black", "title_font_size": 16, "label_font_size": 14}


def machine_scene(machine: Machine, node_values: np.ndarray | None = None, scalar_label: str | None = None,
                  cmap: str = "inferno", points: np.ndarray | None = None, point_labels: list[str] | None = None,
                  point_values: np.ndarray | None = None, point_label: str | None = None,
                  point_categories: list[str] | None = None, title: str | None = None,
                  clim: tuple[float, float] | None = None) -> pv.Plotter:
    """The off-screen plotter of :func:`render_machine`, before its screenshot.

    Parameters
    ----------
    machine : Machine
        A built machine.
    node_values : ndarray, optional
        Values on the mesh nodes to colour by (use ``thermal.nodal_field`` for temperatures); else by part.
    scalar_label : str, optional
        Their colour-bar title, with the unit.
    cmap : str
        Colour map of ``node_values``.
    points : ndarray, shape (k, 3), optional
        Points to mark, m.
    point_labels : list of str, optional
        Text beside each point.
    point_values : ndarray, optional
        Values colouring the points, with a colour bar titled ``point_label``.
    point_label : str, optional
        That colour bar's title, with the unit.
    point_categories : list of str, optional
        One category per point, coloured with a legend.
    title : str, optional
        Text at the top.
    clim : tuple of float, optional
        Colour span of ``node_values``.

    Returns
    -------
    pyvista.Plotter
        Off-screen, in the isometric view.
    """
    grid = machine.mesh.to_pyvista()
    plotter = _plotter()
    _add_machine_surface(plotter, grid, node_values, scalar_label, cmap, clim, points is not None,
                         point_values is not None)
    if points is not None:
        points = np.asarray(points, float)
        cloud = pv.PolyData(points)
        sphere = pv.Sphere(radius=0.01 * float(np.ptp(machine.mesh.points, axis=0).max()))
        if point_categories is not None:
            _add_point_categories(plotter, points, point_categories, sphere)
        elif point_values is not None:
            cloud[point_label or "score"] = np.asarray(point_values, float)
            plotter.add_mesh(cloud.glyph(geom=sphere, scale=False, orient=False),
                             scalars=point_label or "score", cmap="viridis",
                             scalar_bar_args={"title": point_label or "score", "color": "black"})
        else:
            plotter.add_mesh(cloud.glyph(geom=sphere, scale=False, orient=False), color="red")
        if point_labels is not None:
            plotter.add_point_labels(cloud, list(point_labels), font_size=14, text_color="black",
                                     shape_opacity=0.6, always_visible=True)
    if title:
        plotter.add_text(title, font_size=12, color="black")
    _iso_view(plotter)
    return plotter


def _add_machine_surface(plotter, grid, node_values, scalar_label, cmap, clim, with_points, with_point_bar):
    """The machine surface: neutral (under marked points), by part, or coloured by nodal values."""
    if node_values is None and with_points:      # a neutral machine, so the points' colours stand out
        surface = grid.extract_surface(algorithm=None)
        plotter.add_mesh(surface, color="lightgrey", opacity=0.45)
        plotter.add_mesh(surface.extract_feature_edges(), color="dimgrey", line_width=1)
    elif node_values is None:
        plotter.add_mesh(grid.extract_surface(algorithm=None), scalars="region", cmap="tab10", show_scalar_bar=False)
    else:
        grid.point_data[scalar_label or "value"] = np.asarray(node_values)
        surface = grid.extract_surface(algorithm=None)
        # with coloured points too, this bar goes upright on the right so the two bars do not overlap
        bar = UPRIGHT_BAR if with_point_bar else {"color": "black"}
        plotter.add_mesh(surface, scalars=scalar_label or "value", cmap=cmap, clim=clim,
                         scalar_bar_args={"title": scalar_label or "value", **bar})


def _add_point_categories(plotter, points, point_categories, sphere):
    """Points (m) as spheres coloured by category, with a legend in the lower right."""
    categories = list(dict.fromkeys(point_categories))
    if len(categories) > len(CATEGORY_COLOURS):
        raise ValueError(f"at most {len(CATEGORY_COLOURS)} point categories, got {len(categories)}")
    legend = []
    for category, colour in zip(categories, CATEGORY_COLOURS):
        mine = [i for i, c in enumerate(point_categories) if c == category]
        plotter.add_mesh(pv.PolyData(points[mine]).glyph(geom=sphere, scale=False, orient=False),
                         color=colour)
        legend.append([str(category), colour, "circle"])
    width = min(0.9, 0.009 * max(len(entry[0]) for entry in legend) + 0.04)
    box = plotter.add_legend(legend, bcolor="white", border=True)
    box.SetPosition(0.98 - width, 0.02)       # lower right, placed here: pyvista's loc mixes up the sizes
    box.SetPosition2(width, 0.035 * len(legend))


def render_machine(machine: Machine, path: str | Path, node_values: np.ndarray | None = None,
                   scalar_label: str | None = None, cmap: str = "inferno", points: np.ndarray | None = None,
                   point_labels: list[str] | None = None, point_values: np.ndarray | None = None,
                   point_label: str | None = None, point_categories: list[str] | None = None,
                   title: str | None = None, clim: tuple[float, float] | None = None) -> Path:
    """Render the machine surface, coloured by part or by nodal values, with optional marked points, as PNG.

    Points are drawn as spheres, coloured by category with a legend, by
    value with a colour bar, or red.

    Parameters
    ----------
    machine, node_values, scalar_label, cmap, points, point_labels, point_values, point_label, \
point_categories, title, clim
        As :func:`machine_scene`.
    path : str or Path
        The PNG file.

    Returns
    -------
    Path
        ``path``.
    """
    return _screenshot(machine_scene(machine, node_values, scalar_label, cmap, points, point_labels, point_values,
                                     point_label, point_categories, title, clim), path)


def _field_view(grid, label, cmap, clim, title, note=None, outline=None):
    """A plotter with ``grid``'s surface coloured by point data ``label``, its part edges, an upright bar."""
    plotter = _plotter()
    surface = grid.extract_surface(algorithm=None)
    plotter.add_mesh(surface, scalars=label, cmap=cmap, clim=clim,
                     scalar_bar_args={"title": label, "fmt": "%.1f", **UPRIGHT_BAR})
    plotter.add_mesh(surface.extract_feature_edges(), color="black", line_width=1)
    if outline is not None:
        plotter.add_mesh(outline, color="grey", line_width=1)
    if note:
        plotter.add_text(note, position="lower_left", font_size=11, color="black")
    if title:
        plotter.add_text(title, font_size=12, color="black")
    _iso_view(plotter)
    return plotter


def render_temperature_field(machine: Machine, temperature: np.ndarray, path: str | Path, title: str | None = None,
                             clim: tuple[float, float] | None = None) -> Path:
    """3-D view of the machine coloured by a temperature field, colour bar in °C, as PNG.

    Parameters
    ----------
    machine : Machine
        A built machine.
    temperature : ndarray
        Temperature on the thermal nodes, °C.
    path : str or Path
        The PNG file.
    title : str, optional
        Text at the top.
    clim : tuple of float, optional
        Colour span, °C.

    Returns
    -------
    Path
        ``path``.
    """
    grid = machine.mesh.to_pyvista()
    grid.point_data["temperature (°C)"] = machine.thermal.nodal_field(temperature)
    return _screenshot(_field_view(grid, "temperature (°C)", "turbo", clim, title), path)


def deformation_scale(displacements_m: Iterable[np.ndarray], size_m: float, fraction: float = 0.08) -> float:
    """A round drawing scale for deformed shapes.

    Parameters
    ----------
    displacements_m : iterable of ndarray, shape (n, 3)
        Displacement fields, m.
    size_m : float
        Size of the machine, m.
    fraction : float
        The largest displacement is drawn at most this fraction of ``size_m``.

    Returns
    -------
    float
        1, 2 or 5 × 10^k (1 when nothing moves).
    """
    largest = max((float(np.linalg.norm(u, axis=1).max()) for u in displacements_m), default=0.0)
    if largest == 0.0:
        return 1.0
    raw = fraction * size_m / largest
    decade = 10.0 ** np.floor(np.log10(raw))
    return float(decade * max(m for m in (1, 2, 5) if m * decade <= raw))


def render_deformed_shape(machine: Machine, displacement: np.ndarray, path: str | Path, scale: float,
                          title: str | None = None, clim_um: tuple[float, float] | None = None) -> Path:
    """The machine deformed by ``scale`` × ``displacement`` (m), coloured by |u| in µm, as PNG.

    ``displacement`` is (n, 3) on the nodes of the elastic space, the mesh
    vertices first (as :func:`twin.core.deformation.displacement_fields` gives it);
    the vertices' rows are drawn.  The undeformed part edges are drawn in grey
    and the drawing scale is written in the picture.

    Parameters
    ----------
    machine : Machine
        A built machine.
    displacement : ndarray, shape (n, 3)
        Displacement, m.
    path : str or Path
        The PNG file.
    scale : float
        Drawing scale of the displacement.
    title : str, optional
        Text at the top.
    clim_um : tuple of float, optional
        Colour span, µm.

    Returns
    -------
    Path
        ``path``.
    """
    grid = machine.mesh.to_pyvista()
    outline = grid.extract_surface(algorithm=None).extract_feature_edges()
    u = np.asarray(displacement, float)[: machine.mesh.n_nodes]
    label = "displacement magnitude (µm)"
    grid.point_data[label] = 1e6 * np.linalg.norm(u, axis=1)
    grid.points = grid.points + scale * u
    note = f"deformation drawn × {scale:g}; grey edges: undeformed"
    return _screenshot(_field_view(grid, label, "viridis", clim_um, title, note, outline), path)


def render_thermal_image(machine: Machine, temperature: np.ndarray, path: str | Path, title: str | None = None,
                         clim: tuple[float, float] | None = None) -> Path:
    """A false-colour thermal image as the machine's camera would see it (°C), from its position, as PNG.

    Parameters
    ----------
    machine : Machine
        A built machine with a ``[camera]``.
    temperature : ndarray
        Temperature on the thermal nodes, °C.
    path : str or Path
        The PNG file.
    title : str, optional
        Text at the top.
    clim : tuple of float, optional
        Colour span, °C; without it the span is set, as a camera's auto-span
        on its region of interest would, to the range of the virtual spots on the face.

    Returns
    -------
    Path
        ``path``.
    """
    camera = machine.definition.camera
    if clim is None:                   # the camera spots are rows of the machine's output operator
        rows = [j for j, c in enumerate(machine.channels) if c.kind == "camera"]
        values = machine.outputs.matrix[rows] @ temperature + machine.outputs.offset[rows]
        margin = max(0.1, 0.1 * float(np.ptp(values)))
        clim = (float(values.min()) - margin, float(values.max()) + margin)
    grid = machine.mesh.to_pyvista()
    grid.point_data["temperature (°C)"] = machine.thermal.nodal_field(temperature)
    plotter = _plotter((960, 720))
    plotter.set_background("black")
    plotter.add_mesh(grid.extract_surface(algorithm=None), scalars="temperature (°C)", cmap="inferno", clim=clim,
                     scalar_bar_args={"title": "temperature (°C)", "color": "white"})
    spots = camera.spots()
    focus = spots.mean(axis=0)
    plotter.camera_position = [tuple(camera.position), tuple(focus), (0.0, 0.0, 1.0)]
    plotter.camera.view_angle = 24.0          # FLIR S65 field of view 24° × 18°
    if title:
        plotter.add_text(title, font_size=12, color="white")
    return _screenshot(plotter, path)


def render_temperature_views(machine: Machine, temperatures: dict[float, np.ndarray], folder: str | Path,
                             name: str) -> list[Path]:
    """``temperature_3d_<t>h.png`` for each temperature field, on one colour span.

    Parameters
    ----------
    machine : Machine
        A built machine.
    temperatures : dict of float to ndarray
        Time (s) → temperature on the thermal nodes (°C).
    folder : str or Path
        Where the PNGs go.
    name : str
        Scenario name, in the titles.

    Returns
    -------
    list of Path
        The PNG files.
    """
    nodal = [machine.thermal.nodal_field(T) for T in temperatures.values()]
    clim = (min(float(v.min()) for v in nodal), max(float(v.max()) for v in nodal)) if nodal else None
    return [render_temperature_field(machine, T, Path(folder) / f"temperature_3d_{t / 3600:.2f}h.png",
                                     title=f"{name}  t = {t / 3600:.2f} h", clim=clim)
            for t, T in temperatures.items()]


def render_deformed_views(machine: Machine, displacements: dict[float, np.ndarray], folder: str | Path,
                          name: str) -> float:
    """``deformed_<t>h.png`` for each displacement field, on one colour span and drawing scale.

    Parameters
    ----------
    machine : Machine
        A built machine.
    displacements : dict of float to ndarray
        Time (s) → displacement (n, 3), m, mesh vertices first.
    folder : str or Path
        Where the PNGs go.
    name : str
        Scenario name, in the titles.

    Returns
    -------
    float
        The drawing scale.
    """
    displacements = {t: np.asarray(u, float)[: machine.mesh.n_nodes] for t, u in displacements.items()}
    scale = deformation_scale(displacements.values(), float(np.ptp(machine.mesh.points, axis=0).max()))
    largest_um = max((1e6 * float(np.linalg.norm(u, axis=1).max()) for u in displacements.values()), default=0.0)
    for t, u in displacements.items():
        render_deformed_shape(machine, u, Path(folder) / f"deformed_{t / 3600:.2f}h.png", scale,
                              title=f"{name}  t = {t / 3600:.2f} h: displacement from "
                                    f"{machine.definition.reference_temperature_C:g} °C on the 3-2-1 mount",
                              clim_um=(0.0, max(largest_um, 1e-3)))
    return scale
