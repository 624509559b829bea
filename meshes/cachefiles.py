"""Cache folders and cached files checked by content: every file carries a SHA-256 that is verified before use.

Two folders hold derived data: the shipped cache ``meshes/cache`` (meshes and
output operators committed with the package, which the documented figures
depend on) and the user cache (``$THERMAL_TWIN_CACHE`` or
``~/.cache/thermal-twin``), where everything built later goes.

Each cached file ``name`` has a sidecar ``name.sha256`` holding the SHA-256 of
its bytes in ``sha256sum`` format (``<hex>  <name>``), so ``sha256sum -c
*.sha256`` checks a folder by hand as well.  The hash is checked before any
parser sees the bytes, so a truncated file, garbage, or an edited file that
still parses (an operator with doubled values) is never used:

- a bad file in the user cache is reported on stderr (its path and why),
  removed, and the caller rebuilds it;
- a bad shipped file stops the program with :class:`CacheFileError`
  (one line, naming the file): rebuilding it would silently change every
  result that depends on it (fTetWild meshes differ from run to run).

Writers use :func:`write_checked`, which writes under a temporary name and
renames the sidecar and then the file into place, so a reader never sees a
half-written file under the real name.
"""
from __future__ import annotations

import hashlib
import logging
import os
import re
from collections.abc import Callable
from pathlib import Path

from .tomlspec import DefinitionError

SHIPPED_CACHE = Path(__file__).resolve().parent / "cache"
SIDECAR_SUFFIX = ".sha256"

#: The package's logger for long work and cache events (the ``twin`` CLI sends it to stderr).
log = logging.getLogger("thermal_twin")


class CacheFileError(DefinitionError):
    """A shipped cache file fails its content check (the installation is damaged)."""


def user_cache_dir() -> Path:
    """Where new meshes and other derived data are cached (created if missing).

    Returns
    -------
    Path
        ``$THERMAL_TWIN_CACHE`` if set, else ``~/.cache/thermal-twin``.
    """
    root = os.environ.get("THERMAL_TWIN_CACHE")
    path = Path(root) if root else Path.home() / ".cache" / "thermal-twin"
    path.mkdir(parents=True, exist_ok=True)
    return path


def sidecar(path: str | Path) -> Path:
    """The checksum file of a cached file.

    Parameters
    ----------
    path : str or Path
        A cached file.

    Returns
    -------
    Path
        ``<name>.sha256`` beside it.
    """
    path = Path(path)
    return path.with_name(path.name + SIDECAR_SUFFIX)


def file_sha256(path: str | Path) -> str:
    """SHA-256 of a file's bytes, read in 1 MiB blocks.

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    str
        64 hex digits.
    """
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def content_problem(path: str | Path) -> str | None:
    """Why a cached file cannot be trusted.

    Parameters
    ----------
    path : str or Path
        A cached file with a ``.sha256`` sidecar.

    Returns
    -------
    str or None
        One phrase (missing or malformed sidecar, hash mismatch), or ``None`` when its bytes match.
    """
    side = sidecar(path)
    try:
        recorded = side.read_text(encoding="ascii").split()
    except (OSError, UnicodeDecodeError):
        return f"its checksum file {side.name} is missing or unreadable"
    if not recorded or not re.fullmatch(r"[0-9a-f]{64}", recorded[0]):
        return f"its checksum file {side.name} is malformed"
    actual = file_sha256(path)
    if actual != recorded[0]:
        return (f"its SHA-256 {actual[:12]}… ({Path(path).stat().st_size} bytes) does not match "
                f"the recorded {recorded[0][:12]}…")
    return None


def checked(path: str | Path) -> Path | None:
    """A cached file after its content check.

    Parameters
    ----------
    path : str or Path
        A file in the shipped or the user cache.

    Returns
    -------
    Path or None
        ``path`` if it passes; ``None`` for a bad user-cache file, after saying so and removing it.

    Raises
    ------
    CacheFileError
        A shipped file fails its check.
    """
    path = Path(path)
    problem = content_problem(path)
    if problem is None:
        return path
    if SHIPPED_CACHE in path.parents:
        raise CacheFileError(f"{path}: corrupt shipped cache file: {problem}; restore it from the "
                             "repository (git checkout meshes/cache) or reinstall the package")
    log.warning("cache file %s is corrupt (%s): removed, building it again", path, problem)
    path.unlink(missing_ok=True)
    sidecar(path).unlink(missing_ok=True)
    return None


def find_cached(name: str) -> Path | None:
    """A checked cached file by name: the shipped cache first, then the user cache.

    Parameters
    ----------
    name : str
        File name (may hold a subfolder), e.g. ``mesh-h45mm-634edd99568b3d79.vtu``.

    Returns
    -------
    Path or None
        The file; ``None`` when absent, or when the user-cache copy failed its
        check (it is then removed and the caller builds it again).
    """
    for folder in (SHIPPED_CACHE, user_cache_dir()):
        if (folder / name).exists():
            return checked(folder / name)
    return None


def write_checked(path: str | Path, write: Callable[[Path], object]) -> Path:
    """Write a cache file atomically with its SHA-256 sidecar.

    The temporary name keeps the suffix (numpy and VTK choose the format by it)
    and holds the process id, so concurrent writers of one key do not collide.

    Parameters
    ----------
    path : str or Path
        The file to write.
    write : callable
        ``write(temporary_path)`` writes the content.

    Returns
    -------
    Path
        ``path``, now complete with its sidecar.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.partial{path.suffix}")
    side_tmp = sidecar(tmp)
    try:
        write(tmp)
        side_tmp.write_text(f"{file_sha256(tmp)}  {path.name}\n", encoding="ascii")
        os.replace(side_tmp, sidecar(path))
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
        side_tmp.unlink(missing_ok=True)
    return path
