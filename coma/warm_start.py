"""Warm start: imitate a planner, then let COMA improve on it (not in the paper).

COMA from scratch learns slowly on a CPU budget: its critic must discover, from noisy team
returns of a near-random policy, how much each UAV's alternatives are worth (see the README
for what we measured). A warm start gives both networks a sensible beginning:

1. fly ``missions`` training missions with a demonstrator planner (default ``ig``);
2. fit the actor to the demonstrator's choices (cross-entropy over the valid actions);
3. fit the critic (and Central-QV's V) to the demonstrator's discounted returns, i.e. to
   Q of the demonstrator's policy.

COMA then starts from a policy as good as the demonstrator and a critic that already ranks
actions under it; its counterfactual advantage is a policy-improvement step from there. The
demonstration missions are drawn from the ``train`` namespace at indices far beyond the ones
COMA trains on (from :data:`DEMO_MISSION_OFFSET`), so no terrain is reused.

The settings are a :class:`~coma.config.WarmStartConfig` (``COMAConfig.warm_start``; defined
with the other hyper-parameters, so inference code can read a config without this module).
"""

from __future__ import annotations

import math
from typing import Any

import torch
from torch import nn

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import make_planner
from ipp_toolkit.runs.progress import progress_bar
from ipp_toolkit.sim.mission import MissionGeometry

from .advantages import td_lambda_targets
from .config import WarmStartConfig
from .networks import learning_forward
from .persistence import COMANetworks
from .rollout import collect_rollout

__all__ = ["DEMO_MISSION_OFFSET", "WarmStartConfig", "warm_start"]

DEMO_MISSION_OFFSET = 1_000_000_000


def _fit(module: nn.Module, loss_of: Any, samples: int, config: WarmStartConfig,
         generator: torch.Generator, max_grad_norm: float) -> float:
    """Minimise ``loss_of(batch_indices)`` over shuffled mini-batches; returns the last mean."""
    optimiser = torch.optim.Adam(module.parameters(), lr=config.lr)
    module.train()
    losses: list[float] = []
    for _ in range(config.epochs):
        losses = []
        order = torch.randperm(samples, generator=generator)
        for start in range(0, samples, config.minibatch_size):
            loss = loss_of(order[start:start + config.minibatch_size])
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            nn.utils.clip_grad_norm_(module.parameters(), max_grad_norm)
            optimiser.step()
            losses.append(loss.item())
    return sum(losses) / max(len(losses), 1)


def warm_start(networks: COMANetworks, env_config: EnvConfig, config: WarmStartConfig,
               seed: int, generator: torch.Generator, progress: bool = True
               ) -> dict[str, float]:
    """Fit the networks in place to a demonstrator's missions.

    Returns:
        ``imitation_accuracy`` (share of held-out decisions where the actor's greedy choice
        equals the demonstrator's), ``actor_loss``, ``critic_loss`` (last epoch means) and
        ``demo_return`` (the demonstrator's mean team return).
    """
    geometry = MissionGeometry(env_config)
    cfg = networks.coma_config
    batches = []
    bar = progress_bar(config.missions, f"warm start: flying {config.planner}", "missions",
                       disable=not progress)
    done = 0
    while done < config.missions:
        count = min(config.missions_per_batch, config.missions - done)
        demonstrators = [make_planner(config.planner) for _ in range(count)]
        batches.append(collect_rollout(networks, env_config, geometry, seed,
                                       DEMO_MISSION_OFFSET + done, count, 0.0,
                                       demonstrators=demonstrators))
        done += count
        bar.update(count)
    bar.close()

    def cat(name: str) -> torch.Tensor:
        return torch.cat([getattr(b, name).flatten(0, 2) for b in batches])

    returns = []
    for b in batches:
        e, n, t = b.actions.shape
        terminal = torch.zeros(e, n, t, dtype=torch.bool)
        terminal[..., -1] = True
        # lambda = 1: the demonstrator's discounted return, an unbiased sample of its Q.
        returns.append(td_lambda_targets(b.rewards.unsqueeze(1).expand(e, n, t),
                                         torch.zeros(e, n, t), terminal, cfg.gamma,
                                         1.0).flatten())
    targets = torch.cat(returns)
    actor_obs, critic_obs, masks, actions = (cat("actor_obs"), cat("critic_obs"),
                                             cat("masks"), cat("actions"))
    per_mission = len(actions) // config.missions
    held = int(round(config.holdout * config.missions)) * per_mission
    fit = len(actions) - held

    def actor_loss(batch: torch.Tensor) -> torch.Tensor:
        logits = learning_forward(networks.actor, actor_obs[batch], cfg.precision)
        logits = logits.masked_fill(~masks[batch], -1e9)
        return nn.functional.cross_entropy(logits, actions[batch])

    def critic_loss(batch: torch.Tensor) -> torch.Tensor:
        q = learning_forward(networks.critic, critic_obs[batch], cfg.precision)
        q = q.gather(-1, actions[batch, None]).squeeze(-1)
        return torch.mean((q - targets[batch]) ** 2)

    result = {"demo_return": float(sum(float(b.returns.sum()) for b in batches)
                                   / config.missions)}
    result["actor_loss"] = _fit(networks.actor, actor_loss, fit, config, generator,
                                cfg.max_grad_norm)
    result["critic_loss"] = _fit(networks.critic, critic_loss, fit, config, generator,
                                 cfg.max_grad_norm)
    if networks.value is not None:
        value_obs = cat("value_obs")

        def value_loss(batch: torch.Tensor) -> torch.Tensor:
            v = learning_forward(networks.value, value_obs[batch], cfg.precision)
            return torch.mean((v.squeeze(-1) - targets[batch]) ** 2)

        result["value_loss"] = _fit(networks.value, value_loss, fit, config, generator,
                                    cfg.max_grad_norm)
    with torch.no_grad():
        if held:
            logits = networks.actor(actor_obs[fit:]).masked_fill(~masks[fit:], -1e9)
            result["imitation_accuracy"] = float(
                (logits.argmax(-1) == actions[fit:]).float().mean())
        else:
            result["imitation_accuracy"] = math.nan
    return result
