"""Writing fields to VTK for ParaView: one ``.vtu``, or a time series as ``.vtu`` files plus a ``.pvd`` index.

Files are written under a temporary name and renamed into place, so an
interrupted write never leaves a file that looks complete.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING
from xml.sax.saxutils import quoteattr

if TYPE_CHECKING:
    import numpy as np

    from .mesh import TetMesh


def _atomic_save(grid, path):
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    grid.save(tmp)
    os.replace(tmp, path)


def write_vtu(path: str | Path, mesh: TetMesh, point_data: dict[str, np.ndarray] | None = None,
              cell_data: dict[str, np.ndarray] | None = None) -> Path:
    """Write the mesh with nodal and cell arrays as ``.vtu``, atomically.

    Parameters
    ----------
    path : str or Path
        The file.
    mesh : TetMesh
        The mesh (coordinates in m).
    point_data, cell_data : dict of str to ndarray, optional
        Arrays by name; names should carry units, e.g. ``temperature_degC``.

    Returns
    -------
    Path
        ``path``.
    """
    _atomic_save(mesh.to_pyvista(point_data, cell_data), path)
    return Path(path)


def write_time_series(path: str | Path, mesh: TetMesh, frames: dict[float, dict[str, np.ndarray]]) -> Path:
    """Write a ``.pvd`` collection of nodal fields over time.

    The ``.vtu`` files go next to the ``.pvd`` in a folder named after it;
    the ``.pvd`` is written last, so it only exists once every frame does.

    Parameters
    ----------
    path : str or Path
        The ``.pvd`` file.
    mesh : TetMesh
        The mesh.
    frames : dict of float to dict
        Time (s) → nodal arrays by name (names with units).

    Returns
    -------
    Path
        ``path``.
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
