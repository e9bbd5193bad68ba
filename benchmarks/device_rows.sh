#!/usr/bin/env bash
# Issue 14's rows that need the accelerator machine, in one call (run by hand; figures go
# to experiments/performance/README.md): COMA's update of the `paper` preset on the GPU, in float32 and
# in bfloat16 (benchmarks/coma_throughput.py).
#
#   bash benchmarks/device_rows.sh                                  # there: cuda, paper preset
#   DEVICE=cpu PRESET=cpu RESOLUTION=0.5 UPDATES=1 bash benchmarks/device_rows.sh   # a try here
#
# The lent machine has torch, numba and numpy but cannot fetch packages: the ones its image
# lacks travel as wheels in .whl/ (ignored by git; name it in the run's carry), fetched here
# for its Python 3.12 (versions of constraints.txt):
#
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \
#       --implementation cp --platform manylinux_2_17_x86_64 -d .whl \
#       gymnasium==1.4.0 pettingzoo==1.27.0 farama-notifications==0.0.6
#
# The toolkit itself is used from this checkout (PYTHONPATH), not installed, so the
# machine's own torch serves.
set -euo pipefail
cd "$(dirname "$0")/.."
if compgen -G ".whl/*.whl" > /dev/null; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl
    export PYTHONPATH="/tmp/site:${PYTHONPATH:-}"
fi
export PYTHONPATH="$PWD:${PYTHONPATH:-}"
DEVICE=${DEVICE:-cuda}
PRESET=${PRESET:-paper}
RESOLUTION=${RESOLUTION:-0.1}
UPDATES=${UPDATES:-3}
python3 -c "import torch; print('torch', torch.__version__, '| cuda:', torch.cuda.is_available() and torch.cuda.get_device_name(0))"
for precision in float32 bfloat16; do
    python3 benchmarks/coma_throughput.py --preset "$PRESET" --resolution "$RESOLUTION" \
        --device "$DEVICE" --updates "$UPDATES" --precision "$precision"
done
