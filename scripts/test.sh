#!/usr/bin/env bash
# Set up everything and run every test: toolchain + package install, lint, types, pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
PY=${PYTHON:-python3}
echo "== firmware"; make -s -C firmware all sim
echo "== ruff";   "$PY" -m ruff check .
echo "== mypy";   "$PY" -m mypy
echo "== pytest"; "$PY" -m pytest "$@"
