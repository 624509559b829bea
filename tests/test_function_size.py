"""No function over 60 code lines or cyclomatic complexity 15 without a reason written beside it.

Complexity is radon's (McCabe's count plus boolean operators), as ``radon cc`` prints it.  Code lines exclude the
docstring, blank lines and comment lines.  A reason is a comment directly above the ``def`` (or its first decorator)
that starts with ``# Long:`` or ``# Complex:`` and says why the function reads best in one piece.
"""
import ast
from pathlib import Path

import pytest
from radon.complexity import cc_visit

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fea", "meshes", "models", "twin")
MAX_COMPLEXITY = 15
MAX_CODE_LINES = 60
REASON_PREFIXES = ("# long:", "# complex:")


def complexities(source):
    """``{line of the def: radon complexity}`` for every function and method in ``source``."""
    found = {}
    for block in cc_visit(source):
        for function in [block, *getattr(block, "methods", [])]:
            found[function.lineno] = function.complexity
    return found


def code_lines(node, lines):
    """Lines of ``node``'s body that hold code: the docstring, blank and comment lines are not counted."""
    first = node.body[0]
    has_docstring = isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(
        first.value.value, str)
    start = first.end_lineno + 1 if has_docstring else first.lineno
    return sum(1 for line in lines[start - 1:node.end_lineno] if line.strip() and not line.strip().startswith("#"))


def has_reason(node, lines):
    """Whether a ``# Long:``/``# Complex:`` comment with text stands directly above the def or its decorators."""
    top = min([node.lineno, *(d.lineno for d in node.decorator_list)])
    above = []
    for line in reversed(lines[:top - 1]):
        if not line.strip().startswith("#"):
            break
        above.append(line.strip().lower())
    return any(line.startswith(REASON_PREFIXES) and len(line.split(":", 1)[1].strip()) > 10 for line in above)


def offenders(source, label):
    """``label:line name (complexity, code lines)`` for each function over a limit with no reason beside it."""
    lines = source.splitlines()
    complexity = complexities(source)
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        cc, n = complexity.get(node.lineno, 0), code_lines(node, lines)
        if (cc > MAX_COMPLEXITY or n > MAX_CODE_LINES) and not has_reason(node, lines):
            found.append(f"{label}:{node.lineno} {node.name} (complexity {cc}, {n} code lines)")
    return found


def test_no_long_or_complex_function_without_a_reason():
    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            found += offenders(path.read_text(encoding="utf-8"), path.relative_to(ROOT).as_posix())
    assert not found, "split these, or write '# Long: why' / '# Complex: why' above them:\n" + "\n".join(found)


BRANCHY = "def f(x):\n" + "".join(f"    if x == {i}:\n        return {i}\n" for i in range(16)) + "    return -1\n"
LONG = "def g():\n    '''Doc.'''\n" + "".join(f"    a{i} = {i}\n" for i in range(61))


@pytest.mark.parametrize("source", [BRANCHY, LONG])
def test_the_scan_finds_a_long_or_complex_function(source):
    assert len(offenders(source, "x.py")) == 1


@pytest.mark.parametrize("reason", ["# Long: one assembly loop over the element types", "# Complex: one dispatch table"])
def test_a_written_reason_is_accepted(reason):
    assert offenders(reason + "\n" + BRANCHY, "x.py") == []
    assert offenders("# Long:\n" + BRANCHY, "x.py") != [], "a reason needs text"


def test_the_limits_are_not_counted_from_the_docstring():
    docstring = "def h():\n    '''" + "line\n" * 80 + "    '''\n    return 1\n"
    assert offenders(docstring, "x.py") == []
