"""GitHub Markdown tables from rows of values: headers, per-column alignment and number formats."""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from numbers import Integral, Real

ALIGNMENTS = {None: "---", "left": ":---", "right": "---:", "center": ":---:"}
MISSING = "–"


def format_cell(value: object, spec: str | Callable[[object], str] | None = None) -> str:
    """One cell as text.

    A NaN or infinite float prints as :data:`MISSING`; integers, strings and
    everything else print as ``str(value)``.  A ``|`` in the text is escaped
    so that it cannot split the cell.

    Parameters
    ----------
    value : object
        The cell's value.
    spec : str or callable, optional
        A format spec (``".2f"``, ``".3g"``) applied to non-integer real
        numbers (Python or numpy floats), or a callable ``value → text``
        applied to every value.

    Returns
    -------
    str
        The cell's text.
    """
    if callable(spec):
        text = spec(value)
    elif isinstance(value, Real) and not isinstance(value, Integral):
        text = (format(value, spec) if spec else str(value)) if math.isfinite(value) else MISSING
    else:
        text = str(value)
    return str(text).replace("|", r"\|")


def _per_column(option, n, name):
    """A per-column option given once for every column, or as one entry per column."""
    if option is None or isinstance(option, str) or callable(option):
        return [option] * n
    option = list(option)
    if len(option) != n:
        raise ValueError(f"{name} has {len(option)} entries for {n} columns")
    return option


def markdown_table(rows: Iterable[Sequence], headers: Sequence[str], align: str | Sequence[str | None] | None = None,
                   formats: str | Callable | Sequence | None = None) -> str:
    """A GitHub Markdown table, one line per row, without a final newline.

    Parameters
    ----------
    rows : iterable of sequences
        One value per column.
    headers : sequence of str
        Column headers; put the unit in them (``"peak drift (µm)"``).
    align : str or sequence, optional
        ``"left"``, ``"right"``, ``"center"`` or None (GitHub's default) — for
        every column, or a sequence with one per column.
    formats : str, callable or sequence, optional
        A format spec (``".2f"``), a callable or None (see :func:`format_cell`)
        — for every column, or a sequence with one per column.

    Returns
    -------
    str
        The table.

    Examples
    --------
    >>> print(markdown_table([("Z", -40.2, 1.98)], ["axis", "peak (µm)", "at (h)"], formats=[None, ".1f", ".2f"]))
    | axis | peak (µm) | at (h) |
    |---|---|---|
    | Z | -40.2 | 1.98 |
    """
    headers = [str(h) for h in headers]
    n = len(headers)
    aligns, specs = _per_column(align, n, "align"), _per_column(formats, n, "formats")
    unknown = [a for a in aligns if a not in ALIGNMENTS]
    if unknown:
        raise ValueError(f"unknown alignment {unknown[0]!r}; use one of {[a for a in ALIGNMENTS if a]} or None")
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join(ALIGNMENTS[a] for a in aligns) + "|"]
    for i, row in enumerate(rows):
        row = list(row)
        if len(row) != n:
            raise ValueError(f"row {i} has {len(row)} values for {n} columns")
        lines.append("| " + " | ".join(format_cell(v, s) for v, s in zip(row, specs)) + " |")
    return "\n".join(lines)
