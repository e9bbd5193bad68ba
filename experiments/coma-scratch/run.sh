#!/usr/bin/env bash
# Run one diagnostic COMA training: run.sh NAME [ipp-train coma flags...]
# Base: the paper preset (its loss, inputs, eps schedule, lr) from random networks, width 64 /
# hidden 128 for speed, validation every 10 updates on 30 missions.
set -euo pipefail
name=$1; shift
. /work/venv-wt/bin/activate
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
ipp-train coma --preset paper --width 64 --set hidden=128 --feature own_position=false \
  --set eval_every=10 --set eval_missions=30 --set checkpoint_every=10 \
  --out /work/runs/$name --no-progress "$@" > /work/runs/$name.log 2>&1
