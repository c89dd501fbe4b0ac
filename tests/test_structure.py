"""The code's structure: no import cycle inside the packages, no oversized file.

Imports are read from the source (``ast``), not by importing: every ``import`` and
``from … import`` of a module of ``golden_model``, ``hdl`` or ``sim``, at any depth (a function's
own imports and ``TYPE_CHECKING`` blocks too), is an edge from the importing module to the module
it names; ``from package import name`` is an edge to ``package.name`` when that is a module, else
to the package.  A cycle is a strongly connected set of more than one module (or a module that
imports itself).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from support import LONGEST_FIRST, REPO, TESTS

PACKAGES = ("golden_model", "hdl", "sim")
MAX_LINES = 800
SIZE_CHECKED = ("golden_model", "hdl")

def module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def package_modules(packages=PACKAGES) -> dict[str, Path]:
    return {module_name(p): p for pkg in packages for p in sorted((REPO / pkg).rglob("*.py"))}


def import_edges(modules: dict[str, Path]) -> set[tuple[str, str]]:
    """``(importer, imported)`` pairs between the given modules (see the module docstring)."""
    edges = set()
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
                stem = ".".join(base + ([node.module] if node.module else []))
                targets = [f"{stem}.{a.name}" if f"{stem}.{a.name}" in modules else stem for a in node.names]
            else:
                continue
            for target in targets:
                while target and target not in modules:  # "a.b.c" of a module a.b: its attribute c
                    target = target.rpartition(".")[0]
                if target:
                    edges.add((name, target))
    return edges


def import_cycles(modules: dict[str, Path], edges: set[tuple[str, str]]) -> list[list[str]]:
    """The strongly connected sets of more than one module, and the modules importing themselves."""
    names = sorted(modules)
    index = {n: i for i, n in enumerate(names)}
    rows, cols = zip(*((index[a], index[b]) for a, b in edges)) if edges else ((), ())
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(names), len(names)))
    _, labels = connected_components(graph, directed=True, connection="strong")
    groups: dict[int, list[str]] = {}
    for n, label in zip(names, labels):
        groups.setdefault(label, []).append(n)
    cycles = [g for g in groups.values() if len(g) > 1]
    cycles += [[a] for a, b in edges if a == b]
    return sorted(cycles)


def test_no_import_cycle_in_the_packages():
    modules = package_modules()
    assert len(modules) > 50  # the walk found the code
    cycles = import_cycles(modules, import_edges(modules))
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_the_cycle_check_finds_a_cycle(tmp_path):
    """The check itself: two modules importing each other, one through a function's own import."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .b import f\n")
    (pkg / "b.py").write_text("def f():\n    from pkg import a\n")
    (pkg / "c.py").write_text("import pkg.a\n")
    modules = {".".join(p.relative_to(tmp_path).with_suffix("").parts).removesuffix(".__init__"): p
               for p in pkg.rglob("*.py")}
    assert import_cycles(modules, import_edges(modules)) == [["pkg.a", "pkg.b"]]


def test_the_package_direction_holds():
    """golden_model <- hdl <- sim: no module imports from a package above its own."""
    modules = package_modules()
    rank = {pkg: k for k, pkg in enumerate(PACKAGES)}
    upward = sorted((a, b) for a, b in import_edges(modules) if rank[b.split(".")[0]] > rank[a.split(".")[0]])
    assert not upward, f"imports against golden_model <- hdl <- sim: {upward}"


def outside_imports(path: Path) -> set[str]:
    """The top-level names of the absolute imports in one file, at any depth (as :func:`import_edges` reads)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_the_golden_model_needs_numpy_alone():
    """golden_model is the model, numpy only (the README's layout): libraries such as libigl, scipy or trimesh
    belong to the flows in sim/ (start layouts, untangling, mesh files, generated meshes)."""
    allowed = set(sys.stdlib_module_names) | {"numpy", "golden_model"}
    modules = package_modules(("golden_model",))
    found = {module: sorted(outside_imports(path) - allowed) for module, path in modules.items()}
    outside = {module: names for module, names in found.items() if names}
    assert not outside, f"golden_model imports beyond numpy: {outside}"


def test_the_numpy_alone_check_sees_a_function_level_import(tmp_path):
    """The check itself: an import inside a function counts."""
    (tmp_path / "m.py").write_text("import numpy as np\nfrom . import x\n"
                                   "def f():\n    from scipy.sparse import csgraph\n")
    assert outside_imports(tmp_path / "m.py") == {"numpy", "scipy"}


def source_lengths() -> dict[str, int]:
    return {str(p.relative_to(REPO)): len(p.read_text().splitlines())
            for pkg in SIZE_CHECKED for p in sorted((REPO / pkg).rglob("*.py"))}


def test_no_file_over_800_lines():
    lengths = source_lengths()
    over = {f: n for f, n in lengths.items() if n > MAX_LINES}
    assert not over, f"files over {MAX_LINES} lines (split them): {over}"


def test_the_longest_first_files_exist():
    """``make test`` starts these files first (``tests/conftest.py``); a renamed one would silently start last."""
    missing = [name for name in LONGEST_FIRST if not (TESTS / name).is_file()]
    assert not missing, f"LONGEST_FIRST names files that do not exist: {missing}"
