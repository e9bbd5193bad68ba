"""One COMA update, top to bottom: TD(lambda) targets from the target critic, then per
mini-batch the critic(s) on those targets and the actor on the advantage.

This module owns :func:`update` (re-exported by :mod:`coma.learner`, where the run around it
lives) and :class:`TrainingDiverged`, what a non-finite loss raises. The advantage itself is
:mod:`coma.advantages`'; the actor loss is the paper's ``-log pi(u) A``, or with
``clip_ratio > 0`` PPO's clipped surrogate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from ipp_toolkit.sim.team import N_ACTIONS

from .advantages import (
    counterfactual_baseline,
    lagged_rewards,
    reference_td_targets,
    td_lambda_targets,
)
from .networks import (
    GainPriorActor,
    bounded_softmax,
    in_input_layout,
    learning_forward,
    mixed_precision,
)
from .persistence import COMANetworks
from .rollout import Rollout

__all__ = ["TrainingDiverged", "update"]


class TrainingDiverged(RuntimeError):
    """A loss became NaN or infinite; the last good checkpoint is kept."""


# Every diagnostic an update logs (mean over its mini-batches; an empty one is left out).
_LOG_KEYS = ("critic_loss", "value_loss", "actor_loss", "advantage_std", "policy_entropy",
             "critic_grad_norm", "actor_grad_norm")


@dataclass
class _Samples:
    """A rollout flattened to one row per agent-transition, with its TD(lambda) targets."""

    actor_obs: torch.Tensor
    critic_obs: torch.Tensor
    value_obs: torch.Tensor | None
    masks: torch.Tensor
    actions: torch.Tensor
    behaviour: torch.Tensor
    targets: torch.Tensor


def update(networks: COMANetworks, target_critic: nn.Module, optimisers: dict[str, Any],
           rollout: Rollout, eps: float, generator: torch.Generator,
           train_actor: bool = True) -> dict[str, float]:
    """One COMA update on a rollout; returns the mean losses and diagnostics.

    ``train_actor=False`` fits only the critic(s) (a critic warm-up): the actor, its
    optimiser and its diagnostics are left alone. The update runs where the networks are: a
    CPU rollout is moved to their device (on the CPU it is used as it is); ``generator``
    (shuffling) is a CPU generator either way. The forward passes run in the config's
    ``precision`` (:func:`~coma.networks.mixed_precision`); losses, advantages and targets
    are float32.

    Raises:
        TrainingDiverged: a loss is not finite (the networks may be damaged: do not save).
    """
    cfg = networks.coma_config
    device = next(networks.critic.parameters()).device
    samples = _flatten(networks, target_critic, rollout.to(device), device)
    logs: dict[str, list[float]] = {k: [] for k in _LOG_KEYS}
    count = len(samples.actions)
    for _ in range(cfg.epochs):
        order = torch.randperm(count, generator=generator).to(device)
        for start in range(0, count, cfg.minibatch_size):
            batch = order[start:start + cfg.minibatch_size]
            q = _critic_step(networks, optimisers, samples, batch, logs)
            if train_actor:
                _actor_step(networks, optimisers, samples, batch, q, eps, device, logs)
    return {k: float(np.mean(v)) for k, v in logs.items() if v}


def _flatten(networks: COMANetworks, target_critic: nn.Module, rollout: Rollout,
             device: torch.device) -> _Samples:
    """The rollout's inputs in each network's layout, one row per agent-transition, and the
    TD(lambda) targets per agent and episode from the target critic."""
    cfg = networks.coma_config
    e, n, t = rollout.actions.shape
    actor_obs = in_input_layout(networks.actor, rollout.actor_obs.flatten(0, 2))
    critic_obs = in_input_layout(networks.critic, rollout.critic_obs.flatten(0, 2))
    value_obs = None
    if rollout.value_obs is not None and networks.value is not None:
        value_obs = in_input_layout(networks.value, rollout.value_obs.flatten(0, 2))
    with torch.no_grad():
        q_target = learning_forward(target_critic, critic_obs, cfg.precision).view(
            e, n, t, N_ACTIONS)
        q_target_taken = q_target.gather(-1, rollout.actions.unsqueeze(-1)).squeeze(-1)
        rewards = rollout.rewards.unsqueeze(1).expand(e, n, t)
        if cfg.critic_targets == "reference":
            # The authors' targets over each agent's buffer of episodes, on their reward timing.
            targets = reference_td_targets(lagged_rewards(rewards, 0.0).transpose(0, 1),
                                           q_target_taken.transpose(0, 1), cfg.gamma,
                                           cfg.td_lambda).transpose(0, 1)
        else:
            next_values = torch.roll(q_target_taken, shifts=-1, dims=-1)  # Q'(s_{t+1}, u_{t+1})
            terminal = torch.zeros(e, n, t, dtype=torch.bool, device=device)
            terminal[..., -1] = True
            targets = td_lambda_targets(rewards, next_values, terminal, cfg.gamma,
                                        cfg.td_lambda)
    return _Samples(actor_obs, critic_obs, value_obs, rollout.masks.flatten(0, 2),
                    rollout.actions.flatten(), rollout.behaviour_probs.flatten(),
                    targets.flatten())


def _critic_step(networks: COMANetworks, optimisers: dict[str, Any], samples: _Samples,
                 batch: torch.Tensor, logs: dict[str, list[float]]) -> torch.Tensor:
    """Fit the critic (and a central value) to the targets on ``batch``; returns the critic's
    pre-step Q, which serves the actor (one forward pass fewer per mini-batch)."""
    cfg = networks.coma_config
    q = learning_forward(networks.critic, samples.critic_obs[batch], cfg.precision)
    q_taken = q.gather(-1, samples.actions[batch].unsqueeze(-1)).squeeze(-1)
    critic_loss = torch.mean((q_taken - samples.targets[batch]) ** 2)
    _check_finite("critic loss", critic_loss)
    logs["critic_grad_norm"].append(_clip_step(optimisers["critic"], networks.critic,
                                               critic_loss, cfg.max_grad_norm))
    logs["critic_loss"].append(critic_loss.item())
    if networks.value is not None:
        v = learning_forward(networks.value, samples.value_obs[batch], cfg.precision).squeeze(-1)
        value_loss = torch.mean((v - samples.targets[batch]) ** 2)
        _check_finite("value loss", value_loss)
        _clip_step(optimisers["value"], networks.value, value_loss, cfg.max_grad_norm)
        logs["value_loss"].append(value_loss.item())
    return q


def _actor_step(networks: COMANetworks, optimisers: dict[str, Any], samples: _Samples,
                batch: torch.Tensor, q: torch.Tensor, eps: float, device: torch.device,
                logs: dict[str, list[float]]) -> None:
    """One actor step on ``batch``: the advantage from the critic's ``q``, then the loss."""
    cfg = networks.coma_config
    logits, penalty = _actor_logits(networks, samples, batch, device)
    masks, actions = samples.masks[batch], samples.actions[batch]
    probs = bounded_softmax(logits, masks, eps)
    q = q.detach()
    with torch.no_grad():
        if cfg.variant == "central_qv":
            baseline = learning_forward(networks.value, samples.value_obs[batch],
                                        cfg.precision).squeeze(-1)
        else:
            baseline = counterfactual_baseline(q, probs.detach(), masks)
        # The paper values the action taken by the critic's Q(s, u); ``return`` by the flown
        # lambda-return (the critic's own target), the baseline the same either way.
        taken = (samples.targets[batch] if cfg.advantage == "return"
                 else q.gather(-1, actions.unsqueeze(-1)).squeeze(-1))
        advantage = taken - baseline
    raw_std = float(advantage.std()) if len(batch) > 1 else 0.0
    if cfg.normalise_advantage and len(batch) > 1:
        advantage = (advantage - advantage.mean()) / (advantage.std() + 1e-8)
    taken = probs.gather(-1, actions.unsqueeze(-1)).squeeze(-1)
    if cfg.clip_ratio > 0:
        ratio = taken / samples.behaviour[batch].clamp_min(1e-12)
        clipped = ratio.clamp(1.0 - cfg.clip_ratio, 1.0 + cfg.clip_ratio)
        actor_loss = -torch.mean(torch.min(ratio * advantage, clipped * advantage))
    else:
        actor_loss = -torch.mean(torch.log(taken.clamp_min(1e-12)) * advantage)
    if cfg.entropy_coef > 0:
        entropy = -(probs * torch.log(probs.clamp_min(1e-12))).sum(-1).mean()
        actor_loss = actor_loss - cfg.entropy_coef * entropy
    if penalty is not None:
        actor_loss = actor_loss + cfg.residual_penalty * penalty
    _check_finite("actor loss", actor_loss)
    logs["actor_grad_norm"].append(_clip_step(optimisers["actor"], networks.actor,
                                              actor_loss, cfg.max_grad_norm))
    logs["actor_loss"].append(actor_loss.item())
    logs["advantage_std"].append(raw_std)
    with torch.no_grad():
        p = probs.clamp_min(1e-12)
        logs["policy_entropy"].append(float(-(probs * torch.log(p)).sum(-1).mean()))


def _actor_logits(networks: COMANetworks, samples: _Samples, batch: torch.Tensor,
                  device: torch.device) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The actor's logits on ``batch`` and, for a gain-prior actor with a
    ``residual_penalty``, the mean square of its centred residual over the valid actions."""
    cfg = networks.coma_config
    if not (cfg.residual_penalty > 0 and isinstance(networks.actor, GainPriorActor)):
        return learning_forward(networks.actor, samples.actor_obs[batch], cfg.precision), None
    with mixed_precision(cfg.precision, device):  # both parts float32 (the heads)
        residual, prior = networks.actor.parts(samples.actor_obs[batch])
    valid = samples.masks[batch].to(residual.dtype)
    centred = residual - (residual * valid).sum(-1, keepdim=True) / valid.sum(-1, keepdim=True)
    return residual + prior, (centred ** 2 * valid).sum() / valid.sum()


def _clip_step(optimiser: torch.optim.Optimizer, module: nn.Module, loss: torch.Tensor,
               max_norm: float) -> float:
    """Backpropagate ``loss``, clip the gradient norm to ``max_norm``, step; the norm."""
    optimiser.zero_grad(set_to_none=True)
    loss.backward()
    norm = nn.utils.clip_grad_norm_(module.parameters(), max_norm)
    optimiser.step()
    return float(norm)


def _check_finite(what: str, value: torch.Tensor) -> None:
    if not torch.isfinite(value):
        raise TrainingDiverged(f"{what} is {value.item()}")
