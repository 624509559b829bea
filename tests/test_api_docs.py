"""The public API is documented: docstrings, full type annotations and numpydoc sections, per package (issue 11).

The scan is ``tests/api_docs.py`` (``python bench/api_coverage.py -v PATH`` prints it).  Every Python file of
the project is in a package of :data:`COVERED`, held to :data:`MIN_SHARES`; a new package cannot slip through
unscanned.
"""
from pathlib import Path

import pytest
from api_docs import coverage, python_files, shares

ROOT = Path(__file__).resolve().parents[1]
PROJECT = ("fea", "meshes", "models", "twin")
#: Held to the thresholds: one entry per package (folder) or top-level module, relative to the repository.
COVERED = ("fea", "meshes", "models", "twin/core", "twin/infra", "twin/run", "twin/compensation", "twin/placement",
           "twin/rom", "twin/fmu", "twin/live", "twin/gap", "twin/__init__.py", "twin/cli.py", "twin/errors.py")
#: Smallest shares (%) of documented definitions, fully typed functions and functions with numpydoc sections.
MIN_SHARES = {"documented": 100.0, "typed": 100.0, "numpydoc": 95.0}
#: Where a package is held to less, and why.
LOWER = {"fea": {"typed": 95.0}}   # the scikit-fem forms of fea/heat_forms.py take skfem's (u, v, w), untyped


@pytest.mark.parametrize("package", COVERED)
def test_public_api_is_documented_typed_and_numpydoc(package):
    counts, missing = coverage(ROOT / package)
    assert counts["definitions"] or package.endswith("__init__.py"), f"{package}: nothing scanned"
    got = shares(counts)
    floor = {**MIN_SHARES, **LOWER.get(package, {})}
    low = {k: f"{got[k]:.1f} % < {floor[k]:g} %" for k in floor if got[k] < floor[k]}
    assert not low, f"{package}: {low}; missing:\n" + "\n".join(m.replace(str(ROOT) + "/", "") for m in missing)


def test_every_python_file_is_covered_or_listed():
    listed = [ROOT / p for p in COVERED]
    everything = {f for p in PROJECT for f in python_files(ROOT / p)}
    covered = {f for p in listed for f in python_files(p)}
    assert not everything - covered, f"not in COVERED: {sorted(everything - covered)}"
    assert all(p.exists() for p in listed), [str(p) for p in listed if not p.exists()]


def test_the_scan_finds_what_is_missing(tmp_path):
    """The scan itself: an untyped function, one without sections, an undocumented class are each caught."""
    (tmp_path / "m.py").write_text('''
def typed_but_bare(x: int) -> int:
    """No sections."""
    return x


def documented(x, y: float = 1.0) -> float:
    """Sections but an untyped parameter.

    Parameters
    ----------
    x, y : float

    Returns
    -------
    float
    """
    return x * y


def complete(x: float) -> float:
    """Everything.

    Parameters
    ----------
    x : float

    Returns
    -------
    float
    """
    return x


class Bare:
    pass


def _private(x):
    return x
''')
    counts, missing = coverage(tmp_path)
    assert counts == {"definitions": 4, "documented": 3, "functions": 3, "typed": 2, "numpydoc": 2}
    assert [m.split(" ", 1)[1] for m in missing] == ["typed_but_bare typed=True numpydoc=False",
                                                     "documented typed=False numpydoc=True",
                                                     "Bare (class) no docstring"]
    assert shares(counts) == pytest.approx({"documented": 75.0, "typed": 200 / 3, "numpydoc": 200 / 3})
