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
LAYERS = ["tasks", "envs", "vlm", "data", "grounding", "fullmodel", "rewards", "rl", "policy", "evaluation",
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
    """The module's dotted name, as a list (a package's __init__ is the package)."""
    parts = ["zsrm", *path.relative_to(PACKAGE).with_suffix("").parts]
    return parts[:-1] if parts[-1] == "__init__" else parts


def _imported_modules(path: Path) -> list[tuple[int, str]]:
    """(line, dotted name) of every zsrm module this file imports."""
    tree = ast.parse(path.read_text(), filename=str(path))
    here = _dotted(path)
    package = here if path.name == "__init__.py" else here[:-1]
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
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and _MODULE_STRING.match(node.value):
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


def test_library_code_never_imports_the_cli():
    bad = [f"{_where(path, line)}: {src} imports zsrm.{CLI}" for path, line, src, dst in _imports()
           if dst == CLI and src != CLI]
    assert not bad, "\n".join(bad)


def _readme_layout_packages() -> list[str]:
    text = (ROOT / "README.md").read_text()
    section = text.split("## Pipeline and layout", 1)[1].split("\n## ", 1)[0]
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
