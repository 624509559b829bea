"""Dependencies point one way: an AST scan of every import (module top and function bodies) of the project.

Layers, lowest first: ``fea`` (imports no other package of the project), ``models`` (none either),
``meshes`` (``fea`` only), then ``twin``.  Inside ``twin``: ``errors`` imports nothing of the project,
``core`` only the lower packages and ``errors``, ``infra`` also ``core``; the capability subpackages
(``run``, ``compensation``, ``placement``, ``rom``, ``fmu``, ``gap``, ``live``) may use all of those and each
other.  Nothing imports the command-line dispatcher ``twin.cli`` or the ``twin`` façade itself.
"""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LOWER = ("fea", "models", "meshes")
CAPABILITIES = ("twin.run", "twin.compensation", "twin.placement", "twin.rom", "twin.fmu", "twin.gap",
                "twin.live")
#: Layer → the layers it may import (a layer always may import itself).
ALLOWED = {
    "fea": (),
    "models": (),
    "meshes": ("fea",),
    "twin.errors": (),
    "twin.core": (*LOWER, "twin.errors"),
    "twin.infra": (*LOWER, "twin.errors", "twin.core"),
    **{c: (*LOWER, "twin.errors", "twin.core", "twin.infra", *CAPABILITIES) for c in CAPABILITIES},
    "twin.cli": (*LOWER, "twin.errors", "twin.core", "twin.infra", *CAPABILITIES),
}


def layer(module):
    """The layer a dotted module name belongs to (``twin.gap.fit`` → ``twin.gap``), or None outside the project."""
    for name in sorted(ALLOWED, key=len, reverse=True):
        if module == name or module.startswith(name + "."):
            return name
    return "twin" if module == "twin" else None


def module_name(path):
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(source, module, is_package=False):
    """(line, dotted module) of every import in ``source``; relative imports resolved against ``module``."""
    package = module if is_package else module.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1] + ([node.module] if node.module else []))
            found.append((node.lineno, base))
            # ``from package import submodule`` reaches the submodule
            found += [(node.lineno, f"{base}.{alias.name}") for alias in node.names
                      if layer(f"{base}.{alias.name}") != layer(base)]
    return found


def violations(source, module, is_package=False):
    """Imports of ``module`` that point up (or sideways into a forbidden layer), as readable lines."""
    own = layer(module)
    bad = []
    for line, target in imported_modules(source, module, is_package):
        other = layer(target)
        if other is None or other == own:
            continue
        if other == "twin" or other == "twin.cli" or other not in ALLOWED[own]:
            bad.append(f"{module}:{line} imports {target} ({own} must not use {other})")
    return bad


def project_files():
    return sorted(p for package in ("fea", "models", "meshes", "twin") for p in (ROOT / package).rglob("*.py"))


def test_every_project_module_is_in_a_layer():
    assert [str(p) for p in project_files() if layer(module_name(p)) is None or
            layer(module_name(p)) == "twin" and p.name != "__init__.py"] == []


def test_no_import_points_up():
    bad = []
    for path in project_files():
        module = module_name(path)
        if module == "twin":
            continue                       # the façade: its public names are imported on use, by name
        bad += violations(path.read_text(encoding="utf-8"), module, path.name == "__init__.py")
    assert bad == []


@pytest.mark.parametrize("module, source", [
    ("twin.core.scenario", "from ..gap.diagnose import diagnose\n"),          # core → capability
    ("twin.infra.plots", "def f():\n    from ..rom import reduction\n"),      # in a function, and a submodule
    ("twin.core.machine", "from ..infra.sweep import cached\n"),               # core → infra
    ("fea.mesh", "import meshes.builder\n"),                                  # fea → meshes
    ("models.anfis", "from fea import TetMesh\n"),                            # models → fea
    ("meshes.builder", "from twin.core.dataset import Dataset\n"),            # meshes → twin
    ("twin.gap.fit", "from twin import cli\n"),                               # anything → the dispatcher
])
def test_the_scan_finds_an_upward_import(module, source):
    assert violations(source, module)


def test_the_scan_allows_what_the_layers_allow():
    assert violations("from ..core.dataset import Dataset\nfrom ..infra import plots\nimport fea\n",
                      "twin.placement.study") == []
    assert violations("from .mesh import TetMesh\n", "fea.heat") == []


def test_the_public_api_resolves():
    import meshes
    import twin
    from twin.core import simulate

    assert [name for name in twin.__all__ if getattr(twin, name, None) is None] == []
    assert [name for name in meshes.__all__ if getattr(meshes, name, None) is None] == []
    assert twin.simulate is simulate.simulate and "placement_study" in dir(twin)
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        twin.no_such_name
