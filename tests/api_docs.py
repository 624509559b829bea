"""The public-API documentation scan (AST): docstrings, full type annotations, numpydoc sections.

Used by ``tests/test_api_docs.py`` (which enforces it) and printed by ``bench/api_coverage.py``.

Counted: module-level functions and classes whose names do not start with ``_``, their public methods
and ``__init__`` (with parameters).  A function is *fully typed* when every parameter but ``self``/``cls``
and its return are annotated (``__init__`` needs no return); it has *numpydoc* sections when its docstring
has ``Parameters`` if it takes parameters and ``Returns`` (``Yields``) if it returns (yields) a value;
properties are exempt from ``Returns`` (numpydoc documents them as attributes), and ``__init__``'s
parameters may be in the class docstring; property setters count with their property.  A method without a
docstring inherits that of a base class in the same module (as :func:`inspect.getdoc` does).
"""
from __future__ import annotations

import ast
from pathlib import Path

FUNCTIONS = (ast.FunctionDef, ast.AsyncFunctionDef)
COUNTS = ("definitions", "documented", "functions", "typed", "numpydoc")


def _inherited_docs(tree):
    """Class name → {method: docstring}, methods of same-module base classes included."""
    classes = {n.name: n for n in tree.body if isinstance(n, ast.ClassDef)}

    def docs(name, seen=()):
        node = classes.get(name)
        if node is None or name in seen:
            return {}
        out = {}
        for base in node.bases:
            if isinstance(base, ast.Name):
                out.update(docs(base.id, (*seen, name)))
        out.update({f.name: ast.get_docstring(f) for f in node.body if isinstance(f, FUNCTIONS) and ast.get_docstring(f)})
        return out

    return {name: docs(name) for name in classes}


def public_definitions(tree):
    """(qualified name, node, docstring) of the public functions, classes and methods of a module."""
    inherited = _inherited_docs(tree)
    for node in tree.body:
        if isinstance(node, FUNCTIONS) and not node.name.startswith("_"):
            yield node.name, node, ast.get_docstring(node) or ""
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            class_doc = ast.get_docstring(node) or ""
            yield node.name, node, class_doc
            for sub in node.body:
                init = sub.name == "__init__" if isinstance(sub, FUNCTIONS) else False
                setter = isinstance(sub, FUNCTIONS) and any(
                    isinstance(d, ast.Attribute) and d.attr in ("setter", "deleter") for d in sub.decorator_list)
                if setter:            # documented with its property
                    continue
                if isinstance(sub, FUNCTIONS) and (not sub.name.startswith("_") or init and len(sub.args.args) > 1):
                    doc = ast.get_docstring(sub) or inherited[node.name].get(sub.name, "")
                    yield f"{node.name}.{sub.name}", sub, doc + ("\n" + class_doc if init else "")


def fully_typed(fn):
    """Every parameter but self/cls annotated, and the return (not needed for ``__init__``)."""
    params = [a for a in fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs if a.arg not in ("self", "cls")]
    params += [a for a in (fn.args.vararg, fn.args.kwarg) if a]
    return all(a.annotation is not None for a in params) and (fn.returns is not None or fn.name == "__init__")


def has_numpydoc_sections(fn, doc):
    """``Parameters`` when it takes parameters, ``Returns``/``Yields`` when it returns/yields a value."""
    params = [a for a in fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs if a.arg not in ("self", "cls")]
    if params and "Parameters\n" not in doc:
        return False
    is_property = any(isinstance(d, ast.Name) and d.id in ("property", "cached_property") for d in fn.decorator_list)
    returns = any(isinstance(n, ast.Return) and n.value is not None for n in ast.walk(fn))
    yields = any(isinstance(n, (ast.Yield, ast.YieldFrom)) for n in ast.walk(fn))
    if returns and not is_property and "Returns\n" not in doc:
        return False
    return not (yields and "Yields\n" not in doc)


def python_files(path, exclude=()):
    """The ``.py`` files under ``path`` (or the file itself), without those under any path of ``exclude``."""
    path = Path(path)
    files = [path] if path.suffix == ".py" else sorted(path.rglob("*.py"))
    skip = [Path(e).resolve() for e in exclude]
    return [f for f in files if not any(f.resolve() == s or s in f.resolve().parents for s in skip)]


def coverage(path, exclude=()):
    """Counts over the ``.py`` files under ``path`` (or the file) but ``exclude``, and what each function misses.

    Returns ``(counts, missing)``: counts of :data:`COUNTS`, and one line ``file:line name typed=… numpydoc=…``
    (or ``(class) no docstring``) per public definition that misses something.
    """
    counts = dict.fromkeys(COUNTS, 0)
    missing = []
    for file in python_files(path, exclude):
        for name, node, doc in public_definitions(ast.parse(file.read_text(encoding="utf-8"))):
            counts["definitions"] += 1
            counts["documented"] += bool(doc)
            if isinstance(node, FUNCTIONS):
                typed, sections = fully_typed(node), bool(doc) and has_numpydoc_sections(node, doc)
                counts["functions"] += 1
                counts["typed"] += typed
                counts["numpydoc"] += sections
                if not (typed and sections):
                    missing.append(f"{file}:{node.lineno} {name} typed={typed} numpydoc={sections}")
            elif not doc:
                missing.append(f"{file}:{node.lineno} {name} (class) no docstring")
    return counts, missing


def shares(counts):
    """Percentages: documented of the definitions, typed and numpydoc of the functions (100 when there are none)."""
    def share(k, n):
        return 100.0 * counts[k] / counts[n] if counts[n] else 100.0

    return {"documented": share("documented", "definitions"), "typed": share("typed", "functions"),
            "numpydoc": share("numpydoc", "functions")}
