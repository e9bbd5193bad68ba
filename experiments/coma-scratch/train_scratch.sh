#!/usr/bin/env bash
# Train the scratch recipe for one seed into /work/runs/scratch-sSEED (resumable):
# train_scratch.sh SEED [more ipp-train coma flags, e.g. --resume or --missions N]
set -euo pipefail
seed=$1; shift
. /work/venv-wt/bin/activate
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
ipp-train coma --preset scratch --seed "$seed" --out /work/runs/scratch-s$seed --no-progress \
  "$@" >> /work/runs/scratch-s$seed.log 2>&1
