"""The hand-kept type stub of the extension (python/granflow/_core.pyi) lists exactly what the
extension exports."""

import ast
from pathlib import Path

from granflow import _core

STUB = Path(__file__).resolve().parents[1] / "python" / "granflow" / "_core.pyi"


def _stub_names() -> tuple[set[str], dict[str, set[str]]]:
    tree = ast.parse(STUB.read_text())
    top: set[str] = set()
    members: dict[str, set[str]] = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            top.add(node.name)
        if isinstance(node, ast.ClassDef):
            members[node.name] = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
    return top, members


def test_stub_lists_every_export():
    top, members = _stub_names()
    exported = {n for n in dir(_core) if not n.startswith("_")}
    assert exported == top
    for cls in ("Sim", "ArrowBatch"):
        real = {n for n in dir(getattr(_core, cls)) if not n.startswith("_")}
        stub = {n for n in members[cls] if not n.startswith("_")}
        assert real == stub, cls
