"""The package's layers, read from its imports (with ``ast``, nothing is run):
no import circle anywhere, and every import points down.

    helpers.__main__
    cli             (the commands, what they write, the notebooks' cached run)
    site            (may use viz)
    viz, exercises
    quality         (metrics, the grade against the truth, the trust flag)
    slam            (the estimator)
    sim             (the simulator)
    config, and the flat modules beside the folders (errors, geometry, paths, outdir, ...)

Within a layer a module may import its neighbours; a layer never imports one
above it, and the trust flag never reaches the ground-truth grader.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "helpers"
LAYERS = {"sim": 1, "slam": 2, "quality": 3, "viz": 4, "exercises": 4, "site": 5, "cli": 6, "__main__": 7}
GRADER = "helpers.quality.evaluation"
TRUST = (
    "helpers.quality.trust",
    "helpers.quality.trust_rules",
    "helpers.quality.trust_facts",
    "helpers.quality.graph_checks",
)
MAX_FLAT_MODULES = 8


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(root: Path) -> dict[str, set[str]]:
    """Module -> the package's modules it imports, anywhere in its body (a function's import counts too)."""
    modules = {module_name(p, root): p for p in root.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                candidates = [f"{base}.{alias.name}" for alias in node.names] + [base]
            elif isinstance(node, ast.Import):
                candidates = [alias.name for alias in node.names]
            else:
                continue
            for candidate in candidates:
                if candidate in modules and candidate != name:
                    targets.add(candidate)
                    break
        graph[name] = targets
    return graph


def rank(module: str) -> int:
    parts = module.split(".")
    return LAYERS.get(parts[1], 0) if len(parts) > 1 else 0


def upward_arrows(graph: dict[str, set[str]]) -> list[str]:
    return [
        f"{a} -> {b}"
        for a, targets in sorted(graph.items())
        for b in sorted(targets)
        if rank(b) > rank(a) or (rank(b) == rank(a) > 0 and a.split(".")[1] != b.split(".")[1])
    ]


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), and self-imports."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def reaches(graph: dict[str, set[str]], start: str, goal: str) -> bool:
    seen, todo = set(), [start]
    while todo:
        v = todo.pop()
        if v == goal:
            return True
        if v not in seen:
            seen.add(v)
            todo.extend(graph.get(v, ()))
    return False


def test_the_package_has_no_import_circle():
    assert circles(import_graph(PACKAGE)) == []


def test_every_import_points_down():
    assert upward_arrows(import_graph(PACKAGE)) == []


def test_the_trust_flag_never_reaches_the_ground_truth_grader():
    graph = import_graph(PACKAGE)
    assert GRADER in graph and all(t in graph for t in TRUST)
    assert [t for t in TRUST if reaches(graph, t, GRADER)] == []


def test_the_layers_are_folders_with_few_modules_beside_them():
    flat = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(flat) <= MAX_FLAT_MODULES, flat
    assert {"sim", "slam", "quality", "cli", "config"} <= {p.name for p in PACKAGE.iterdir() if p.is_dir()}


@pytest.fixture
def planted(tmp_path):
    """A small copy of the layout to plant faults in: helpers/{errors,sim/a,slam/b,quality/c}.py."""
    root = tmp_path / "helpers"
    for folder in ("", "sim", "slam", "quality"):
        (root / folder).mkdir(exist_ok=True)
        (root / folder / "__init__.py").write_text("")
    (root / "errors.py").write_text("")
    (root / "sim" / "a.py").write_text("from helpers.errors import *\n")
    (root / "slam" / "b.py").write_text("from helpers.sim import a\n")
    (root / "quality" / "c.py").write_text("from ..slam.b import thing\n")
    return root


def test_the_checks_find_a_planted_circle_and_an_upward_arrow(planted):
    graph = import_graph(planted)
    assert circles(graph) == [] and upward_arrows(graph) == []
    assert graph["helpers.quality.c"] == {"helpers.slam.b"}  # a relative import is resolved
    (planted / "sim" / "a.py").write_text("def late():\n    from helpers.slam.b import x\n")  # inside a function
    graph = import_graph(planted)
    assert circles(graph) == [["helpers.sim.a", "helpers.slam.b"]]
    assert upward_arrows(graph) == ["helpers.sim.a -> helpers.slam.b"]
    (planted / "sim" / "a.py").write_text("import helpers.quality.c\n")
    assert upward_arrows(import_graph(planted)) == ["helpers.sim.a -> helpers.quality.c"]


def test_the_public_names_resolve_and_the_reference_helpers_are_at_the_top():
    import helpers
    import helpers.quality
    import helpers.sim
    import helpers.slam

    for package in (helpers, helpers.sim, helpers.slam, helpers.quality):
        assert sorted(dir(package)) == sorted(package.__all__)
        assert all(getattr(package, name) is not None for name in package.__all__)
    assert "helperCreateDataset" in helpers.create_dataset.__doc__
    assert "helperEstimateLoopCandidates" in helpers.find_loop_candidates.__doc__
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        helpers.no_such_name  # noqa: B018


def test_the_notebooks_import_few_module_paths():
    """The notebooks (and their solutions) take what they use from a handful of the package's paths."""
    import json
    import re

    paths = set()
    for notebook in (PACKAGE.parent / "notebooks").rglob("*.ipynb"):
        for cell in json.loads(notebook.read_text())["cells"]:
            if cell["cell_type"] == "code":
                source = "".join(cell["source"])
                paths |= set(re.findall(r"^\s*from\s+(helpers[\w.]*)\s+import", source, re.M))
                paths |= set(re.findall(r"^\s*import\s+(helpers[\w.]*)", source, re.M))
    assert "helpers" in paths and len(paths) <= 12, sorted(paths)


def test_the_distribution_ships_every_layer():
    """pyproject.toml's package discovery finds every package folder, so an installed copy has them all."""
    import tomllib

    from setuptools import find_packages

    pyproject = tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())
    found = set(find_packages(str(PACKAGE.parent), **pyproject["tool"]["setuptools"]["packages"]["find"]))
    folders = {module_name(p, PACKAGE) for p in PACKAGE.rglob("__init__.py")}
    assert folders and folders <= found, sorted(folders - found)
