"""CPU time per test mission of each planner, in one process (what an evaluation worker pays).

    python benchmarks/mission_times.py                        # ipp-compare's default planners
    python benchmarks/mission_times.py --planners coma,ppo --missions 25

Builds each planner, flies its mission 0 untimed (the compiled kernels load, the planner's
lazy set-up), then times missions 1..N of ``ipp-compare``'s defaults (4 UAVs, D = 25 m,
r_M = 0.1 m, test namespace, seed 0) with one BLAS and one torch thread and freed memory
kept for reuse, as an evaluation worker runs them.
Prints milliseconds of CPU and wall time per mission.
"""

from __future__ import annotations

import argparse
import time

from ipp_toolkit.config.settings import build_env_config
from ipp_toolkit.planning import make_planner
from ipp_toolkit.runs.evaluation import run_mission
from ipp_toolkit.runs.process_pool import (
    limit_blas_threads,
    limit_torch_threads,
    retain_freed_memory,
)
from ipp_toolkit.sim.mission import MissionGeometry
from reports.compare import DEFAULT_PLANNERS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", default=",".join(DEFAULT_PLANNERS),
                        help="comma-separated registered planners (default: ipp-compare's)")
    parser.add_argument("--missions", type=int, default=20)
    args = parser.parse_args()
    limit_blas_threads()
    retain_freed_memory()  # as ipp_toolkit.runs.process_pool's workers do
    config = build_env_config(None)
    geometry = MissionGeometry(config)
    print(f"{args.missions} test missions per planner, one process; ms per mission")
    for name in args.planners.split(","):
        planner = make_planner(name)
        limit_torch_threads()
        run_mission(config, planner, 0, 0, geometry=geometry)
        wall, cpu = time.perf_counter(), time.process_time()
        for mission in range(1, args.missions + 1):
            run_mission(config, planner, 0, mission, geometry=geometry)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        print(f"{name:10s} CPU {cpu / args.missions * 1000:7.1f}   "
              f"wall {wall / args.missions * 1000:7.1f}", flush=True)


if __name__ == "__main__":
    main()
