"""meshes: machine geometry (TOML definitions, part shapes) and the mesher (pytetwild), with checked caches.

- :mod:`meshes.definition` — the geometry part of a machine TOML: parts, shapes, mesh settings;
- :mod:`meshes.shapes` — part shapes: closed surfaces to mesh, signed depth to label tetrahedra;
- :mod:`meshes.builder` — geometry → labelled tetrahedral mesh, cached by geometry and mesh size;
- :mod:`meshes.cachefiles` — cache folders, and files checked by their SHA-256 before use;
- :mod:`meshes.tomlspec` — reading TOML with errors that name the file, the field and the value.

``meshes`` imports only :mod:`fea` of the project (tests/test_architecture.py).
"""
import importlib

#: Public name → the module of ``meshes`` that defines it.
_API = {
    **dict.fromkeys(("MeshInfo", "build_mesh", "mesh_statistics", "read_labelled_mesh"), "builder"),
    **dict.fromkeys(("SHIPPED_CACHE", "CacheFileError", "user_cache_dir"), "cachefiles"),
    **dict.fromkeys(("DEFAULT_MESH_SIZE_M", "MachineGeometry", "Part", "available_machines", "load_geometry",
                     "machine_path"), "definition"),
    **dict.fromkeys(("Box", "Cylinder", "HollowBox", "StlPart"), "shapes"),
    "DefinitionError": "tomlspec",
}
__all__ = sorted(_API)


def __getattr__(name):
    """Import a public name on first use (PEP 562), so that the light modules stay light: reading a scenario
    (:mod:`meshes.tomlspec`) must not load pyvista, VTK and scipy with the mesher."""
    if name not in _API:
        raise AttributeError(f"module 'meshes' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"meshes.{_API[name]}"), name)
    globals()[name] = value
    return value
