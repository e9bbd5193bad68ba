"""Planner throughput and quality: greedy information gain against the random and lawnmower
baselines at the paper configuration (run by hand).

    python benchmarks/ig_throughput.py                   # 4 agents, D = 25 m, r_M = 0.1 m
    python benchmarks/ig_throughput.py --missions 5 --resolution 0.5

Per planner, over the same test missions (``reset_mission(config, seed=0, mission=k,
namespace="test")``), all on one core:
  act          joint steps/s of ``planner.act(views)`` alone;
  act+step     joint steps/s of the whole decision loop: ``planner_views`` + ``act`` +
               ``step_mission`` (move, measure, exchange, fuse, reward, metrics);
  entropy, F1  mean final entropy over interesting cells and F1 of the global map.
Mission resets are not timed.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from ipp_toolkit.config.schema import EnvConfig  # noqa: E402
from ipp_toolkit.planning import Planner, make_planner, planner_views  # noqa: E402
from ipp_toolkit.sim.mission import MissionGeometry, reset_mission, step_mission  # noqa: E402


def run(planner: Planner, config: EnvConfig, geometry: MissionGeometry,
        missions: int) -> dict[str, float]:
    """Fly ``missions`` test missions; returns throughputs and mean final metrics."""
    steps, act_time, loop_time = 0, 0.0, 0.0
    entropy, f1 = [], []
    for mission in range(missions):
        state = reset_mission(config, seed=0, mission=mission, namespace="test",
                              geometry=geometry)
        planner.reset(config, seed=mission)
        while not state.done:
            start = time.perf_counter()
            views = planner_views(state, planner)
            before_act = time.perf_counter()
            actions = planner.act(views)
            after_act = time.perf_counter()
            step_mission(state, actions)
            loop_time += time.perf_counter() - start
            act_time += after_act - before_act
            steps += 1
        metrics = state.metrics()
        entropy.append(metrics.entropy)
        f1.append(metrics.f1)
    return {"act": steps / act_time, "loop": steps / loop_time,
            "entropy": float(np.mean(entropy)), "entropy_sd": float(np.std(entropy)),
            "f1": float(np.mean(f1))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=4)
    parser.add_argument("--comm", type=float, default=25.0, help="communication range (m)")
    parser.add_argument("--resolution", type=float, default=0.1, help="map cell side (m)")
    parser.add_argument("--missions", type=int, default=20)
    parser.add_argument("--planners", nargs="+", default=["ig", "random", "coverage"])
    args = parser.parse_args()
    config = EnvConfig().replace(world={"resolution": args.resolution},
                                 team={"n_agents": args.agents, "comm_range": args.comm})
    geometry = MissionGeometry(config)
    print(f"{args.agents} agents, D = {args.comm:g} m, r_M = {args.resolution:g} m "
          f"({config.world.map_cells}^2 cells), {args.missions} test missions of "
          f"{config.team.budget} steps, one core")
    print(f"{'':10s} {'joint steps/s':>21s}   {'final global map':>23s}")
    print(f"{'planner':10s} {'act':>10s} {'act+step':>10s}   {'entropy (sd)':>15s} {'F1':>7s}")
    for name in args.planners:
        planner = make_planner(name)
        run(planner, config, geometry, 1)  # warm-up (imports, caches)
        result = run(planner, config, geometry, args.missions)
        print(f"{name:10s} {result['act']:10.0f} {result['loop']:10.0f}   "
              f"{result['entropy']:7.3f} ({result['entropy_sd']:.3f}) {result['f1']:7.3f}")


if __name__ == "__main__":
    main()
