"""The package's shape: no import circle among its modules (imports inside functions count: a
lazy import only hides a circle), nothing imports the applications, and the public names are
importable from ``warpsim`` itself."""

import ast
import importlib
import pkgutil
import re
import tomllib
from pathlib import Path

import pytest

import warpsim

ROOT = Path(__file__).resolve().parents[1]


def declared_packages() -> list[str]:
    """The packages ``pyproject.toml`` installs."""
    with open(ROOT / "pyproject.toml", "rb") as f:
        return tomllib.load(f)["tool"]["setuptools"]["packages"]


def package_modules() -> dict[str, Path]:
    """Every module of the declared packages: name -> source file."""
    found = {}
    for name in declared_packages():  # some live in other folders (kernels/, export/)
        package = importlib.import_module(name)
        found[name] = Path(package.__file__)
        for info in pkgutil.iter_modules(package.__path__, f"{name}."):
            if not info.ispkg:
                found[info.name] = Path(importlib.util.find_spec(info.name).origin)
    return found


def test_every_subpackage_is_declared():
    declared = set(declared_packages())
    for name in declared:
        package = importlib.import_module(name)
        for info in pkgutil.iter_modules(package.__path__, f"{name}."):
            assert not info.ispkg or info.name in declared, f"{info.name} is not installed"



def imports_of(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's modules that ``name`` imports anywhere in its source: ``from X import y``
    counts as an import of ``X.y`` when that is a module, of ``X`` otherwise."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                root = ".".join(parts[:len(parts) - node.level + 1])
                base = f"{root}.{base}" if base else root
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                targets.add(sub if sub in modules else base)
    return {t for t in targets if t in modules and t != name}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle of ``graph`` as a list of modules (first repeated last), or None."""
    state = dict.fromkeys(graph, 0)  # 0 unvisited, 1 on the current path, 2 done
    path: list[str] = []

    def visit(node):
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state[nxt] == 1:
                return path[path.index(nxt):] + [nxt]
            if state[nxt] == 0 and (found := visit(nxt)):
                return found
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if state[node] == 0 and (found := visit(node)):
            return found
    return None


def import_graph() -> dict[str, set[str]]:
    modules = package_modules()
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def test_the_cycle_finder_finds_a_planted_circle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None


def test_the_walk_sees_every_part_of_the_package():
    graph = import_graph()
    for name in ("warpsim.apps.cli", "warpsim.analysis.reference", "warpsim.distributed.draw",
                 "warpsim.export.usd_read", "warpsim.kernels.nearest", "warpsim.feasibility"):
        assert name in graph
    assert "warpsim.analysis.reference" in graph["warpsim.analysis.error_report"]


@pytest.mark.slow
def test_no_import_circle_in_the_package():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import circle: " + " -> ".join(cycle)


@pytest.mark.slow
def test_nothing_imports_the_applications():
    graph = import_graph()
    for name, targets in graph.items():
        if name.startswith("warpsim.apps") or name == "warpsim.__main__":
            continue
        assert not {t for t in targets if t.startswith("warpsim.apps")}, name
    assert "warpsim.apps.cli" not in graph["warpsim.apps.bench"]


def test_every_public_name_is_importable_from_warpsim():
    for name in warpsim.__all__:
        assert getattr(warpsim, name) is not None, name
    assert len(set(warpsim.__all__)) == len(warpsim.__all__)


def test_every_name_the_readme_uses_is_public():
    """``ws.X`` and ``warpsim.X`` in the README: a name of ``warpsim.__all__`` or one of the
    package's modules (used as ``warpsim.module.name``), never a private path."""
    readme = ROOT / "README.md"
    if not readme.is_file():
        pytest.skip("README.md not present (installed package)")
    text = readme.read_text(encoding="utf-8")
    modules = {name.split(".")[1] for name in package_modules() if name.count(".") >= 1}
    used = set(re.findall(r"\b(?:ws|warpsim)\.([A-Za-z_]\w*)", text))
    for name in used:
        assert not name.startswith("_"), name
        assert name in warpsim.__all__ or name in modules, f"warpsim.{name} is not public"
    for name in ("PrecisionWarning", "ContactEvents", "ContactKind", "Motion", "BroadPhase"):
        assert name in warpsim.__all__


@pytest.mark.slow
@pytest.mark.parametrize("module", ["warpsim", "warpsim.apps.cli", "warpsim.apps.bench",
                                    "warpsim.analysis.accuracy"])
def test_python_dash_m_entry_points(module):
    """Each ``python -m`` entry point starts, without runpy's warning about a module its
    package imported first."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-W", "error::RuntimeWarning", "-m", module, "--help"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("usage: warpsim")
