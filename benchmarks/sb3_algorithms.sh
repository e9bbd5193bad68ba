#!/usr/bin/env bash
# Which SB3 algorithm to start from: each trained for the same budget of agent-steps at
# 4 UAVs / D = 25 m (r_M = 0.5 m, the paper's inputs, seed 0), then flown by ipp-compare
# against ig and random on the same validation missions. Run by hand:
#   bash benchmarks/sb3_algorithms.sh [TIMESTEPS] [OUT]
set -euo pipefail
steps="${1:-60000}"
out="${2:-runs/sb3-table}"
planners="ig,random"
for algo in MaskablePPO PPO A2C DQN QRDQN RecurrentPPO; do
    dir="$out/$(echo "$algo" | tr '[:upper:]' '[:lower:]')"
    start=$(date +%s)
    ipp-train sb3 --algo "$algo" --timesteps "$steps" --out "$dir" --no-progress \
        $([ -f "$dir/checkpoint.pt" ] && echo --resume) > "$dir.log" 2>&1
    echo "$algo: trained $steps agent-steps in $(( $(date +%s) - start )) s"
    planners="$planners,$algo:sb3=$dir/policy.pt"
done
ipp-compare --namespace validation --seed 3 --trials 30 --resolution 0.5 \
    --planners "$planners" --out "$out/compare" --no-progress
