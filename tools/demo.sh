#!/usr/bin/env bash
# The main job on a fresh machine: virtual environment, install, then a headless closed-loop run
# of the cell that writes a Meshcat HTML recording.
# Usage: bash tools/demo.sh [SCENARIO] [FLAGS...]   (FLAGS go to `hrc-drake simulate`, e.g. --lean)
set -euo pipefail
cd "$(dirname "$0")/.."
scenario="row8-forces-4-then-8"
# A first argument that starts with "-" is a flag for simulate, not a scenario.
if [ $# -gt 0 ] && [ "${1#-}" = "$1" ]; then
  scenario="$1"
  shift
fi
# Install only when needed: the stamp is written after a good install, so a venv whose install
# is older than pyproject.toml (or never finished) is installed again; a current one is reused.
stamp=.venv/.hrc_drake-demo-installed
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
if [ ! -x .venv/bin/hrc-drake ] || [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  .venv/bin/python -m pip install --quiet --upgrade pip
  .venv/bin/python -m pip install --quiet -e .
  touch "$stamp"
fi
mkdir -p out
# A lean run (0.5 s holds) gets its own recording, so that it does not replace the full run's.
record="out/$scenario.html"
for arg in "$@"; do
  if [ "$arg" = "--lean" ]; then
    record="out/$scenario-lean.html"
  fi
done
echo "demo: recording to $record" >&2
.venv/bin/hrc-drake simulate --scenario "$scenario" --record "$record" "$@"
