"""Credit assignment: TD(lambda) targets and the advantages of COMA and its variants.

This module is the one owner of these formulas: the learner, the teaching examples and the
tests import them from here. Everything works on plain tensors, so a 2 x 2 matrix game can
use the same functions as the UAV team.
"""

from __future__ import annotations

import torch

__all__ = ["td_lambda_targets", "counterfactual_advantage", "central_value_advantage"]


def td_lambda_targets(rewards: torch.Tensor, next_values: torch.Tensor, terminal: torch.Tensor,
                      gamma: float, lam: float) -> torch.Tensor:
    """Forward-view lambda-returns of whole episodes, computed backwards in time.

    ``G_t = r_t + gamma * [(1 - lam) * Q'(s_{t+1}, u_{t+1}) + lam * G_{t+1}]`` and, where step t
    ends the episode (``terminal[..., t]``), ``G_t = r_t``: nothing is bootstrapped across an
    episode's end. The last column must be terminal unless the caller passes the bootstrap
    there (``next_values[..., -1]`` is then used with ``G_{T} = next_values[..., -1]``).

    Args:
        rewards: (..., T) reward r_t of each step.
        next_values: (..., T) target-critic value of the *next* transition,
            Q'(s_{t+1}, u_{t+1}); ignored where ``terminal`` is true.
        terminal: (..., T) bool, true where the step ends its episode.
        gamma: discount in [0, 1].
        lam: lambda in [0, 1]; 0 gives one-step TD targets, 1 Monte-Carlo returns.

    Returns:
        (..., T) the targets, same dtype as ``rewards``.
    """
    if rewards.shape != next_values.shape or rewards.shape != terminal.shape:
        raise ValueError(f"rewards {tuple(rewards.shape)}, next_values "
                         f"{tuple(next_values.shape)} and terminal {tuple(terminal.shape)} "
                         "must have the same shape (..., T)")
    not_done = (~terminal.bool()).to(rewards.dtype)
    targets = torch.empty_like(rewards)
    following = next_values[..., -1]  # G_{t+1}; only used where the last step is not terminal
    for t in range(rewards.shape[-1] - 1, -1, -1):
        bootstrap = (1.0 - lam) * next_values[..., t] + lam * following
        targets[..., t] = rewards[..., t] + gamma * not_done[..., t] * bootstrap
        following = targets[..., t]
    return targets


def counterfactual_advantage(q_values: torch.Tensor, actions: torch.Tensor,
                             policy: torch.Tensor, mask: torch.Tensor | None = None
                             ) -> torch.Tensor:
    """COMA's advantage: the value of the action taken minus the policy-weighted average.

    ``A_i = Q(s, (u_-i, u_i)) - sum_a pi(a | o_i) Q(s, (u_-i, a))``, the sum over the agent's
    valid actions with the other agents' actions held fixed (the counterfactual baseline).
    The same formula serves ``actor_independent`` and ``decentralised``, whose critics
    simply see less.

    Args:
        q_values: (B, A) Q(s, (u_-i, a)) for every action a of the agent.
        actions: (B,) int the actions taken.
        policy: (B, A) the agent's action probabilities (rows sum to 1 over valid actions).
        mask: (B, A) valid actions (bool or 0/1); invalid actions get no weight even if
            ``policy`` gives them some.

    Returns:
        (B,) the advantages.
    """
    if q_values.shape != policy.shape or q_values.dim() != 2:
        raise ValueError(f"q_values {tuple(q_values.shape)} and policy {tuple(policy.shape)} "
                         "must both be (B, A)")
    weights = policy if mask is None else policy * mask.to(policy.dtype)
    weights = weights / weights.sum(dim=-1, keepdim=True).clamp_min(1e-12)
    baseline = (weights * q_values).sum(dim=-1)
    taken = q_values.gather(-1, actions.long().unsqueeze(-1)).squeeze(-1)
    return taken - baseline


def central_value_advantage(q_values: torch.Tensor, actions: torch.Tensor,
                            values: torch.Tensor) -> torch.Tensor:
    """Central-QV's advantage ``A_i = Q(s, u) - V(s)``: the baseline ignores the agent's choice.

    Args:
        q_values: (B, A) Q(s, (u_-i, a)).
        actions: (B,) int the actions taken.
        values: (B,) V(s) from a separate state-value critic.

    Returns:
        (B,) the advantages.
    """
    taken = q_values.gather(-1, actions.long().unsqueeze(-1)).squeeze(-1)
    return taken - values
