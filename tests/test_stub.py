"""The hand-kept type stub of the extension (python/granflow/_core.pyi) lists exactly what the
extension exports, its signatures match the extension (mypy's stubtest), and the package's use
of it type-checks (mypy)."""

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest
from granflow import _core

ROOT = Path(__file__).resolve().parents[1]
STUB = ROOT / "python" / "granflow" / "_core.pyi"


def _stub_names() -> tuple[set[str], dict[str, set[str]]]:
    tree = ast.parse(STUB.read_text())
    top: set[str] = set()
    members: dict[str, set[str]] = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            top.add(node.name)
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) \
                and not node.target.id.startswith("_"):
            top.add(node.target.id)
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


def _stubtest(env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "mypy.stubtest", "granflow._core"],
                          capture_output=True, text=True, timeout=600, cwd=ROOT,
                          env={**os.environ, **(env or {})})


def test_stub_signatures_match_the_extension():
    """mypy's stubtest: every name, signature, property and class flag of the stub against the
    built extension."""
    r = _stubtest()
    assert r.returncode == 0, r.stdout + r.stderr


def test_stubtest_catches_a_wrong_stub(tmp_path):
    pkg = tmp_path / "granflow"
    pkg.mkdir()
    (pkg / "__init__.pyi").write_text("")
    good = "def hertz_zeta(e_n: float) -> float: ..."
    assert good in STUB.read_text()
    (pkg / "_core.pyi").write_text(
        STUB.read_text().replace(good, "def hertz_zeta(e_n: float, k: int) -> float: ..."))
    r = _stubtest({"MYPYPATH": str(tmp_path)})
    assert r.returncode != 0 and "hertz_zeta" in r.stdout, r.stdout + r.stderr


def test_package_use_of_the_stub_type_checks(tmp_path):
    """The package's calls into the extension are checked against the stub (as the mypy step of
    scripts/test.sh), and a wrong call is caught."""
    mypy_api = pytest.importorskip("mypy.api")
    out, err, status = mypy_api.run([str(ROOT / "python" / "granflow")])
    assert status == 0, out + err
    wrong = tmp_path / "wrong_use.py"
    wrong.write_text("from granflow import _core\n\n_core.hertz_zeta('0.5')\n")
    out, err, status = mypy_api.run([str(wrong)])
    assert status == 1 and "arg-type" in out, out + err
