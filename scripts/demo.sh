#!/usr/bin/env bash
# Set up (first run builds the extension) and run the main demo end to end.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
. .venv/bin/activate
python examples/demo.py "$@"
