"""The paper's credit-assignment study in small: COMA against its three variants.

Each variant differs only in what its critic sees and in the baseline of the advantage
(``coma.config.VARIANTS``):

* ``coma``: the critic sees the state and the teammates' actions; the baseline averages the
  agent's own alternatives (counterfactual).
* ``central_qv``: the same critic, but the baseline is a learned V(s): it does not know which
  part of the team's success is the agent's own.
* ``actor_independent``: the critic does not see the teammates' actions.
* ``decentralised``: the critic sees only the agent's own observation.

Every variant is trained with the same seed, budget and network on a small mission (two UAVs,
a coarse 1 m map, 8 steps), then flown greedily on held-out validation missions. With a
minute of training the differences are small and noisy: the point is to show how to run the
study, not to settle it (the full study is ``ipp-train coma --variant ...`` per variant).

    python examples/03_credit_assignment_study.py            # ~1 minute on a laptop CPU
    python examples/03_credit_assignment_study.py --quick    # what the test suite runs
"""

from __future__ import annotations

import argparse
import tempfile
import time

import torch

from coma.config import VARIANTS, COMAConfig
from coma.learner import train
from coma.persistence import load_policy
from coma.validation import evaluate_greedy
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.sim.mission import MissionGeometry


def small_mission() -> EnvConfig:
    """Two UAVs, 1 m map cells, 8 steps, 25 m communication range."""
    return EnvConfig().replace(world={"resolution": 1.0},
                               team={"n_agents": 2, "budget": 8, "comm_range": 25.0})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a few updates only")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    torch.set_num_threads(1)
    env = small_mission()
    missions, eval_missions = (20, 5) if args.quick else (600, 40)
    geometry = MissionGeometry(env)
    budget = env.team.budget
    print(f"{'variant':<18} {'train s':>8} {'entropy':>8} {'F1':>6}   "
          f"(greedy, {eval_missions} validation missions, {missions} training missions)")
    for variant in VARIANTS:
        config = COMAConfig(variant=variant, width=16, hidden=32, missions=missions,
                            missions_per_update=20, minibatch_size=80, epochs=2,
                            eps_anneal_missions=missions // 2, eval_every=10_000,
                            eval_missions=1, target_update_transitions=1_000,
                            eps_start=0.5, warm_start="", seed=args.seed)
        start = time.perf_counter()
        with tempfile.TemporaryDirectory() as folder:
            result = train(config, env, folder, progress=False, tensorboard=False)
            networks, _ = load_policy(result.last_checkpoint)
        seconds = time.perf_counter() - start
        scores = evaluate_greedy(networks.actor, env, geometry, args.seed, eval_missions)
        print(f"{variant:<18} {seconds:8.1f} {scores[f'entropy_{budget}']:8.3f} "
              f"{scores[f'f1_{budget}']:6.3f}")


if __name__ == "__main__":
    main()
