"""Credit assignment: TD(lambda) targets and the advantages of COMA and its variants.

This module is the one owner of these formulas: the learner, the teaching examples and the
tests import them from here. Everything works on plain tensors, so a 2 x 2 matrix game can
use the same functions as the UAV team.
"""

from __future__ import annotations

import torch

__all__ = ["td_lambda_targets", "reference_td_targets", "lagged_rewards",
           "counterfactual_advantage", "counterfactual_baseline", "central_value_advantage"]


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


def reference_td_targets(rewards: torch.Tensor, target_q: torch.Tensor, gamma: float,
                         lam: float) -> torch.Tensor:
    """The critic targets the authors' code computes (not the paper's TD(lambda)).

    Kept to measure whether the published learning depended on them (``critic_targets =
    "reference"`` of :class:`~coma.config.COMAConfig`). Each agent's buffer is its E episodes
    of T steps one after another. For buffer position i, step t of episode e, with
    ``M = T - t`` steps left in the episode:

    * the first step of every episode but the buffer's first gets the target 0;
    * the n-step returns ``G(n) = sum_{k<n} gamma^k r_{i+k} + gamma^n Q'(i+n)``, n = 1..M,
      weighted ``(1 - lam) lam^(n-1)``; ``G(M)`` bootstraps from the buffer's next position,
      the *next episode's* first state (nothing after the buffer's end);
    * outside the buffer's last episode, a Monte-Carlo tail ``sum_{k<M} gamma^k r_{i+k}``
      weighted ``(1 - lam) lam^(M+1)``, so the weights do not sum to one.

    With r = 1, Q' = 0, two episodes of 4 steps, gamma 0.99 and lambda 0.8 this gives
    [1.56, 1.14, 0.72, 0.33, 0.0, 0.90, 0.52, 0.20] (the correct lambda-returns are
    [2.92, 2.42, 1.79, 1.0] twice). In their runs Q' was the critic's random start, never
    updated: the learner does not refresh the target critic in this mode.

    Args:
        rewards: (A, E, T) reward of each step, per agent buffer.
        target_q: (A, E, T) target critic's Q'(s_t, u_t) of each step.
        gamma: discount.
        lam: lambda.

    Returns:
        (A, E, T) the targets.
    """
    if rewards.shape != target_q.shape or rewards.dim() != 3:
        raise ValueError(f"rewards {tuple(rewards.shape)} and target_q "
                         f"{tuple(target_q.shape)} must both be (A, E, T)")
    agents, episodes, steps = rewards.shape
    r = rewards.reshape(agents, episodes * steps).double()
    q = target_q.reshape(agents, episodes * steps).double()
    length = episodes * steps
    q_after = torch.cat([q, torch.zeros(agents, steps + 1, dtype=q.dtype)], dim=1)
    r_after = torch.cat([r, torch.zeros(agents, steps + 1, dtype=r.dtype)], dim=1)
    targets = torch.zeros(agents, length, dtype=r.dtype)
    for i in range(length):
        e, t = divmod(i, steps)
        if t == 0 and e > 0:
            continue
        left = steps - t
        discounts = gamma ** torch.arange(left, dtype=r.dtype)
        partial = torch.cumsum(r_after[:, i:i + left] * discounts, dim=1)  # sum_{k<n}, n=1..M
        n = torch.arange(1, left + 1, dtype=r.dtype)
        n_step = partial + gamma ** n * q_after[:, i + 1:i + left + 1]
        weights = (1 - lam) * lam ** (n - 1)
        total = (n_step * weights).sum(dim=1)
        if e < episodes - 1:
            total = total + (1 - lam) * lam ** (left + 1) * partial[:, -1]
        targets[:, i] = total
    return targets.reshape(agents, episodes, steps).to(rewards.dtype)


def lagged_rewards(rewards: torch.Tensor, first: float) -> torch.Tensor:
    """The authors' reward timing: step t is paid step t-1's reward, step 0 ``first``.

    Their step-t reward credits the measurements at the positions before the move, so an
    action's measurement is paid one step late and the last one never (``rewards``: (..., T)).
    """
    lagged = torch.roll(rewards, shifts=1, dims=-1)
    lagged[..., 0] = first
    return lagged


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
    taken = q_values.gather(-1, actions.long().unsqueeze(-1)).squeeze(-1)
    return taken - counterfactual_baseline(q_values, policy, mask)


def counterfactual_baseline(q_values: torch.Tensor, policy: torch.Tensor,
                            mask: torch.Tensor | None = None) -> torch.Tensor:
    """COMA's baseline ``b_i = sum_a pi(a | o_i) Q(s, (u_-i, a))`` over the valid actions.

    It does not depend on the agent's own action, so subtracting it from any unbiased
    estimate of the action's value (the critic's Q, or a flown return) adds no bias.

    Args:
        q_values: (B, A) Q(s, (u_-i, a)) for every action a of the agent.
        policy: (B, A) the agent's action probabilities.
        mask: (B, A) valid actions, or None.

    Returns:
        (B,) the baselines.
    """
    if q_values.shape != policy.shape or q_values.dim() != 2:
        raise ValueError(f"q_values {tuple(q_values.shape)} and policy {tuple(policy.shape)} "
                         "must both be (B, A)")
    weights = policy if mask is None else policy * mask.to(policy.dtype)
    weights = weights / weights.sum(dim=-1, keepdim=True).clamp_min(1e-12)
    return (weights * q_values).sum(dim=-1)


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
