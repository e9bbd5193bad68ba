"""Gain planes (``features.gain``): milliseconds per step, incremental cache vs recomputation.

    python benchmarks/gain_planes.py                  # 4 UAVs, D = 25 m, r_M = 0.1 m
    python benchmarks/gain_planes.py --agents 8 --comm inf
    python benchmarks/gain_planes.py --smoothing 5      # the planes of coma / ppo

Flies random valid missions and times, on one core, the ``gain`` planes of every agent after
each step (start measurement included): once through the mission's incremental
:class:`~ipp_toolkit.belief.gain.FootprintGainCache` (what the ``coma_prior`` planner and training
pay) and once the footprint sums recomputed from the whole maps (the cost before the cache).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from ipp_toolkit.belief.gain import recomputed_footprint_sums  # noqa: E402
from ipp_toolkit.belief.interest import interest_smoother  # noqa: E402
from ipp_toolkit.config.schema import EnvConfig  # noqa: E402
from ipp_toolkit.sim.features import gain_planes  # noqa: E402
from ipp_toolkit.sim.mission import MissionGeometry, reset_mission, step_mission  # noqa: E402


def measure(config: EnvConfig, missions: int, incremental: bool, smoothing: float = 0.0) -> float:
    """Mean milliseconds per step of the gain planes of all agents (``smoothing`` > 0: the
    ``ig_spatial`` objective, weighted by the smoothed interest, as the shipped ``coma`` and
    ``ppo`` policies see it)."""
    geometry = MissionGeometry(config)
    rng = np.random.default_rng(0)
    reward = config.reward
    calls, elapsed = 0, 0.0
    for mission in range(missions):
        state = reset_mission(config, seed=0, mission=mission, namespace="validation",
                              geometry=geometry)
        while True:
            start = time.perf_counter()
            if incremental:
                gain_planes(state, smoothing)
            elif smoothing > 0:
                world = config.world
                smoother = interest_smoother(world.map_cells, world.resolution, smoothing)
                recomputed_footprint_sums(state.maps, state.n_agents, geometry.camera,
                                          (1.0, 0.0), objective="interesting",
                                          cell_weight=smoother(state.maps.prob[:state.n_agents]))
            else:
                recomputed_footprint_sums(state.maps, state.n_agents, geometry.camera,
                                          (reward.weight_interesting,
                                           reward.weight_uninteresting))
            elapsed += time.perf_counter() - start
            calls += 1
            if state.done:
                break
            scores = rng.random(state.masks().shape) * state.masks()
            step_mission(state, scores.argmax(axis=1))
    return 1000 * elapsed / calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=4)
    parser.add_argument("--comm", type=float, default=25.0, help="communication range (m)")
    parser.add_argument("--resolution", type=float, default=0.1)
    parser.add_argument("--missions", type=int, default=5)
    parser.add_argument("--smoothing", type=float, default=0.0,
                        help="gain smoothing in metres (0: the ig objective)")
    args = parser.parse_args()
    config = EnvConfig().replace(world={"resolution": args.resolution},
                                 team={"n_agents": args.agents, "comm_range": args.comm},
                                 features={"gain": True})
    print(f"{args.agents} UAVs, D = {args.comm:g} m, r_M = {args.resolution:g} m, "
          f"{args.missions} missions, smoothing {args.smoothing:g} m, one core")
    for name, incremental in (("incremental cache", True), ("recomputed", False)):
        print(f"  {name + ':':18s} "
              f"{measure(config, args.missions, incremental, args.smoothing):8.1f} ms/step")


if __name__ == "__main__":
    main()
