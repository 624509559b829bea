"""Options, checks and option-value parsers that several ``twin`` commands share (light: the parser imports it)."""
from __future__ import annotations

import argparse
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


def add_overwrite(parser: argparse.ArgumentParser, output: str = "folder") -> None:
    """Add ``--overwrite`` to a command.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser.
    output : str
        What its ``--out`` is: ``"folder"`` or ``"file"`` (chooses the help text).
    """
    parser.add_argument("--overwrite", action="store_true", help=_OVERWRITE_HELP[output])


def existing_fmu(path: str | Path) -> Path:
    """An argument that must name an FMU archive (an ``argparse`` type).

    Parameters
    ----------
    path : str or Path
        The argument.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    TwinInputError
        The file is missing or not a zip archive.
    """
    path = Path(path)
    if not path.is_file():
        raise TwinInputError(f"{path}: FMU file not found")
    if not zipfile.is_zipfile(path):
        raise TwinInputError(f"{path}: not an FMU (an FMU is a zip archive)")
    return path


def add_cluster_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--machine``, ``--mesh-size`` (m) and ``--scheduler`` for a command that sweeps scenarios on Dask.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser.
    """
    parser.add_argument("--machine", default="vmc_ram", help="machine name or TOML path")
    parser.add_argument("--mesh-size", type=mesh_size, help="target tetrahedron edge length, m")
    parser.add_argument("--scheduler", default="local", help="'local' (a local Dask cluster, default), 'serial', "
                                                              "or tcp://HOST:8786 for an existing one")


def mesh_size(text: str) -> float:
    """The value of ``--mesh-size``: a target tetrahedron edge length in m (argparse ``type``).

    Parameters
    ----------
    text : str
        The option's text.

    Returns
    -------
    float
        The length, m, from :data:`meshes.builder.MIN_MESH_SIZE_M` to :data:`meshes.builder.MAX_MESH_SIZE_M`; a
        larger one is refused before any meshing, with a hint when it reads as mm.
    """
    from meshes.builder import (  # heavy (pyvista): only when the option is given
        MAX_MESH_SIZE_M,
        MIN_MESH_SIZE_M,
        check_mesh_size,
        mm_hint,
    )

    try:
        size = float(text)
    except ValueError:
        size = float("nan")   # refused below with the bounds, as a NaN is
    try:
        return check_mesh_size(size)
    except ValueError:   # meshes' DefinitionError
        raise argparse.ArgumentTypeError(f"{text!r} is not a mesh size: give a finite length in m, from "
                                         f"{MIN_MESH_SIZE_M:g} m ({MIN_MESH_SIZE_M * 1e3:g} mm) to "
                                         f"{MAX_MESH_SIZE_M:g} m{mm_hint(size)}") from None


def check_out_file(args: argparse.Namespace, inputs: tuple = (), suffix: str | None = None) -> None:
    """Check ``args.out`` (a file, if given) before any work; ``args.overwrite`` allows replacing it.

    Parameters
    ----------
    args : argparse.Namespace
        With ``out`` and ``overwrite``.
    inputs : tuple of str or Path
        The command's input files, which the output must not be.
    suffix : str, optional
        The ending the file's name must have (:func:`twin.infra.outdir.check_output_file`).
    """
    if args.out is not None:
        check_output_file(args.out, args.overwrite, inputs, suffix)


def read_column_map(value: str | None) -> dict[str, str] | None:
    """A column map from a JSON file path or inline JSON.

    Parameters
    ----------
    value : str or None
        A path, or inline JSON such as ``{"t1": "T01_degC"}``.

    Returns
    -------
    dict of str to str or None
        CSV column → ``<name>_<unit>``, or to None (JSON null: the column is left out); None without a value.
    """
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


def check_distinct(option: str, items: list, what: str) -> None:
    """Refuse a list option that names nothing, or names an item twice (its work would be done twice).

    Parameters
    ----------
    option : str
        The option, e.g. ``--orders``.
    items : list
        Its items.
    what : str
        What one item is, e.g. ``"order"``.

    Raises
    ------
    TwinInputError
        One line naming the option and the repeated item.
    """
    if not items:
        raise TwinInputError(f"{option} must name at least one {what}, got none")
    repeated = [x for i, x in enumerate(items) if x in items[:i]]
    if repeated:
        raise TwinInputError(f"{option} names {what} {repeated[0]!r} more than once")


def split_names(value: str | list[str] | None) -> list[str]:
    """Channel names from a comma-separated string or a list of them.

    Parameters
    ----------
    value : str or list of str or None
        ``"T01,T05"`` or ``["T01", "T05"]`` (items may hold commas too).

    Returns
    -------
    list of str
        ``["T01", "T05"]``; empty for None.
    """
    if value is None:
        return []
    if isinstance(value, str):
        value = [value]
    return [n.strip() for item in value for n in str(item).split(",") if n.strip()]
