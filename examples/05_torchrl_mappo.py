"""MAPPO on the UAV team with TorchRL (needs the optional extra `torchrl`).

Multi-agent PPO in TorchRL's own building blocks: a shared actor (``MultiAgentMLP``) that
samples from a ``MaskedCategorical`` over the six moves with each UAV's action mask, a
centralised critic on every UAV's planes (``centralized=True``), GAE and ``ClipPPOLoss``.
The env is :func:`ipp_toolkit.torchrl_env.make_torchrl_env`: batched copies of the
simulator behind TorchRL's ``ActionMask`` (the masks survive the batching and the
``FlattenObservation`` transform) in which a failed UAV keeps its slot, so a failure does not
end the episode; this example flies one failure per mission to show it.

Every iteration collects one mission per copy (all UAVs are done together after ``budget``
steps), trains a few epochs on it and prints the final entropy and F1 of the global map.
Each UAV gets the team reward (a failed one 0), so a sum of rewards over the UAVs would count
the team's return once per UAV. At the end the shared actor is saved to ``OUT/policy.pt``
(:func:`baselines.torchrl.policy.save_torchrl_policy`: plain weights and the mission config),
which the ``torchrl`` planner flies beside the others.

    pip install -c constraints.txt -e ".[torchrl]"
    python examples/05_torchrl_mappo.py --out runs/mappo   # 4 UAVs, 8 copies, 60 iterations
    ipp-compare --agents 4 --resolution 0.5 --planners ig,torchrl=runs/mappo/policy.pt
    python examples/05_torchrl_mappo.py --quick --out /tmp/mappo   # what the tests run
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.envs import FlattenObservation
from torchrl.modules import MaskedCategorical, MultiAgentMLP, ProbabilisticActor
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from baselines.torchrl.policy import save_torchrl_policy
from ipp_toolkit import EnvConfig
from ipp_toolkit.torchrl_env import GROUP, make_torchrl_env

OBS = (GROUP, "observation", "observation")


def build_env(args: argparse.Namespace):
    config = EnvConfig().replace(world={"resolution": args.resolution},
                                 team={"n_agents": args.agents, "random_failures": 1})
    # FlattenObservation: (C, G, G) planes -> C*G*G inputs of the MLPs; ActionMask sits below.
    flatten = FlattenObservation(-3, -1, in_keys=[OBS])
    return make_torchrl_env(config, num_envs=args.envs, seed=args.seed, transforms=[flatten],
                            invalid_action="raise"), config  # raise: prove no masked action


def build_modules(env, n_agents: int, hidden: int):
    n_inputs = env.observation_spec[OBS].shape[-1]
    n_actions = env.full_action_spec[GROUP, "action"].space.n
    policy_net = TensorDictModule(
        MultiAgentMLP(n_inputs, n_actions, n_agents, centralized=False, share_params=True,
                      depth=2, num_cells=hidden, activation_class=nn.Tanh),
        in_keys=[OBS], out_keys=[(GROUP, "logits")])
    actor = ProbabilisticActor(
        policy_net, in_keys={"logits": (GROUP, "logits"), "mask": (GROUP, "action_mask")},
        out_keys=[(GROUP, "action")], distribution_class=MaskedCategorical,
        return_log_prob=True, log_prob_key=(GROUP, "sample_log_prob"))
    critic = TensorDictModule(
        MultiAgentMLP(n_inputs, 1, n_agents, centralized=True, share_params=True, depth=2,
                      num_cells=hidden, activation_class=nn.Tanh),
        in_keys=[OBS], out_keys=[(GROUP, "state_value")])
    return actor, critic


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a tiny run for the test suite")
    parser.add_argument("--agents", type=int, default=4)
    parser.add_argument("--envs", type=int, default=8, help="simulator copies per iteration")
    parser.add_argument("--iterations", type=int, default=60)
    parser.add_argument("--resolution", type=float, default=0.5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("examples-output/05_torchrl_mappo"),
                        help="folder of the saved actor, OUT/policy.pt (the torchrl planner "
                             "flies it; default: examples-output/05_torchrl_mappo)")
    args = parser.parse_args(argv)
    if args.quick:
        args.agents, args.envs, args.iterations, args.resolution = 2, 2, 2, 1.0
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)  # small batches: extra threads only slow a shared CPU down

    env, config = build_env(args)
    actor, critic = build_modules(env, args.agents, hidden=32 if args.quick else 128)
    # Advantages are normalised over the batch, not across the agent dimension (-2).
    loss = ClipPPOLoss(actor, critic, clip_epsilon=0.2, entropy_coeff=0.01,
                       normalize_advantage=True, normalize_advantage_exclude_dims=(-2,))
    # Per-agent keys: every UAV has its own reward, done and log-probability entries.
    loss.set_keys(reward=(GROUP, "reward"), action=(GROUP, "action"),
                  sample_log_prob=(GROUP, "sample_log_prob"), value=(GROUP, "state_value"),
                  done=(GROUP, "done"), terminated=(GROUP, "terminated"))
    loss.make_value_estimator(ValueEstimators.GAE, gamma=0.99, lmbda=0.95)
    optimiser = torch.optim.Adam(loss.parameters(), lr=3e-4)
    budget = config.team.budget
    try:
        for iteration in range(args.iterations):
            with torch.no_grad():
                data = env.rollout(budget, policy=actor)  # (envs, budget): one mission each
                loss.value_estimator(data, params=loss.critic_network_params,
                                     target_params=loss.target_critic_network_params)
            flat = data.reshape(-1)
            for _ in range(4):  # epochs over the missions just flown
                for batch in flat.split(max(len(flat) // 2, 1)):
                    terms = loss(batch)
                    total = terms["loss_objective"] + terms["loss_critic"] + \
                        terms["loss_entropy"]
                    optimiser.zero_grad()
                    total.backward()
                    nn.utils.clip_grad_norm_(loss.parameters(), 1.0)
                    optimiser.step()
            final = data["next", GROUP, "info"][:, -1, 0]  # the global map: any UAV's info
            print(f"iteration {iteration + 1}: final entropy {final['entropy'].mean():.3f}, "
                  f"F1 {final['f1'].mean():.3f}")
    finally:
        env.close()
    args.out.mkdir(parents=True, exist_ok=True)
    path = save_torchrl_policy(args.out / "policy.pt", actor.module[0].module, config,
                               iterations=args.iterations, seed=args.seed)
    print(f"saved the actor to {path}: ipp-compare --agents {args.agents} --resolution "
          f"{args.resolution:g} --planners ig,torchrl={path}")


if __name__ == "__main__":
    main()
