#!/usr/bin/env bash
# The whole test suite: format and lint checks (cargo fmt, clippy, ruff, mypy), the API reference
# build (mkdocs --strict), the Rust kernel tests (cargo test) and the Python tests
# (pytest). Exits non-zero if any check or test fails.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
. .venv/bin/activate
echo "== cargo fmt --check"
cargo fmt --all --check
echo "== cargo clippy"
cargo clippy --workspace --all-targets --release -- -D warnings
echo "== cargo test (kernel)"
cargo test --workspace --exclude granflow-python --release
echo "== ruff"
ruff check python tests benchmarks examples
echo "== mypy"
mypy python/granflow
echo "== API reference (mkdocs --strict: a stale name in a docstring fails)"
mkdocs build --strict --quiet
echo "== pytest"
python -m pytest -q tests
