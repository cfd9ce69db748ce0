#!/usr/bin/env bash
# Every test: set-up, then the C unit tests (ctest) and the Python suite (pytest).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/checks.sh   # sanitizers, valgrind, fuzzing, win64 (README "Checks")
echo "== C unit tests (ctest)"
(cd build && ctest --output-on-failure)
echo "== Python tests (pytest)"
.venv/bin/python -m pytest tests/python -q -p no:cacheprovider --durations=25 "$@"
