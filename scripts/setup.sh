#!/usr/bin/env bash
# One-time set-up shared by demo.sh and test.sh: a virtual environment in .venv with granflow
# built from this checkout (release build of the Rust extension), its test dependencies and the
# API reference's (mkdocs).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    "$PY" -m venv .venv
fi
. .venv/bin/activate
python -m pip install --quiet --upgrade pip
# Rebuild only when the sources changed since the last install.
stamp=.venv/.granflow-build-stamp
hash=$(cat Cargo.toml pyproject.toml bindings/Cargo.toml $(git ls-files src bindings python 2>/dev/null || find src bindings python -type f) 2>/dev/null | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$hash" ]; then
    python -m pip install --quiet ".[test,docs]"
    echo "$hash" > "$stamp"
fi
