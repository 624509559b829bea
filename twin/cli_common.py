"""Options and checks that several ``twin`` commands share (light: imported when the parser is built)."""
from __future__ import annotations

import zipfile
from pathlib import Path

from .errors import TwinInputError

_OVERWRITE_HELP = {
    "folder": "write into a non-empty folder that is not a twin output: its files are kept (the twin only ever "
              "replaces files it wrote, as its .thermal-twin-output.json lists them)",
    "file": "replace the output file if it exists",
}


def add_overwrite(parser, output="folder"):
    """Add ``--overwrite`` for a command whose ``--out`` is a ``"folder"`` or a ``"file"``."""
    parser.add_argument("--overwrite", action="store_true", help=_OVERWRITE_HELP[output])


def existing_fmu(path):
    """``path`` if it names an FMU archive; a one-line :class:`TwinInputError` otherwise."""
    path = Path(path)
    if not path.is_file():
        raise TwinInputError(f"{path}: FMU file not found")
    if not zipfile.is_zipfile(path):
        raise TwinInputError(f"{path}: not an FMU (an FMU is a zip archive)")
    return path
