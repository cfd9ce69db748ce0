#!/usr/bin/env bash
# The main job: set-up, build the FMU, synthesize the demo campaign (it hides
# the paper's own first-named error source: soil that varies over the test
# area), then identify, validate, diagnose and write out/report/report.md.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
campaign=${JUNO_CAMPAIGN:-out/demo-campaign}
report=${JUNO_REPORT:-out/report}
if [ -z "${JUNO_CAMPAIGN:-}" ]; then
  .venv/bin/juno synthesize "$campaign" --effect "${JUNO_DEMO_EFFECT:-soil_patch}" --strength 0.8 --seed 2013 --overwrite \
    --time-scale "${JUNO_TIME_SCALE:-1.0}"
fi
.venv/bin/juno report "$campaign" --out "$report" ${JUNO_REPORT_FLAGS:---diagnose} --json "$report.json"
echo "main: report at $report/report.md"
