"""Reading TOML definition files with errors that name the file, the field and the value.

Machine definitions and scenarios are data written by people.  Every value is
read through a :class:`Table`, which knows the file and the dotted path of
the field it came from, so a mistake is reported as e.g.::

    scenarios/etve.toml: ambient.amplitude_K must be a number ≥ 0, got 'five'
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


class DefinitionError(ValueError):
    """A definition file is malformed or holds a bad value; the message says where."""


def read_toml(path):
    """Parse a TOML file into a :class:`Table`; malformed TOML raises :class:`DefinitionError`."""
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


def resolve_definition(name_or_path, folder, kind):
    """The TOML file of a named definition in ``folder`` (``vmc_ram``) or an explicit path.

    ``kind`` ("machine", "scenario") names what is looked for in the errors,
    which list the available names.
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


def plain_value(value):
    """``value`` with numpy scalars and arrays (inside lists, tuples and dicts too) as plain Python values.

    Error messages show values with ``repr``; a numpy scalar would show as
    ``np.int64(3600)`` where the user wrote ``3600``.
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
    """

    def __init__(self, data, file, path):
        if not isinstance(data, dict):
            raise DefinitionError(f"{file}: {path or 'the file'} must be a table, got {plain_value(data)!r}")
        self.data, self.file, self.path = data, file, path

    def where(self, key=None):
        dotted = ".".join(p for p in (self.path, key) if p)
        return f"{self.file}: {dotted or '(top level)'}"

    def error(self, key, message, value=_MISSING):
        shown = "" if value is _MISSING else f", got {plain_value(value)!r}"
        return DefinitionError(f"{self.where(key)} {message}{shown}")

    def __contains__(self, key):
        return key in self.data

    def keys(self):
        return self.data.keys()

    def raw(self, key, default=_MISSING):
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise self.error(key, "is required")
        return default

    def check_keys(self, allowed):
        unknown = sorted(set(self.data) - set(allowed))
        if unknown:
            raise DefinitionError(f"{self.where()}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")

    def table(self, key, default=_MISSING):
        value = self.raw(key, {} if default is _MISSING else default)
        if value is None:
            return None
        if not isinstance(value, dict):
            raise self.error(key, "must be a table", value)
        return Table(value, self.file, f"{self.path}.{key}" if self.path else key)

    def tables(self, key, required=False):
        value = self.raw(key, _MISSING if required else [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(key, "must be an array of tables ([[...]])", value)
        base = f"{self.path}.{key}" if self.path else key
        return [Table(v, self.file, f"{base}[{i}]") for i, v in enumerate(value)]

    def number(self, key, default=_MISSING, minimum=None, maximum=None, strict_minimum=False):
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

    def integer(self, key, default=_MISSING, minimum=None):
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, "must be an integer", value)
        if minimum is not None and value < minimum:
            raise self.error(key, f"must be ≥ {minimum}", value)
        return value

    def string(self, key, default=_MISSING, choices=None):
        value = self.raw(key, default)
        if value is None:
            return None
        if not isinstance(value, str):
            raise self.error(key, "must be a string", value)
        if choices is not None and value not in choices:
            raise self.error(key, f"must be one of {sorted(choices)}", value)
        return value

    def boolean(self, key, default=_MISSING):
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, "must be true or false", value)
        return value

    def vector(self, key, length=None, default=_MISSING):
        value = self.raw(key, default)
        if value is None:
            return None
        ok = isinstance(value, (list, tuple)) and all(
            not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) for v in value)
        if not ok or (length is not None and len(value) != length):
            size = f"{length} " if length else ""
            raise self.error(key, f"must be an array of {size}finite numbers", value)
        return tuple(float(v) for v in value)

    def strings(self, key, default=_MISSING):
        value = self.raw(key, default)
        if isinstance(value, str):
            return [value]
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.error(key, "must be a string or an array of strings", value)
        return list(value)
