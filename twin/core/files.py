"""Atomic text files: a reader never sees a half-written result."""
from __future__ import annotations

import os
from pathlib import Path


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to a hidden ``.<name>.partial`` beside ``path``, then rename it into place.

    Parameters
    ----------
    path : str or Path
        The file to write; its folder must exist.
    text : str
        The content.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.partial")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path
