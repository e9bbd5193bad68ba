"""RLlib's own action-masking RLModule on the toolkit's multi-agent env, as RLlib's docs use a
custom env: name it in ``PPOConfig().environment(...)``, train, save, restore with
``Algorithm.from_checkpoint`` and compute actions.

Importing ``baselines.rllib.module`` registers the env as ``ipp_toolkit_multi_agent``. Its
``env_config`` asks for ``observation: rllib``, the layout RLlib's
``ActionMaskingTorchRLModule`` reads (``{"observations": the planes flattened,
"action_mask": floats}``), and ``invalid_action: raise``: a masked action stops the run, so a
finished run shows that no masked action was sampled. Every UAV maps to one shared module.

    python examples/06_rllib_action_masking.py --iterations 5

Needs the optional RLlib extra (docs/rllib.md): pip install -c constraints-rllib.txt -e
".[rllib]". ``--quick`` trains 2 small iterations (the test suite runs it).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
import torch
from ray.rllib.algorithms.algorithm import Algorithm
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.examples.rl_modules.classes.action_masking_rlm import (
    ActionMaskingTorchRLModule,
)

from baselines.rllib.module import ENV_NAME, IPPMultiAgentEnv

SHARED = "shared"


def build_config(env_config: dict[str, Any], train_batch: int, seed: int) -> PPOConfig:
    """PPO with RLlib's action-masking module shared by every UAV."""
    return (
        PPOConfig()
        # RLlib's env pre-check steps random actions, masked ones included, which
        # invalid_action="raise" refuses.
        .environment(ENV_NAME, env_config=env_config, disable_env_checking=True)
        .env_runners(num_env_runners=0)
        .learners(num_learners=0)
        .multi_agent(policies={SHARED},
                     policy_mapping_fn=lambda agent_id, episode, **kwargs: SHARED)
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={
            SHARED: RLModuleSpec(module_class=ActionMaskingTorchRLModule,
                                 model_config={"fcnet_hiddens": [64, 64]})}))
        .training(train_batch_size_per_learner=train_batch,
                  minibatch_size=min(128, train_batch), num_epochs=2)
        .debugging(seed=seed, log_level="ERROR")
    )


def fly(module: Any, env_config: dict[str, Any]) -> tuple[float, dict[str, Any]]:
    """One mission with the module's greedy actions: the team return and the last info."""
    env = IPPMultiAgentEnv(env_config)
    observations, _ = env.reset()
    team_return, info = 0.0, {}
    while env.agents:
        agents = list(observations)
        batch = {key: torch.from_numpy(np.stack([observations[a][key] for a in agents]))
                 for key in ("observations", "action_mask")}
        logits = module.forward_inference({"obs": batch})["action_dist_inputs"]
        actions = dict(zip(agents, logits.argmax(dim=-1).tolist(), strict=True))
        observations, rewards, _, _, infos = env.step(actions)
        team_return += max(rewards.values())
        info = next(iter(infos.values()))
    env.close()
    return team_return, info


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=5)
    parser.add_argument("--train-batch", type=int, default=512,
                        help="team steps sampled per iteration")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="examples-output/06_rllib_action_masking",
                        help="folder of the checkpoint (default: %(default)s)")
    parser.add_argument("--quick", action="store_true", help="2 iterations of 64 team steps")
    args = parser.parse_args(argv)
    iterations, train_batch = (2, 64) if args.quick else (args.iterations, args.train_batch)
    # RLlib reads a relative path as a URI without a scheme and refuses it.
    out = Path(args.out).expanduser().resolve()
    env_config = {"env": {"team": {"n_agents": 2}, "world": {"resolution": 1.0}},
                  "observation": "rllib", "invalid_action": "raise", "base_seed": args.seed}

    algo = build_config(env_config, train_batch, args.seed).build_algo()
    for iteration in range(1, iterations + 1):
        result = algo.train()
        mean = result["env_runners"].get("episode_return_mean", float("nan"))
        print(f"iteration {iteration}: episode_return_mean {mean:.3f}")
    checkpoint = algo.save_to_path(str(out / "checkpoint"))
    algo.stop()
    print(f"saved {checkpoint}")

    restored = Algorithm.from_checkpoint(checkpoint)
    team_return, info = fly(restored.get_module(SHARED), {**env_config, "base_seed": 1000})
    restored.stop()
    print(f"restored and flew one mission: team return {team_return:.3f}, "
          f"final entropy {info['entropy']:.3f}, F1 {info['f1']:.3f}")


if __name__ == "__main__":
    main()
