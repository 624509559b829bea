"""Public-API documentation coverage, by an AST scan: docstrings, full type annotations, numpydoc sections.

Usage::

    python bench/api_coverage.py fea meshes twin/core twin/infra twin/run      # one line per path
    python bench/api_coverage.py -v meshes                                      # and every function that misses

The scan and what it counts are in ``tests/api_docs.py``; ``tests/test_api_docs.py`` enforces it per
package (its ``COVERED`` lists which).  This script only prints it.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from api_docs import coverage, shares  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", help="packages (folders) or modules")
    parser.add_argument("-v", "--verbose", action="store_true", help="list what each function misses")
    parser.add_argument("--exclude", action="append", default=[], help="a file or folder left out (repeatable)")
    args = parser.parse_intermixed_args()
    for path in args.paths:
        c, missing = coverage(path, args.exclude)
        s = shares(c)
        print(f"{path:16s} public definitions {c['definitions']:4d}, with docstring {s['documented']:5.1f} %; "
              f"functions {c['functions']:4d}: fully typed {s['typed']:5.1f} %, "
              f"numpydoc sections {s['numpydoc']:5.1f} %")
        for line in missing if args.verbose else ():
            print("   ", line)


if __name__ == "__main__":
    main()
