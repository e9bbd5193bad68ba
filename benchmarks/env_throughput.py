"""Simulator throughput: joint steps per second with random valid actions (run by hand).

    python benchmarks/env_throughput.py                 # paper configuration, r_M = 0.1 m
    python benchmarks/env_throughput.py --resolution 0.5
    python benchmarks/env_throughput.py --clock cpu     # CPU time: on a machine shared with
                                                        # other jobs (pin it: taskset -c 1)

Prints three figures per configuration, all on one core:
  core         step_mission only (move, measure, exchange, fuse, reward, metrics);
  +obs         plus the actor observations of every agent and state() after every step;
  +obs+reset   the same including mission resets (terrain generation, start measurements).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from ipp_toolkit.config.schema import EnvConfig  # noqa: E402
from ipp_toolkit.sim.features import actor_observations, global_state  # noqa: E402
from ipp_toolkit.sim.mission import MissionGeometry, reset_mission, step_mission  # noqa: E402


def random_valid(masks: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N,) uniform valid action per agent from (N, 6) masks."""
    scores = rng.random(masks.shape) * masks
    return scores.argmax(axis=1)


CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}


def measure(config: EnvConfig, missions: int, observe: bool, count_reset: bool,
            clock: str = "wall") -> float:
    """Joint steps per second over ``missions`` missions, timed by ``CLOCKS[clock]``."""
    now = CLOCKS[clock]
    geometry = MissionGeometry(config)
    rng = np.random.default_rng(0)
    steps, elapsed = 0, 0.0
    for mission in range(missions):
        start = now()
        state = reset_mission(config, seed=0, mission=mission, geometry=geometry)
        if observe:
            actor_observations(state, config.features)
            global_state(state, config.features)
        if count_reset:
            elapsed += now() - start
        start = now()
        while not state.done:
            step_mission(state, random_valid(state.masks(), rng))
            if observe:
                actor_observations(state, config.features)
                global_state(state, config.features)
            steps += 1
        elapsed += now() - start
    return steps / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=4)
    parser.add_argument("--comm", type=float, default=25.0, help="communication range (m)")
    parser.add_argument("--resolution", type=float, nargs="+", default=[0.1, 0.5])
    parser.add_argument("--missions", type=int, default=40)
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall",
                        help="wall time, or this process's CPU time (robust to other jobs on "
                             "the same core, not to their use of the shared caches)")
    args = parser.parse_args()
    print(f"{args.agents} agents, D = {args.comm} m, {args.missions} missions of 15 steps, "
          f"random valid actions, one core, {args.clock} time")
    for resolution in args.resolution:
        config = EnvConfig().replace(world={"resolution": resolution},
                                     team={"n_agents": args.agents, "comm_range": args.comm})
        measure(config, 2, True, True)  # warm-up
        core = measure(config, args.missions, False, False, args.clock)
        observed = measure(config, args.missions, True, False, args.clock)
        with_reset = measure(config, args.missions, True, True, args.clock)
        print(f"r_M = {resolution:g} m ({config.world.map_cells}^2 cells): "
              f"core {core:7.0f} | +obs {observed:7.0f} | +obs+reset {with_reset:7.0f} "
              "joint steps/s")


if __name__ == "__main__":
    main()
