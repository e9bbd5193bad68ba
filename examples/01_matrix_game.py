"""Credit assignment in a two-agent cooperative matrix game (runs in seconds on a CPU).

Two agents pick one of three actions each and share ONE team reward. Agent 2's choice moves
the reward a lot; agent 1's choice moves it a little, but agent 1 still has a best action.
With the shared reward as its learning signal, agent 1 is mostly told how well agent 2 did:
its good action is "punished" whenever agent 2 blunders. COMA's counterfactual baseline asks
instead "how much better was my action than my average one, with my teammate's action held
fixed?", which removes agent 2's contribution from agent 1's signal exactly.

The script prints the advantages each agent would receive for a few joint actions under three
credit-assignment rules, then trains both agents with each rule (a tabular critic learns
Q(u1, u2) from the noisy rewards) and reports how often agent 1 has learned its best action.
The advantage functions are the toolkit's own (``coma.advantages``), the ones the UAV learner
uses.

    python examples/01_matrix_game.py            # full run, ~10 s of CPU
    python examples/01_matrix_game.py --quick    # what the test suite runs
"""

from __future__ import annotations

import argparse

import torch

from coma.advantages import central_value_advantage, counterfactual_advantage
from coma.networks import bounded_softmax

# Team reward R[u1, u2] = own1[u1] + own2[u2]: agent 1's actions differ by 1, agent 2's by 10.
OWN_1 = torch.tensor([0.0, 1.0, 0.5])
OWN_2 = torch.tensor([0.0, 10.0, -10.0])
PAYOFF = OWN_1[:, None] + OWN_2[None, :]  # (3, 3)
NOISE = 1.0  # std of the reward noise
RULES = ("shared reward", "central V (Q - V)", "counterfactual (COMA)")


def advantages(rule: str, q_table: torch.Tensor, joint: torch.Tensor, reward: torch.Tensor,
               policies: list[torch.Tensor], baseline: torch.Tensor) -> list[torch.Tensor]:
    """Per-agent advantages of a batch of joint actions.

    Args:
        rule: one of :data:`RULES`.
        q_table: (3, 3) the critic's Q(u1, u2).
        joint: (B, 2) int joint actions.
        reward: (B,) team rewards received.
        policies: two (3,) action distributions.
        baseline: () a running mean of the reward (the independent learners' baseline).

    Returns:
        two (B,) tensors: the advantage of agent 1 and of agent 2.
    """
    batch = len(joint)
    if rule == "shared reward":
        return [reward - baseline, reward - baseline]
    out = []
    for agent in (0, 1):
        # Q(s, (u_-i, a)) for each of agent i's actions a, teammate's action held fixed.
        q_rows = q_table[:, joint[:, 1]].T if agent == 0 else q_table[joint[:, 0], :]
        mine = joint[:, agent]
        policy = policies[agent].expand(batch, 3)
        if rule == "central V (Q - V)":
            value = (policies[0][:, None] * policies[1][None, :] * q_table).sum()
            out.append(central_value_advantage(q_rows, mine, value.expand(batch)))
        else:
            out.append(counterfactual_advantage(q_rows, mine, policy))
    return out


def show_advantages() -> None:
    """Print the advantages of a few joint actions under uniform policies and the true Q."""
    uniform = [torch.full((3,), 1 / 3), torch.full((3,), 1 / 3)]
    joint = torch.tensor([[1, 2], [1, 1], [0, 1], [0, 2]])
    reward = PAYOFF[joint[:, 0], joint[:, 1]]
    baseline = PAYOFF.mean()
    print("Agent 1's best action is 1, agent 2's is 1. Advantages with the true Q and uniform "
          "policies:")
    print(f"{'joint action':>13} {'reward':>7} | " + " | ".join(f"{r:>23}" for r in RULES))
    rows = {rule: advantages(rule, PAYOFF, joint, reward, uniform, baseline) for rule in RULES}
    for b in range(len(joint)):
        cells = " | ".join(f"A1 {rows[r][0][b]:+6.2f}  A2 {rows[r][1][b]:+6.2f}" for r in RULES)
        print(f"{str(tuple(joint[b].tolist())):>13} {reward[b]:7.2f} | {cells}")
    print("(1, 2): agent 1 chose well, but the shared reward gives it -9.50 because agent 2 "
          "blundered;\n        the counterfactual advantage gives it +0.50, its own "
          "contribution.\n")


def train(rule: str, seed: int, updates: int, batch: int = 8, lr: float = 0.05,
          eps: float = 0.5) -> float:
    """Train both agents' policies; returns agent 1's final greedy P(best action).

    Both agents explore with COMA's bounded softmax (weight ``eps`` on uniform actions), so
    agent 2 keeps blundering now and then, as UAV teammates do early in training. Adam makes
    the step size independent of the advantages' scale, so the rules compare fairly.
    """
    gen = torch.Generator().manual_seed(seed)
    logits = [torch.zeros(3, requires_grad=True), torch.zeros(3, requires_grad=True)]
    optimiser = torch.optim.Adam(logits, lr=lr)
    every = torch.ones(3, dtype=torch.bool)
    q_table, counts = torch.zeros(3, 3), torch.zeros(3, 3)
    baseline = torch.tensor(0.0)
    for _ in range(updates):
        policies = [bounded_softmax(x[None], every[None], eps)[0] for x in logits]
        joint = torch.stack([torch.multinomial(p.detach(), batch, replacement=True,
                                               generator=gen) for p in policies], dim=1)
        reward = PAYOFF[joint[:, 0], joint[:, 1]] + NOISE * torch.randn(batch, generator=gen)
        # The critic: a running mean of the rewards seen for each joint action.
        for (u1, u2), r in zip(joint.tolist(), reward.tolist(), strict=True):
            counts[u1, u2] += 1
            q_table[u1, u2] += (r - q_table[u1, u2]) / counts[u1, u2]
        with torch.no_grad():
            adv = advantages(rule, q_table, joint, reward, [p.detach() for p in policies],
                             baseline)
        baseline = 0.9 * baseline + 0.1 * reward.mean()
        loss = -sum((torch.log(policies[i][joint[:, i]]) * adv[i]).mean() for i in (0, 1))
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    return float(torch.softmax(logits[0].detach(), -1)[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer seeds and updates")
    args = parser.parse_args()
    seeds, updates = (4, 40) if args.quick else (20, 100)
    torch.manual_seed(0)
    show_advantages()
    print(f"Training both agents for {updates} updates of 8 joint actions, {seeds} seeds:")
    for rule in RULES:
        final = [train(rule, seed, updates) for seed in range(seeds)]
        mean = sum(final) / len(final)
        learned = sum(p > 0.9 for p in final)
        print(f"  {rule:<23} agent 1 P(best action) = {mean:.2f} on average; "
              f"> 0.9 in {learned}/{seeds} runs")


if __name__ == "__main__":
    main()
