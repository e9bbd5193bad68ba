"""Time of the learned field prior per planning step, and of ig_learned against ig_spatial.

Prints, for each resolution, the prior's prediction for the whole team (input planes, forward
pass, resampling onto ig_spatial's 0.5 m blocks) in ms per step, and the mean ``act`` time of
``ig_spatial`` and ``ig_learned`` over whole missions (the ``plan_ms`` of ipp-compare):

    python benchmarks/prior_inference.py [--prior PATH] [--agents 4] [--missions 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from baselines.field_prior.planner import DEFAULT_PRIOR, LearnedPriorPlanner
from baselines.heuristics.spatial_gain import SpatialGainPlanner
from ipp_toolkit import EnvConfig
from ipp_toolkit.belief.interest import interest_smoother
from ipp_toolkit.planning import planner_views
from ipp_toolkit.sim.driver import fly_missions, start_missions


def act_ms(planner, config: EnvConfig, missions: int) -> float:
    """Mean wall time of ``planner.act`` per step over ``missions`` validation missions."""
    times: list[float] = []
    for mission in range(missions):
        state, = start_missions(config, 0, mission, 1, "validation")
        planner.reset(config, seed=0)

        def policy(states, planner=planner):
            views = planner_views(states[0], planner)
            start = time.perf_counter()
            joint = planner.act(views)
            times.append(time.perf_counter() - start)
            return [joint]

        fly_missions([state], policy)
    return 1e3 * float(np.mean(times[len(times) // 10:]))  # the first steps warm caches


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--prior", default=str(DEFAULT_PRIOR))
    parser.add_argument("--agents", type=int, default=4)
    parser.add_argument("--missions", type=int, default=5)
    parser.add_argument("--repeat", type=int, default=50)
    args = parser.parse_args()
    torch.set_num_threads(1)
    learned = LearnedPriorPlanner(args.prior)
    for resolution in (0.5, 0.1):
        config = EnvConfig().replace(world={"resolution": resolution},
                                     team={"n_agents": args.agents})
        cells = config.world.map_cells
        fine = interest_smoother(cells, resolution, 5.0).block
        prob = np.random.default_rng(0).random((args.agents, cells, cells), dtype=np.float32)
        learned.prior.fine_values(prob, resolution, fine)
        start = time.perf_counter()
        for _ in range(args.repeat):
            learned.prior.fine_values(prob, resolution, fine)
        prior_ms = 1e3 * (time.perf_counter() - start) / args.repeat
        spatial = act_ms(SpatialGainPlanner(), config, args.missions)
        learned_ms = act_ms(learned, config, args.missions)
        print(f"r_M {resolution:g} m, {args.agents} UAVs: prior {prior_ms:.2f} ms/step; act: "
              f"ig_spatial {spatial:.2f} ms, ig_learned {learned_ms:.2f} ms")


if __name__ == "__main__":
    main()
