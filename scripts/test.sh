#!/usr/bin/env bash
# The whole test suite: Rust kernel tests (cargo test) and Python tests (pytest), plus lint.
# Exits non-zero if any test fails.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
. .venv/bin/activate
echo "== cargo test (kernel)"
cargo test --workspace --exclude granflow-python --release
echo "== ruff"
ruff check python tests benchmarks examples
echo "== mypy"
mypy python/granflow
echo "== pytest"
python -m pytest -q tests
