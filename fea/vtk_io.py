"""Writing fields to VTK for ParaView: one ``.vtu``, or a time series as ``.vtu`` files plus a ``.pvd`` index.

Files are written under a temporary name and renamed into place, so an
interrupted write never leaves a file that looks complete.
"""
from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr


def _atomic_save(grid, path):
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    grid.save(tmp)
    os.replace(tmp, path)


def write_vtu(path, mesh, point_data=None, cell_data=None):
    """Write the mesh with nodal and cell arrays (names should carry units, e.g. ``temperature_degC``)."""
    _atomic_save(mesh.to_pyvista(point_data, cell_data), path)
    return Path(path)


def write_time_series(path, mesh, frames):
    """Write a ``.pvd`` collection: ``frames`` maps time (s) to a dict of nodal arrays.

    The ``.vtu`` files go next to the ``.pvd`` in a folder named after it;
    the ``.pvd`` is written last, so it only exists once every frame does.
    """
    path = Path(path)
    folder = path.with_suffix("")
    folder.mkdir(parents=True, exist_ok=True)
    entries = []
    for k, (time_s, arrays) in enumerate(sorted(frames.items())):
        name = f"{folder.name}_{k:05d}.vtu"
        write_vtu(folder / name, mesh, arrays)
        entries.append(f'    <DataSet timestep="{time_s:.6g}" file={quoteattr(folder.name + "/" + name)}/>')
    text = ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
            + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n")
    tmp = path.with_name(f".{path.name}.partial")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path
