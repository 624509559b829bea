"""Off-screen 3-D pictures of a machine (pyvista): parts, fields, marked sensors, thermal-camera views."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pyvista as pv

pv.OFF_SCREEN = True


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


def render_machine(machine, path, node_values=None, scalar_label=None, cmap="inferno", points=None,
                   point_labels=None, point_values=None, point_label=None, title=None, clim=None):
    """Render the machine surface, coloured by part or by nodal values, with optional marked points.

    ``node_values`` are on mesh nodes (use ``thermal.nodal_field`` for temperatures);
    ``points`` (k, 3) in m are drawn as spheres, coloured by ``point_values`` when given.
    """
    grid = machine.mesh.to_pyvista()
    plotter = _plotter()
    if node_values is None:
        surface = grid.extract_surface(algorithm=None)
        plotter.add_mesh(surface, scalars="region", cmap="tab10", show_edges=False, opacity=1.0 if points is None
                         else 0.55, show_scalar_bar=False)
    else:
        grid.point_data[scalar_label or "value"] = np.asarray(node_values)
        surface = grid.extract_surface(algorithm=None)
        # with coloured points too, this bar goes upright on the right so the two bars do not overlap
        upright = {"vertical": True, "position_x": 0.86, "position_y": 0.25, "height": 0.5, "width": 0.05} \
            if point_values is not None else {}
        plotter.add_mesh(surface, scalars=scalar_label or "value", cmap=cmap, clim=clim,
                         scalar_bar_args={"title": scalar_label or "value", "color": "black", **upright})
    if points is not None:
        cloud = pv.PolyData(np.asarray(points, float))
        size = 0.02 * float(np.ptp(machine.mesh.points, axis=0).max())
        if point_values is not None:
            cloud[point_label or "score"] = np.asarray(point_values, float)
            plotter.add_mesh(cloud.glyph(geom=pv.Sphere(radius=size / 2), scale=False, orient=False),
                             scalars=point_label or "score", cmap="viridis",
                             scalar_bar_args={"title": point_label or "score", "color": "black"})
        else:
            plotter.add_mesh(cloud.glyph(geom=pv.Sphere(radius=size / 2), scale=False, orient=False), color="red")
        if point_labels is not None:
            plotter.add_point_labels(cloud, list(point_labels), font_size=14, text_color="black",
                                     shape_opacity=0.6, always_visible=True)
    if title:
        plotter.add_text(title, font_size=12, color="black")
    plotter.camera_position = "iso"
    plotter.camera.azimuth = 35
    plotter.reset_camera()
    plotter.camera.zoom(1.15)
    return _screenshot(plotter, path)


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
