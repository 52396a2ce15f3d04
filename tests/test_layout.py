"""The package's layout: imports run one way (the module import graph of python/granflow is
acyclic, and the layers import only downwards: scenes never import studies; analysis never imports
scenes, studies or the continuum models; granflow.states imports nothing of granflow; studies
share code only through their engine, studies._campaign), every module imports on its own, and
module docstrings carry no issue numbers."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "python" / "granflow"


def _module_name(path: Path, pkg: Path = PKG) -> str:
    parts = list(path.relative_to(pkg.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules(pkg: Path = PKG) -> dict[str, Path]:
    return {_module_name(p, pkg): p for p in sorted(pkg.rglob("*.py"))}


def import_graph(pkg: Path = PKG) -> dict[str, set[str]]:
    """module -> the package's modules it imports (anywhere in the file, function bodies
    included: a lazy import closes a circle, and crosses a layer, as well)."""
    mods = _modules(pkg)
    # submodules without Python source (the extension, known by its stub) are leaves
    known = set(mods) | {_module_name(p, pkg) for p in pkg.rglob("*.pyi")}
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = mod.split(".")
                    base = base[: len(base) - node.level + (1 if is_pkg else 0)]
                    src = ".".join(base + ([node.module] if node.module else []))
                else:
                    src = node.module or ""
                targets = [f"{src}.{a.name}" if f"{src}.{a.name}" in known else src
                           for a in node.names]
            for t in targets:
                if t in mods and t != mod:
                    graph[mod].add(t)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A circle of the graph as a list of nodes (first == last), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return stack[stack.index(m):] + [m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state:
            found = visit(n)
            if found:
                return found
    return None


#: layer -> the layers it must not import (a layer is a module and everything below it)
FORBIDDEN: dict[str, tuple[str, ...]] = {
    "granflow.scenes": ("granflow.studies",),
    "granflow.analysis": ("granflow.scenes", "granflow.studies", "granflow.continuum",
                          "granflow.runner", "granflow.cli"),
    "granflow.continuum": ("granflow.scenes", "granflow.studies"),
    "granflow.states": ("granflow",),  # a leaf
}


def _within(mod: str, layer: str) -> bool:
    return mod == layer or mod.startswith(layer + ".")


def layer_violations(graph: dict[str, set[str]],
                     forbidden: dict[str, tuple[str, ...]] = FORBIDDEN) -> list[str]:
    """Every import ``a -> b`` of ``graph`` where ``a``'s layer must not import ``b``'s."""
    out = []
    for mod, targets in sorted(graph.items()):
        for layer, banned in forbidden.items():
            if not _within(mod, layer):
                continue
            out += [f"{mod} -> {t}" for t in sorted(targets)
                    if any(_within(t, b) for b in banned) and not _within(t, layer)]
    return out


def _synthetic_package(root: Path, files: dict[str, str]) -> Path:
    pkg = root / "granflow"
    for rel, text in files.items():
        f = pkg / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
    return pkg


def test_layer_rules_catch_a_violation(tmp_path):
    # a synthetic package breaking each rule once, at module level and inside a function
    pkg = _synthetic_package(tmp_path, {
        "__init__.py": "",
        "states.py": "import granflow.errors\n",
        "errors.py": "",
        "scenes/__init__.py": "",
        "scenes/channel.py": "def f():\n    from ..studies import run\n",
        "studies/__init__.py": "",
        "studies/run.py": "from granflow.scenes import channel\n",
        "analysis/__init__.py": "from . import stats\n",
        "analysis/stats.py": "from granflow.scenes.channel import f\n",
        "analysis/report.py": "def g():\n    import granflow.studies.run\n",
    })
    g = import_graph(pkg)
    assert layer_violations(g) == [
        "granflow.analysis.report -> granflow.studies.run",
        "granflow.analysis.stats -> granflow.scenes.channel",
        "granflow.scenes.channel -> granflow.studies.run",
        "granflow.states -> granflow.errors",
    ]
    # ... and the circle the lazy import closes (scenes.channel -> studies.run -> scenes.channel)
    assert find_cycle(g) == ["granflow.scenes.channel", "granflow.studies.run",
                             "granflow.scenes.channel"]
    # the allowed direction is no violation
    assert layer_violations({"granflow.studies.run": {"granflow.scenes.channel"},
                             "granflow.scenes.channel": {"granflow.analysis.stats"}}) == []


def test_layers_import_downwards():
    bad = layer_violations(import_graph())
    assert not bad, "imports against the layer order: " + "; ".join(bad)


def test_cycle_finder_finds_circles():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_import_graph_sees_relative_and_lazy_imports():
    g = import_graph()
    assert "granflow.scenes._base" in g["granflow.scenes.channel"]  # relative import
    assert "granflow.analysis.channel" in g["granflow.scenes.channel"]  # lazy, in a method
    assert "granflow.scenes.channel" in g["granflow.scenes"]  # package __init__


def test_imports_run_one_way():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import circle: " + " -> ".join(cycle or [])


@pytest.mark.parametrize("name", sorted(_modules()))
def test_every_module_imports(name):
    importlib.import_module(name)


def test_module_docstrings_carry_no_issue_numbers():
    for name, path in _modules().items():
        doc = ast.get_docstring(ast.parse(path.read_text())) or ""
        assert not re.search(r"\bissue\b|#\d", doc, re.I), name


def test_scenes_have_one_home():
    from granflow import scenes
    from granflow.scenes.cell import ShearCell
    from granflow.scenes.channel import Channel

    assert scenes.Channel is Channel and scenes.ShearCell is ShearCell
    assert {"channel", "cell", "gas"} <= set(scenes.SCENES)
    assert scenes.get_scene("channel") is Channel
    for old in ("granflow.channel", "granflow.cell", "granflow.timestep", "granflow.stability",
                "granflow.plotting", "granflow.analysis.errors"):
        with pytest.raises(ModuleNotFoundError):
            importlib.import_module(old)


def study_violations(graph: dict[str, set[str]]) -> list[str]:
    """Imports from one study module of granflow.studies to another: a study reaches others'
    code only through the shared engine, granflow.studies._campaign; a study's report,
    its report's sections and its figure modules (``X_report``, ``X_report_<section>``,
    ``X_figures``) may import its study ``X``, and it them."""
    def study(mod: str) -> str | None:
        parts = mod.split(".")
        if len(parts) < 3 or parts[:2] != ["granflow", "studies"] or parts[2] == "_campaign":
            return None
        return parts[2].split("_report")[0].removesuffix("_figures")

    out = []
    for mod, targets in sorted(graph.items()):
        own = study(mod)
        if own is None:
            continue
        out += [f"{mod} -> {t}" for t in sorted(targets)
                if study(t) is not None and study(t) != own]
    return out


def test_studies_share_code_only_through_the_engine():
    assert study_violations(import_graph()) == []
    assert study_violations({
        "granflow.studies.cross_scene": {"granflow.studies.reproduce_002",
                                         "granflow.studies._campaign.cell",
                                         "granflow.studies.cross_scene_report"},
        "granflow.studies.cross_scene_report": {"granflow.studies.cross_scene",
                                                "granflow.studies.cross_scene_report_bulk"},
        "granflow.studies.reproduce_002_report_x": {"granflow.studies.cross_scene"},
        "granflow.studies.stability": {"granflow.studies.timestep"},
    }) == ["granflow.studies.cross_scene -> granflow.studies.reproduce_002",
           "granflow.studies.reproduce_002_report_x -> granflow.studies.cross_scene",
           "granflow.studies.stability -> granflow.studies.timestep"]


def test_the_committed_reports_print_no_nan():
    """A missing value is written '-' or left out (granflow.studies._campaign.report.pm),
    never as NaN: a report cell with 'nan' is a formatting bug."""
    docs = PKG.parents[1] / "docs"
    bad = [f"{p.name}:{i}: {line.strip()[:120]}" for p in sorted(docs.glob("*.md"))
           for i, line in enumerate(p.read_text().splitlines(), 1)
           if re.search(r"(?<![\w.])nan(?![\w.])", line, re.I)]
    assert not bad, "\n".join(bad)
