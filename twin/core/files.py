"""Atomic, durable text files: a reader never sees a half-written result, even after a power cut."""
from __future__ import annotations

import os
from pathlib import Path

from .interrupt import raise_if_interrupted


def write_text_atomic(path: str | Path, text: str, after_interrupt: bool = False) -> Path:
    """Write ``text`` (UTF-8) to a hidden ``.<name>.partial`` beside ``path``, then rename it into place.

    The content reaches the disk before the rename, and the rename before the
    function returns, so a crash leaves the old file or the new one, never an
    empty or truncated file under the final name.

    Parameters
    ----------
    path : str or Path
        The file to write; its folder must exist.
    text : str
        The content.
    after_interrupt : bool, default False
        Write it after a Ctrl-C too (a live twin's state, whose saving is part of stopping); by default a Ctrl-C,
        even one a library swallowed, cancels the result.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.partial")
    with open(tmp, "w", encoding="utf-8") as file:
        file.write(text)
        file.flush()
        os.fsync(file.fileno())
    try:
        if not after_interrupt:
            raise_if_interrupted()
    except KeyboardInterrupt:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)
    sync_folder(path.parent)
    return path


def sync_file(path: str | Path) -> None:
    """Flush a written file's content to the disk (``fsync``).

    Parameters
    ----------
    path : str or Path
        The file.
    """
    with open(path, "rb") as file:
        os.fsync(file.fileno())


def sync_folder(path: str | Path) -> None:
    """Flush a folder's entries (its renames) to the disk; Windows has no folder ``fsync`` and needs none.

    Parameters
    ----------
    path : str or Path
        The folder.
    """
    if os.name == "nt":  # pragma: no cover - the CI runs on Linux
        return
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)
