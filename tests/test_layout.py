"""The package layout: layers that read as the pipeline, each importing only from the ones below.

``LAYERS`` is the one place the order is written; the README's layout table must list the
same packages in the same order. The import graph is read from the source with ``ast`` (every
``import``, ``from ... import`` and relative import, also those inside functions, and module
paths written as strings for lazy imports), so a violation fails here before it runs.
"""
from __future__ import annotations

import ast
import re
import sys
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "zsrm"

# Bottom to top. A package may import from the packages before it, never from those after it.
LAYERS = ["common", "tasks", "envs", "vlm", "data", "grounding", "fullmodel", "rewards", "rl", "policy", "evaluation",
          "pipeline", "testing", "cli"]
CLI = "cli"
# Pairs the order allows but the design does not: (package, package it must not import, why).
APART = [("vlm", "envs", "the VLM knows no simulator: the renders it learns from are data, handed to it"),
         ("rewards", "envs", "a reward sees pixels and text; rollouts along scripted controllers are evaluation")]
MAX_FUNCTION_LINES = 60

_MODULE_STRING = re.compile(r"^zsrm(\.[A-Za-z_][A-Za-z0-9_]*)+$")


def _modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def _layer_of(path: Path) -> str | None:
    """The layer package a source file belongs to (None for zsrm/__init__.py)."""
    parts = path.relative_to(PACKAGE).parts
    return parts[0] if len(parts) > 1 else None


def _dotted(path: Path) -> list[str]:
    """The module's dotted name, as a list (a package's __init__ is the package); a script's, its name."""
    if PACKAGE not in path.parents:
        return [path.stem]
    parts = ["zsrm", *path.relative_to(PACKAGE).with_suffix("").parts]
    return parts[:-1] if parts[-1] == "__init__" else parts


def _imported_modules(path: Path) -> list[tuple[int, str]]:
    """(line, dotted name) of every zsrm module this file imports."""
    tree = ast.parse(path.read_text(), filename=str(path))
    here = _dotted(path)
    package = here if path.name == "__init__.py" else here[:-1]
    # a package named for its data files (importlib.resources.files("zsrm.envs")) is not imported
    data = {id(node.args[0]) for node in ast.walk(tree) if isinstance(node, ast.Call) and node.args
            and getattr(node.func, "attr", getattr(node.func, "id", None)) == "files"}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                base = package[:len(package) - node.level + 1] + ([node.module] if node.module else [])
                name = ".".join(base)
            else:
                name = node.module or ""
            out.append((node.lineno, name))
            out += [(node.lineno, f"{name}.{alias.name}") for alias in node.names]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and _MODULE_STRING.match(node.value) \
                and id(node) not in data:
            out.append((node.lineno, node.value))  # lazy imports by name (importlib)
    return [(line, name) for line, name in out if name == "zsrm" or name.startswith("zsrm.")]


def _imports() -> list[tuple[Path, int, str, str]]:
    """(file, line, importing layer, imported layer) for every import across layers."""
    out = []
    for path in _modules():
        src = _layer_of(path)
        for line, name in _imported_modules(path):
            parts = name.split(".")
            dst = parts[1] if len(parts) > 1 else None
            if dst is not None and dst != src and (PACKAGE / dst).is_dir():
                out.append((path, line, src, dst))
    return out


def _where(path: Path, line: int) -> str:
    return f"{path.relative_to(ROOT)}:{line}"


def _module_file(name: str) -> Path | None:
    """The source file of the longest zsrm module a dotted name starts with (``zsrm.rl.envs.make_vec``
    -> zsrm/rl/envs.py; a package is its __init__.py)."""
    parts = name.split(".")
    for n in range(len(parts), 1, -1):
        base = ROOT.joinpath(*parts[:n])
        for path in (base.with_suffix(".py"), base / "__init__.py"):
            if path.is_file() and PACKAGE in path.parents:
                return path
    return None


def _file_graph() -> dict[Path, set[Path]]:
    """file -> the zsrm files it imports (lazy imports inside functions included)."""
    graph: dict[Path, set[Path]] = defaultdict(set)
    for path in _modules():
        for _, name in _imported_modules(path):
            target = _module_file(name)
            if target is not None and target != path:
                graph[path].add(target)
    return graph


def _circles(graph: dict[Path, set[Path]]) -> list[list[Path]]:
    """One shortest circle through each file that lies on one (breadth-first from the file)."""
    out, seen = [], set()
    for start in sorted(graph):
        if start in seen:
            continue
        parents, frontier = {start: None}, [start]
        while frontier and start not in seen:
            nxt = []
            for node in frontier:
                for dst in sorted(graph.get(node, ())):
                    if dst == start:
                        circle = [node]
                        while parents[circle[-1]] is not None:
                            circle.append(parents[circle[-1]])
                        circle = circle[::-1]
                        out.append(circle)
                        seen.update(circle)
                        break
                    if dst not in parents:
                        parents[dst] = node
                        nxt.append(dst)
                if start in seen:
                    break
            frontier = nxt
    return out


def test_every_package_is_a_layer():
    packages = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert packages <= set(LAYERS), f"packages missing from LAYERS: {sorted(packages - set(LAYERS))}"
    loose = [p.name for p in PACKAGE.glob("*.py") if p.name != "__init__.py"]
    assert not loose, f"modules outside a layer package: {loose}"
    assert not _imported_modules(PACKAGE / "__init__.py"), "zsrm/__init__.py must import nothing of zsrm"


def test_no_layer_imports_a_higher_one():
    rank = {name: i for i, name in enumerate(LAYERS)}
    bad = [f"{_where(path, line)}: {src} imports {dst}" for path, line, src, dst in _imports()
           if rank[dst] > rank[src]]
    assert not bad, "lower layers import higher ones:\n" + "\n".join(bad)


@pytest.mark.parametrize("src, dst, why", APART)
def test_packages_kept_apart(src, dst, why):
    bad = [_where(path, line) for path, line, a, b in _imports() if (a, b) == (src, dst)]
    assert not bad, f"{src} imports {dst} ({why}): " + ", ".join(bad)


def test_no_import_circle_between_packages():
    graph: dict[str, set[str]] = defaultdict(set)
    for _, _, src, dst in _imports():
        graph[src].add(dst)

    def reaches(start: str, goal: str, seen: set[str]) -> bool:
        for nxt in graph[start]:
            if nxt == goal or (nxt not in seen and reaches(nxt, goal, seen | {nxt})):
                return True
        return False

    circles = sorted(src for src in list(graph) if reaches(src, src, {src}))
    assert not circles, f"packages on an import circle: {circles}"


def test_no_import_circle_between_files():
    circles = _circles(_file_graph())
    text = [" -> ".join(str(p.relative_to(ROOT)) for p in [*c, c[0]]) for c in circles]
    assert not circles, "files on an import circle:\n" + "\n".join(text)


def test_the_circle_finder_finds_a_circle(tmp_path):
    a, b, c = tmp_path / "a.py", tmp_path / "b.py", tmp_path / "c.py"
    assert _circles({a: {b}, b: {c}, c: {a}}) == [[a, b, c]]
    assert _circles({a: {b}, b: {c}}) == []


# The shared helpers live in zsrm.common; zsrm.vlm is about vision-language models only.
SHARED_MODULES = {"files", "registry", "optim", "checkpoints"}


def _shared_names() -> set[str]:
    """Top-level functions, classes and constants of the zsrm.common modules."""
    names = set()
    for path in (PACKAGE / "common").glob("*.py"):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                names.add(node.name)
            elif isinstance(node, ast.Assign):
                names.update(t.id for t in node.targets if isinstance(t, ast.Name))
    return names


def _shared_from_vlm() -> list[str]:
    """Imports of the shared helpers through zsrm.vlm, in the repo's Python files outside zsrm/vlm/."""
    shared, out = SHARED_MODULES | _shared_names(), []
    paths = [p for top in ("zsrm", "tests", "benchmarks", "probes", "tools") for p in (ROOT / top).rglob("*.py")]
    for path in sorted(paths):
        rel = path.relative_to(ROOT)
        if (PACKAGE / "vlm") in path.parents:
            continue
        for line, name in _imported_modules(path):
            parts = name.split(".")
            if parts[:2] == ["zsrm", "vlm"] and shared & set(parts[2:]):
                out.append(f"{rel}:{line}: {name}")
    return out


def test_shared_helpers_are_not_imported_from_the_vlm_package():
    bad = _shared_from_vlm()
    assert not bad, "import these from zsrm.common, not zsrm.vlm:\n" + "\n".join(bad)


def test_the_vlm_package_holds_none_of_the_shared_modules():
    assert not [m for m in SHARED_MODULES if (PACKAGE / "vlm" / f"{m}.py").exists()]


def test_the_common_package_imports_nothing_else_of_zsrm():
    bad = [f"{_where(path, line)}: {name}" for path in (PACKAGE / "common").glob("*.py")
           for line, name in _imported_modules(path) if not name.startswith("zsrm.common")]
    assert not bad, "\n".join(bad)


def test_library_code_never_imports_the_cli():
    bad = [f"{_where(path, line)}: {src} imports zsrm.{CLI}" for path, line, src, dst in _imports()
           if dst == CLI and src != CLI]
    assert not bad, "\n".join(bad)


def _readme_layout_packages() -> list[str]:
    text = (ROOT / "README.md").read_text()
    section = text.split("## Layout", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("|") and "`zsrm." in line]
    return [re.search(r"`zsrm\.(\w+)`", row.split("|")[2]).group(1) for row in rows]


def test_readme_layout_table_lists_the_layers_in_order():
    assert _readme_layout_packages() == LAYERS


def _long_functions() -> list[str]:
    out = []
    for path in _modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    out.append(f"{_where(path, node.lineno)}: {node.name} has {length} lines")
    return out


def test_no_function_is_longer_than_60_lines():
    long = _long_functions()
    assert not long, "\n".join(long)


@pytest.mark.parametrize("source, expected", [
    ("from zsrm.rewards import BaseReward\n", {"zsrm.rewards", "zsrm.rewards.BaseReward"}),
    ("def f():\n    import zsrm.cli\n", {"zsrm.cli"}),
    ("from ..tasks import Task\n", {"zsrm.tasks", "zsrm.tasks.Task"}),
    ("LAZY = {'x': 'zsrm.evaluation.curves'}\n", {"zsrm.evaluation.curves"}),
])
def test_the_import_reader_sees_every_kind_of_import(tmp_path, monkeypatch, source, expected):
    fake = tmp_path / "zsrm" / "vlm" / "fake.py"
    fake.parent.mkdir(parents=True)
    fake.write_text(source)
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", tmp_path / "zsrm")
    assert {name for _, name in _imported_modules(fake)} == expected
