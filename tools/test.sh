#!/usr/bin/env bash
# Fresh virtual environment, project installed with its dev extras, then the whole test suite.
# This is the README's test command; .ci/run calls it.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e '.[dev]'
.venv/bin/ruff check .
.venv/bin/ruff format --check .
set +e
# Two workers: the closed-loop physics runs are most of the time and the machine has two cores.
# The slowest tests are listed at the end: the suite has a 20-minute budget on two cores.
.venv/bin/python -m pytest -n 2 --dist worksteal --durations=25 "$@"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
  echo "pytest collected no tests: treating that as a failure" >&2
  exit 1
fi
exit "$rc"
