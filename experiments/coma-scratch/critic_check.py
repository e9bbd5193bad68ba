"""How well a COMA run's critic knows the returns, and how much it separates actions.

Flies validation missions with the run's policy (eps as given), then compares the critic's
Q(s_t, u_t) with the Monte Carlo return to go G_t of the same missions, and its spread over
each agent's valid actions with its error:

    python experiments/coma-scratch/critic_check.py RUN/last.pt --missions 20
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from coma.advantages import counterfactual_baseline, td_lambda_targets
from coma.networks import bounded_softmax
from coma.persistence import load_policy
from coma.rollout import collect_rollout
from ipp_toolkit.sim.mission import MissionGeometry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy")
    parser.add_argument("--missions", type=int, default=20)
    parser.add_argument("--eps", type=float, default=0.02)
    args = parser.parse_args()
    torch.set_num_threads(1)
    networks, _ = load_policy(args.policy)
    cfg, env = networks.coma_config, networks.env_config
    rollout = collect_rollout(networks, env, MissionGeometry(env), 0, 0, args.missions,
                              args.eps, namespace="validation")
    e, n, t = rollout.actions.shape
    rewards = rollout.rewards.double()
    returns = torch.zeros_like(rewards)
    following = torch.zeros(e, dtype=rewards.dtype)
    for step in range(t - 1, -1, -1):
        following = rewards[:, step] + cfg.gamma * following
        returns[:, step] = following
    returns = returns.unsqueeze(1).expand(e, n, t)
    with torch.no_grad():
        q = networks.critic(rollout.critic_obs.flatten(0, 2)).double().view(e, n, t, -1)
        probs = bounded_softmax(networks.actor(rollout.actor_obs.flatten(0, 2)),
                                rollout.masks.flatten(0, 2), args.eps).double()
    taken = q.gather(-1, rollout.actions.unsqueeze(-1)).squeeze(-1)
    next_values = torch.roll(taken, -1, dims=-1)
    terminal = torch.zeros(e, n, t, dtype=torch.bool)
    terminal[..., -1] = True
    targets = td_lambda_targets(rewards.unsqueeze(1).expand(e, n, t), next_values, terminal,
                                cfg.gamma, cfg.td_lambda)
    masks = rollout.masks.flatten(0, 2)
    flat_q = q.flatten(0, 2)
    baseline = counterfactual_baseline(flat_q, probs, masks)
    valid_q = flat_q.masked_fill(~masks, float("nan")).numpy()
    spread = np.nanstd(valid_q, axis=-1)
    error = (taken - returns).flatten().numpy()
    g, qt = returns.flatten().numpy(), taken.flatten().numpy()
    print(f"{args.policy}: {e} missions x {n} agents x {t} steps, eps {args.eps}")
    print(f"  return to go G: mean {g.mean():+.3f}, std {g.std():.3f}")
    rmse = np.sqrt((error ** 2).mean())
    print(f"  Q(s,u) vs G: correlation {np.corrcoef(qt, g)[0, 1]:.3f}, RMSE {rmse:.3f}")
    print(f"  TD(lambda) target vs G: RMSE {np.sqrt(((targets - returns) ** 2).mean()):.3f}")
    print(f"  Q's spread over an agent's valid actions (std): mean {spread.mean():.3f}")
    paper = (taken.flatten() - baseline).numpy()
    flown = (targets.flatten() - baseline).numpy()
    print(f"  advantage std: paper Q(s,u) - b {paper.std():.3f}; flown G - b {flown.std():.3f}")


if __name__ == "__main__":
    main()
