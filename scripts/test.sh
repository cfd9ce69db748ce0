#!/usr/bin/env bash
# Every test: set-up, then the C unit tests (ctest) and the Python suite (pytest).
set -euo pipefail
cd "$(dirname "$0")/.."
export JUNO_WERROR=ON   # the tests build with warnings as errors
bash scripts/setup.sh
bash scripts/checks.sh   # sanitizers, valgrind, fuzzing, win64 (docs/checks.md)
echo "== C unit tests (ctest)"
(cd build && ctest --output-on-failure)
echo "== Python tests (pytest)"
# One worker per core (pytest-xdist), a test file per worker: a diagnose test keeps
# both cores busy only part of the time (its base fit and judging are serial), and the other files
# fill the gaps.  The two files of blind diagnoses take about eight minutes each, most of the
# suite: they start first, one per worker, and the short files fill in behind them (longest
# first, not xdist's default of the files with the most tests first).
LONGEST_FIRST=(tests/python/test_diagnose.py tests/python/test_diagnose_how_many_causes.py)
.venv/bin/python -m pytest "${LONGEST_FIRST[@]}" tests/python -q -p no:cacheprovider --durations=25 -n auto \
  --dist loadfile --no-loadscope-reorder "$@"
