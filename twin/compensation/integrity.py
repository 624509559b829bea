"""Digests of a compensation-model file's fields: a field changed after ``twin train`` saved it is refused on load.

A compensation-model file is written by ``twin train`` only, and every
number in it comes from the fit. A field edited by hand (a gain, a time
constant, ``n_poles``, ``zero_reference``, an input's name or unit) gives
predictions that can be off by any amount with nothing to show it, so the
file carries the SHA-256 of each of its fields::

    "field_sha256": {"model_name": "<64 hex>", …, "preprocessing.zero_reference": …,
                     "estimator.class": …, "estimator.params.n_poles": …,
                     "estimator.learned.gains_": …}

one per top-level field of the file, or per entry of one that is an object
(``preprocessing.<name>``, ``metadata.<name>``), and within the estimator
document one per ``params.<name>`` and ``learned.<name>`` and one per other
field of it (``format``, ``version``, ``class``), so a message names the
entry that changed. A digest is that of the field's
canonical JSON (:func:`canonical`: keys sorted, no spaces, floats in their
shortest round-trip form), taken of the document as it reads back from the
file, so a file that is only re-indented or has its keys reordered still
matches. On load (:func:`check_sealed`) a field whose digest differs, one
that is missing or one that was added is refused with one line naming the
file, the field and its value as written.

This catches edits, not forgery: anyone can recompute a SHA-256. A file
without ``field_sha256`` (written before the digests, or with the field
removed) is read with a warning on the ``thermal_twin`` logger; of its
fields only the switches of ``preprocessing`` are checked here (true or
false, :data:`SWITCHES`), the estimator's values by
:func:`models.persistence.model_from_document`.
"""
from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path

from ..core.dataset import json_default
from ..errors import TwinInputError

log = logging.getLogger("thermal_twin")

#: the top-level field that holds the digests
FIELD = "field_sha256"
#: how deep an object field is split into entries with a digest each: the estimator's params and learned per entry
_DEPTH = {"estimator": 2}
#: the entries of ``preprocessing`` that are true or false: any other value (``"yes"``) would be read as true
SWITCHES = ("zero_reference", "time_column", "rest_start")


def canonical(value: object) -> str:
    """The canonical JSON of a value read from a JSON file: keys sorted, no spaces (NaN written as ``NaN``).

    Parameters
    ----------
    value : object
        A value as :func:`json.loads` gives it.

    Returns
    -------
    str
    """
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def fields(document: dict) -> dict[str, object]:
    """The fields of a compensation-model document that have a digest, by their dotted names.

    Parameters
    ----------
    document : dict
        The file's document (the digests themselves, :data:`FIELD`, are left out).

    Returns
    -------
    dict of str to object
        ``model_name``, ``inputs`` … per top-level field, ``preprocessing.<name>`` … per entry of an object;
        ``estimator.<field>``, and ``estimator.params.<name>`` / ``estimator.learned.<name>`` per entry.
    """
    out = {}
    for key, value in document.items():
        if key != FIELD:
            out.update(_entries(key, value, _DEPTH.get(key, 1)))
    return out


def _entries(name, value, depth):
    """``{dotted name: value}`` of a field, an object split into its entries ``depth`` levels down (an empty
    object stays one field)."""
    if depth == 0 or not isinstance(value, dict) or not value:
        return {name: value}
    out = {}
    for key, inner in value.items():
        out.update(_entries(f"{name}.{key}", inner, depth - 1))
    return out


def digests(document: dict) -> dict[str, str]:
    """SHA-256 (hex) of the :func:`canonical` JSON of each of the document's :func:`fields`.

    Parameters
    ----------
    document : dict
        A compensation-model document as it reads back from JSON.

    Returns
    -------
    dict of str to str
        Dotted field name → 64 hex digits.
    """
    return {name: hashlib.sha256(canonical(value).encode("utf-8")).hexdigest()
            for name, value in fields(document).items()}


def sealed(document: dict) -> dict:
    """The document as it will read back from its JSON file, with the digests of its fields under :data:`FIELD`.

    Parameters
    ----------
    document : dict
        The document to write (numpy values allowed, as :func:`twin.core.dataset.json_default` writes them).

    Returns
    -------
    dict
        Plain JSON values; write it with :func:`json.dumps` (any indentation).
    """
    plain = json.loads(json.dumps(document, default=json_default))
    plain[FIELD] = digests(plain)
    return plain


def check_sealed(document: dict, path: Path | str) -> None:
    """Refuse a document whose fields do not match the digests it was saved with; warn if it has none.

    Parameters
    ----------
    document : dict
        The parsed model file.
    path : Path or str
        The file, named in the message.

    Raises
    ------
    TwinInputError
        One line naming the file, the first field changed, missing or added, and its value as written.
    """
    stored = document.get(FIELD)
    if stored is None:
        log.warning("%s: written without field digests (%s; project version %s), so an edit to it cannot be "
                    "detected; train it again to add them", path, FIELD, document.get("project_version", "?"))
        _check_switches(document, path)
        return
    if not isinstance(stored, dict):
        raise TwinInputError(f"{path}: field {FIELD!r} has value {_shown(stored)}, expected the digests "
                             "`twin train` writes; train again or restore the file")
    now, values = digests(document), fields(document)
    for name in [*stored, *(n for n in now if n not in stored)]:
        if name not in now:
            what = "was removed"
        elif name not in stored:
            what = f"= {_shown(values[name])} was added"
        elif now[name] != stored[name]:
            what = f"= {_shown(values[name])} was changed"
        else:
            continue
        raise TwinInputError(f"{path}: field {name!r} {what} after the model was saved (its digest in {FIELD!r} "
                             "does not match); train again or restore the file")


def _check_switches(document, path):
    """Refuse a ``preprocessing`` that is not an object, or a :data:`SWITCHES` entry that is not true or false."""
    prep = document.get("preprocessing") or {}
    if not isinstance(prep, dict):
        raise TwinInputError(f"{path}: field 'preprocessing' has value {_shown(prep)}, expected an object")
    for name in SWITCHES:
        if not isinstance(prep.get(name, False), bool):
            raise TwinInputError(f"{path}: field 'preprocessing.{name}' has value {_shown(prep[name])}, expected "
                                 "true or false")


def _shown(value, limit=160):
    """The canonical JSON of a value, cut to ``limit`` characters for a message."""
    text = canonical(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"
