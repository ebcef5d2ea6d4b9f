#!/usr/bin/env bash
# The main job on a fresh machine: virtual environment, install, then a headless closed-loop run
# of the cell that writes a Meshcat HTML recording. Usage: bash tools/demo.sh [SCENARIO] [--lean]
set -euo pipefail
cd "$(dirname "$0")/.."
scenario="${1:-row8-forces-4-then-8}"
shift || true
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e .
mkdir -p out
.venv/bin/hrc-drake simulate --scenario "$scenario" --record "out/$scenario.html" "$@"
