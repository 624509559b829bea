"""Ways a cached file gets spoiled, for the cache tests: the file changes, its SHA-256 sidecar does not."""
import numpy as np
import pytest

from meshes.cachefiles import CacheFileError, sidecar
from meshes.tomlspec import DefinitionError

#: Every spoil of a ``.npz``; a ``.vtu`` has all but ``pickled``.
NPZ_SPOILS = ("truncated", "empty", "garbage", "pickled", "values doubled", "no checksum")
VTU_SPOILS = ("truncated", "empty", "garbage", "values doubled", "no checksum")


def spoil(path, how):
    """Damage ``path`` the way a disk, a copy or a person can; "values doubled" keeps it a valid, parsable file."""
    raw = path.read_bytes()
    if how == "truncated":
        path.write_bytes(raw[: len(raw) // 2])
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "garbage":
        path.write_bytes(np.random.default_rng(1).bytes(len(raw)))
    elif how == "pickled":
        np.savez(path, data=np.array([{"rows": 1}], dtype=object))
    elif how == "values doubled" and path.suffix == ".vtu":
        import pyvista as pv

        grid = pv.read(path)
        grid.points *= 2.0
        grid.save(path)
    elif how == "values doubled":
        with np.load(path, allow_pickle=False) as data:
            arrays = dict(data)
        arrays = {k: 2 * v if v.dtype.kind == "f" else v for k, v in arrays.items()}
        np.savez(path, **arrays)
    elif how == "no checksum":
        sidecar(path).unlink()
    else:
        raise ValueError(f"unknown spoil {how!r}")


def assert_refused(path, action):
    """``action()`` stops with a one-line :class:`CacheFileError` (a DefinitionError, so the CLI prints one
    line) that names ``path``."""
    with pytest.raises(CacheFileError) as info:
        action()
    message = str(info.value)
    assert isinstance(info.value, DefinitionError)
    assert message.startswith(f"{path}: corrupt shipped cache file") and "\n" not in message
