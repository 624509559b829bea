"""Off-screen 3-D pictures of a machine (pyvista): parts, fields, deformed shapes, marked sensors, camera views."""
from __future__ import annotations

import ctypes.util
import os
import sys
from pathlib import Path


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


def machine_scene(machine, node_values=None, scalar_label=None, cmap="inferno", points=None, point_labels=None,
                  point_values=None, point_label=None, point_categories=None, title=None, clim=None):
    """The off-screen plotter of :func:`render_machine` (same arguments), before its screenshot."""
    grid = machine.mesh.to_pyvista()
    plotter = _plotter()
    if node_values is None and points is not None:      # a neutral machine, so the points' colours stand out
        surface = grid.extract_surface(algorithm=None)
        plotter.add_mesh(surface, color="lightgrey", opacity=0.45)
        plotter.add_mesh(surface.extract_feature_edges(), color="dimgrey", line_width=1)
    elif node_values is None:
        plotter.add_mesh(grid.extract_surface(algorithm=None), scalars="region", cmap="tab10", show_scalar_bar=False)
    else:
        grid.point_data[scalar_label or "value"] = np.asarray(node_values)
        surface = grid.extract_surface(algorithm=None)
        # with coloured points too, this bar goes upright on the right so the two bars do not overlap
        bar = UPRIGHT_BAR if point_values is not None else {"color": "black"}
        plotter.add_mesh(surface, scalars=scalar_label or "value", cmap=cmap, clim=clim,
                         scalar_bar_args={"title": scalar_label or "value", **bar})
    if points is not None:
        points = np.asarray(points, float)
        cloud = pv.PolyData(points)
        sphere = pv.Sphere(radius=0.01 * float(np.ptp(machine.mesh.points, axis=0).max()))
        if point_categories is not None:
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


def render_machine(machine, path, node_values=None, scalar_label=None, cmap="inferno", points=None,
                   point_labels=None, point_values=None, point_label=None, point_categories=None, title=None,
                   clim=None):
    """Render the machine surface, coloured by part or by nodal values, with optional marked points; PNG at ``path``.

    ``node_values`` are on mesh nodes (use ``thermal.nodal_field`` for temperatures);
    ``points`` (k, 3) in m are drawn as spheres, coloured by category with a
    legend (``point_categories``, one label per point) or by ``point_values``
    with a colour bar titled ``point_label``.
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


def render_temperature_field(machine, temperature, path, title=None, clim=None):
    """3-D view of the machine coloured by a temperature field (°C on the thermal nodes), colour bar in °C."""
    grid = machine.mesh.to_pyvista()
    grid.point_data["temperature (°C)"] = machine.thermal.nodal_field(temperature)
    return _screenshot(_field_view(grid, "temperature (°C)", "turbo", clim, title), path)


def deformation_scale(displacements_m, size_m, fraction=0.08):
    """A round drawing scale (1, 2 or 5 × 10^k) drawing the largest displacement at most ``fraction`` × ``size_m``."""
    largest = max((float(np.linalg.norm(u, axis=1).max()) for u in displacements_m), default=0.0)
    if largest == 0.0:
        return 1.0
    raw = fraction * size_m / largest
    decade = 10.0 ** np.floor(np.log10(raw))
    return float(decade * max(m for m in (1, 2, 5) if m * decade <= raw))


def render_deformed_shape(machine, displacement, path, scale, title=None, clim_um=None):
    """The machine deformed by ``scale`` × ``displacement`` (m), coloured by |u| in µm.

    ``displacement`` is (n, 3) on the nodes of the elastic space, the mesh
    vertices first (as :func:`twin.core.deformation.displacement_fields` gives it);
    the vertices' rows are drawn.  The undeformed part edges are drawn in grey
    and the drawing scale is written in the picture.
    """
    grid = machine.mesh.to_pyvista()
    outline = grid.extract_surface(algorithm=None).extract_feature_edges()
    u = np.asarray(displacement, float)[: machine.mesh.n_nodes]
    label = "displacement magnitude (µm)"
    grid.point_data[label] = 1e6 * np.linalg.norm(u, axis=1)
    grid.points = grid.points + scale * u
    note = f"deformation drawn × {scale:g}; grey edges: undeformed"
    return _screenshot(_field_view(grid, label, "viridis", clim_um, title, note, outline), path)


def render_thermal_image(machine, temperature, path, title=None, clim=None):
    """A false-colour thermal image as the machine's camera would see it (°C), from its position.

    Without ``clim`` the colour span is set, as a camera's auto-span on its
    region of interest would, to the range of the virtual spots on the face.
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


def render_temperature_views(machine, temperatures, folder, name):
    """``temperature_3d_<t>h.png`` for each time (s) → temperature field (°C, thermal nodes), on one colour span."""
    nodal = [machine.thermal.nodal_field(T) for T in temperatures.values()]
    clim = (min(float(v.min()) for v in nodal), max(float(v.max()) for v in nodal)) if nodal else None
    return [render_temperature_field(machine, T, Path(folder) / f"temperature_3d_{t / 3600:.2f}h.png",
                                     title=f"{name}  t = {t / 3600:.2f} h", clim=clim)
            for t, T in temperatures.items()]


def render_deformed_views(machine, displacements, folder, name):
    """``deformed_<t>h.png`` for each time (s) → vertex displacements (m), on one colour span and drawing scale.

    Returns the drawing scale.
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
