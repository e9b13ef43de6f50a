#!/usr/bin/env bash
# On the GPU machine: the call that brings the last staged part (or any call after it).
# Receives this call's part (tools/device_receive.sh), puts a partial record carried in
# .stage/gpu_check beside the output (the check keeps only what the same card measured with
# the same code), then runs the GPU check into $OUT/gpu_check within BUDGET seconds:
#   bash tools/device_check.sh [BUDGET [CHECK OPTIONS...]]     (default 420)
# e.g. `bash tools/device_check.sh 540 --skip iterations_halfcheetah,...`: the options go to
# python -m benchmarks.gpu_check as they are.
set -uo pipefail
bash tools/device_receive.sh || exit $?
out="${OUT:?the device tool sets OUT, the folder whose files come back}/gpu_check"
mkdir -p "$out"
if [ -f .stage/gpu_check/gpu_check.json ]; then
  cp .stage/gpu_check/gpu_check.json "$out/"
fi
PYTHONPATH="${QDIL_STAGE_SITE:-/tmp/site}:src" \
  python3 -m benchmarks.gpu_check --out "$out" --budget "${1:-420}" "${@:2}"
