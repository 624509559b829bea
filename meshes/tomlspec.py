"""Reading TOML definition files with errors that name the file, the field and the value.

Machine definitions and scenarios are data written by people.  Every value is
read through a :class:`Table`, which knows the file and the dotted path of
the field it came from, so a mistake is reported as e.g.::

    scenarios/etve.toml: ambient.amplitude_K must be a number ≥ 0, got 'five'
"""
from __future__ import annotations

import math
import sys
from collections.abc import KeysView
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


class DefinitionError(ValueError):
    """A definition file is malformed or holds a bad value; the message says where."""


def read_toml(path: str | Path) -> Table:
    """Parse a TOML file into a :class:`Table`.

    Parameters
    ----------
    path : str or Path
        The TOML file (UTF-8).

    Returns
    -------
    Table
        The top-level table; errors of its fields name ``path``.

    Raises
    ------
    DefinitionError
        The file is missing, not UTF-8 or not valid TOML.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DefinitionError(f"{path}: file not found") from None
    except UnicodeDecodeError as exc:
        raise DefinitionError(f"{path}: not UTF-8 text ({exc})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise DefinitionError(f"{path}: malformed TOML: {exc}") from None
    return Table(data, str(path), "")


def resolve_definition(name_or_path: str | Path, folder: str | Path, kind: str) -> Path:
    """The TOML file of a named definition in ``folder`` (``vmc_ram``) or an explicit path.

    Parameters
    ----------
    name_or_path : str or Path
        A name (the file stem in ``folder``) or a path; a ``.toml`` suffix or an
        existing file means a path.
    folder : str or Path
        Where the named definitions are.
    kind : str
        What is looked for (``"machine"``, ``"scenario"``), named in the errors.

    Returns
    -------
    Path
        The definition file.

    Raises
    ------
    DefinitionError
        The file does not exist; for an unknown name the message lists the available ones.
    """
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.exists():
            raise DefinitionError(f"{path}: {kind} file not found")
        return path
    candidate = Path(folder) / f"{name_or_path}.toml"
    if not candidate.exists():
        known = sorted(p.stem for p in Path(folder).glob("*.toml"))
        raise DefinitionError(f"unknown {kind} {name_or_path!r}; available: {known}")
    return candidate


_MISSING = object()


def duplicates(names: list[str]) -> list[str]:
    """The names that occur more than once in ``names``, sorted (empty when all are unique).

    Parameters
    ----------
    names : list of str
        Names read from a definition, e.g. the ``name`` of every ``[[parts]]`` entry.

    Returns
    -------
    list of str
        Each repeated name once.
    """
    return sorted({n for n in names if names.count(n) > 1})


def plain_value(value: object) -> object:
    """``value`` with numpy scalars and arrays (inside lists, tuples and dicts too) as plain Python values.

    Error messages show values with ``repr``; a numpy scalar would show as
    ``np.int64(3600)`` where the user wrote ``3600``.

    Parameters
    ----------
    value : object
        Any value read from a definition or computed from one.

    Returns
    -------
    object
        The same value with numpy scalars as Python numbers and arrays as lists.
    """
    if type(value) in (list, tuple):
        return type(value)(map(plain_value, value))
    if isinstance(value, dict):
        return {plain_value(k): plain_value(v) for k, v in value.items()}
    if type(value).__module__ == "numpy" and hasattr(value, "tolist"):
        return value.tolist()
    return value


class Table:
    """A TOML table that knows where it came from.

    Accessors take the key and constraints, and raise
    :class:`DefinitionError` naming ``file: path.key`` and the value.
    :meth:`check_keys` rejects keys nobody reads, so typos do not pass silently.

    Parameters
    ----------
    data : dict
        The parsed TOML table.
    file : str
        The file it was read from.
    path : str
        Its dotted path in the file (``""`` at the top level).
    """

    def __init__(self, data: dict, file: str, path: str) -> None:
        """Wrap ``data``, the table at dotted ``path`` (``""`` at the top) of ``file``."""
        if not isinstance(data, dict):
            raise DefinitionError(f"{file}: {path or 'the file'} must be a table, got {plain_value(data)!r}")
        self.data, self.file, self.path = data, file, path

    def where(self, key: str | None = None) -> str:
        """``file: path.key``, the place of a field in error messages.

        Parameters
        ----------
        key : str, optional
            A key of this table; without it, the table itself.

        Returns
        -------
        str
            E.g. ``scenarios/etve.toml: ambient.amplitude_K``.
        """
        dotted = ".".join(p for p in (self.path, key) if p)
        return f"{self.file}: {dotted or '(top level)'}"

    def error(self, key: str, message: str, value: object = _MISSING) -> DefinitionError:
        """The error (to raise) for field ``key``: its place, ``message`` and, if given, the value.

        Parameters
        ----------
        key : str
            The field.
        message : str
            What is wrong, e.g. ``"must be ≥ 0"``.
        value : object, optional
            The offending value, shown as ``got <repr>``.

        Returns
        -------
        DefinitionError
            ``file: path.key message, got value``.
        """
        shown = "" if value is _MISSING else f", got {plain_value(value)!r}"
        return DefinitionError(f"{self.where(key)} {message}{shown}")

    def __contains__(self, key):
        return key in self.data

    def keys(self) -> KeysView[str]:
        """The keys of the table.

        Returns
        -------
        KeysView of str
            The keys, in the order written.
        """
        return self.data.keys()

    def raw(self, key: str, default: object = _MISSING) -> object:
        """The value of ``key`` as parsed, unchecked.

        Parameters
        ----------
        key : str
            The field.
        default : object, optional
            Returned when the key is absent; without it the key is required.

        Returns
        -------
        object
            The TOML value (or ``default``).
        """
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise self.error(key, "is required")
        return default

    def check_keys(self, allowed: set[str]) -> None:
        """Refuse keys nobody reads (typos), listing the allowed ones.

        Parameters
        ----------
        allowed : set of str
            The keys this table may hold.
        """
        unknown = sorted(set(self.data) - set(allowed))
        if unknown:
            raise DefinitionError(f"{self.where()}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")

    def table(self, key: str, default: object = _MISSING) -> Table | None:
        """The sub-table ``key`` (an empty one when absent and no default is given).

        Parameters
        ----------
        key : str
            The field.
        default : object, optional
            Used when absent; ``None`` gives ``None``.

        Returns
        -------
        Table or None
            The sub-table, whose errors name ``path.key``.
        """
        value = self.raw(key, {} if default is _MISSING else default)
        if value is None:
            return None
        if not isinstance(value, dict):
            raise self.error(key, "must be a table", value)
        return Table(value, self.file, f"{self.path}.{key}" if self.path else key)

    def tables(self, key: str, required: bool = False) -> list[Table]:
        """The array of tables ``[[key]]`` (empty when absent unless ``required``).

        Parameters
        ----------
        key : str
            The field.
        required : bool
            Refuse a missing array.

        Returns
        -------
        list of Table
            One per entry, whose errors name ``key[i]``.
        """
        value = self.raw(key, _MISSING if required else [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(key, "must be an array of tables ([[...]])", value)
        base = f"{self.path}.{key}" if self.path else key
        return [Table(v, self.file, f"{base}[{i}]") for i, v in enumerate(value)]

    def number(self, key: str, default: object = _MISSING, minimum: float | None = None,
               maximum: float | None = None, strict_minimum: bool = False) -> float | None:
        """A finite number within bounds, as float (in the unit the key's name gives).

        Parameters
        ----------
        key : str
            The field.
        default : object, optional
            Used when absent (``None`` gives ``None``); without it the key is required.
        minimum, maximum : float, optional
            Bounds, inclusive unless ``strict_minimum``.
        strict_minimum : bool
            Refuse a value equal to ``minimum``.

        Returns
        -------
        float or None
            The value.
        """
        value = self.raw(key, default)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.error(key, "must be a finite number", value)
        if minimum is not None and (value < minimum or (strict_minimum and value == minimum)):
            rel = ">" if strict_minimum else "≥"
            raise self.error(key, f"must be {rel} {minimum}", value)
        if maximum is not None and value > maximum:
            raise self.error(key, f"must be ≤ {maximum}", value)
        return float(value)

    def integer(self, key: str, default: object = _MISSING, minimum: int | None = None) -> int:
        """An integer (not a bool, not a float) of at least ``minimum``.

        Parameters
        ----------
        key : str
            The field.
        default : object, optional
            Used when absent; without it the key is required.
        minimum : int, optional
            Smallest allowed value.

        Returns
        -------
        int
            The value.
        """
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, "must be an integer", value)
        if minimum is not None and value < minimum:
            raise self.error(key, f"must be ≥ {minimum}", value)
        return value

    def string(self, key: str, default: object = _MISSING, choices: set[str] | None = None) -> str | None:
        """A string, optionally one of ``choices``.

        Parameters
        ----------
        key : str
            The field.
        default : object, optional
            Used when absent (``None`` gives ``None``); without it the key is required.
        choices : set of str, optional
            The allowed values, listed in the error.

        Returns
        -------
        str or None
            The value.
        """
        value = self.raw(key, default)
        if value is None:
            return None
        if not isinstance(value, str):
            raise self.error(key, "must be a string", value)
        if choices is not None and value not in choices:
            raise self.error(key, f"must be one of {sorted(choices)}", value)
        return value

    def boolean(self, key: str, default: object = _MISSING) -> bool:
        """``true`` or ``false``.

        Parameters
        ----------
        key : str
            The field.
        default : object, optional
            Used when absent; without it the key is required.

        Returns
        -------
        bool
            The value.
        """
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, "must be true or false", value)
        return value

    def vector(self, key: str, length: int | None = None, default: object = _MISSING) -> tuple[float, ...] | None:
        """An array of finite numbers, e.g. a point ``[x, y, z]`` in m.

        Parameters
        ----------
        key : str
            The field.
        length : int, optional
            The required number of entries.
        default : object, optional
            Used when absent (``None`` gives ``None``); without it the key is required.

        Returns
        -------
        tuple of float or None
            The values.
        """
        value = self.raw(key, default)
        if value is None:
            return None
        ok = isinstance(value, (list, tuple)) and all(
            not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) for v in value)
        if not ok or (length is not None and len(value) != length):
            size = f"{length} " if length else ""
            raise self.error(key, f"must be an array of {size}finite numbers", value)
        return tuple(float(v) for v in value)

    def strings(self, key: str, default: object = _MISSING) -> list[str]:
        """A string or an array of strings, as a list.

        Parameters
        ----------
        key : str
            The field.
        default : object, optional
            Used when absent; without it the key is required.

        Returns
        -------
        list of str
            The values (one for a single string).
        """
        value = self.raw(key, default)
        if isinstance(value, str):
            return [value]
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.error(key, "must be a string or an array of strings", value)
        return list(value)
