"""Options, checks and option-value parsers that several ``twin`` commands share (light: the parser imports it)."""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

from ..errors import TwinInputError
from .outdir import check_output_file

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


def add_cluster_options(parser):
    """Add ``--machine``, ``--mesh-size`` and ``--scheduler`` for a command that sweeps scenarios on Dask."""
    parser.add_argument("--machine", default="vmc_ram", help="machine name or TOML path")
    parser.add_argument("--mesh-size", type=float, help="target tetrahedron edge length, m")
    parser.add_argument("--scheduler", default="local", help="'local' (a local Dask cluster, default), 'serial', "
                                                              "or tcp://HOST:8786 for an existing one")


def check_out_file(args, inputs=()):
    """Check ``args.out`` (a file, if given) before any work; ``args.overwrite`` allows replacing it."""
    if args.out is not None:
        check_output_file(args.out, args.overwrite, inputs)


def read_column_map(value):
    """A column map from a JSON file path or inline JSON (``{"t1": "T01_degC"}``), or None."""
    if value is None:
        return None
    path = Path(value)
    text = path.read_text(encoding="utf-8") if path.exists() else value
    try:
        out = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TwinInputError(f"column map {value!r} is neither a JSON file nor inline JSON ({exc})") from None
    if not isinstance(out, dict):
        raise TwinInputError(f"column map must be a JSON object csv column → '<name>_<unit>', got {out!r}")
    return out


def split_names(value):
    """``"T01,T05"`` or ``["T01", "T05"]`` → ``["T01", "T05"]``."""
    if value is None:
        return []
    if isinstance(value, str):
        value = [value]
    return [n.strip() for item in value for n in str(item).split(",") if n.strip()]
