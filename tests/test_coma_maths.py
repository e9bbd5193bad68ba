"""COMA's maths on hand-sized cases: TD(lambda) targets, the advantages, the bounded softmax,
the exploration schedule and the networks' training layout."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from coma.advantages import (
    central_value_advantage,
    counterfactual_advantage,
    counterfactual_baseline,
    lagged_rewards,
    reference_td_targets,
    td_lambda_targets,
)
from coma.networks import ConvNet, bounded_softmax, epsilon_at

# ---------------------------------------------------------------------------- TD(lambda)


def test_td_lambda_matches_hand_values_per_episode():
    # r = 1 everywhere, Q' = 0, two episodes of 4 steps side by side in one row.
    rewards = torch.ones(1, 8)
    terminal = torch.tensor([[False, False, False, True] * 2])
    targets = td_lambda_targets(rewards, torch.zeros(1, 8), terminal, 0.99, 0.8)
    expected = [2.916, 2.419, 1.792, 1.0]
    assert torch.allclose(targets[0], torch.tensor(expected * 2), atol=1e-3)


def _brute_force_lambda_return(rewards, next_values, gamma, lam):
    """Forward view: (1 - lam) sum_n lam^(n-1) G^(n) + lam^(T-t-1) G^MC, one episode."""
    length = len(rewards)
    out = []
    for t in range(length):
        horizon = length - t
        total = 0.0
        for n in range(1, horizon):
            n_step = sum(gamma ** k * rewards[t + k] for k in range(n))
            n_step += gamma ** n * next_values[t + n - 1]  # Q'(s_{t+n}, u_{t+n})
            total += (1 - lam) * lam ** (n - 1) * n_step
        monte_carlo = sum(gamma ** k * rewards[t + k] for k in range(horizon))
        out.append(total + lam ** (horizon - 1) * monte_carlo)
    return out


@pytest.mark.parametrize("lam", [0.0, 0.8, 1.0])
def test_td_lambda_equals_forward_view(lam):
    rng = np.random.default_rng(3)
    rewards = rng.normal(size=6)
    next_values = rng.normal(size=6)
    terminal = torch.zeros(6, dtype=torch.bool)
    terminal[-1] = True
    got = td_lambda_targets(torch.tensor(rewards), torch.tensor(next_values), terminal, 0.9, lam)
    want = _brute_force_lambda_return(rewards, next_values, 0.9, lam)
    assert np.allclose(got.numpy(), want)


@pytest.mark.parametrize("lam", [0.0, 0.5, 0.8, 1.0])
def test_td_lambda_with_an_exact_critic_is_the_monte_carlo_return(lam):
    # On a logged episode, a critic that knows each step's return to go makes every
    # lambda-return the Monte-Carlo return: the targets then carry no critic error at all.
    rng = np.random.default_rng(5)
    rewards = rng.normal(size=(3, 7))
    returns = np.zeros_like(rewards)
    following = np.zeros(3)
    for t in range(6, -1, -1):
        following = rewards[:, t] + 0.95 * following
        returns[:, t] = following
    next_values = np.roll(returns, -1, axis=1)  # Q(s_{t+1}, u_{t+1}) = G_{t+1}
    terminal = torch.zeros(3, 7, dtype=torch.bool)
    terminal[:, -1] = True
    got = td_lambda_targets(torch.tensor(rewards), torch.tensor(next_values), terminal, 0.95,
                            lam)
    assert np.allclose(got.numpy(), returns)


def test_reference_targets_reproduce_the_authors_buffer_on_the_hand_example():
    # r = 1, Q' = 0, one agent, two episodes of 4 steps, gamma 0.99, lambda 0.8: the values
    # the authors' code gives (zero at the second episode's start, weights not summing to 1).
    targets = reference_td_targets(torch.ones(1, 2, 4), torch.zeros(1, 2, 4), 0.99, 0.8)
    expected = [[1.56, 1.14, 0.72, 0.33], [0.0, 0.90, 0.52, 0.20]]
    assert torch.allclose(targets[0], torch.tensor(expected), atol=5e-3)


def test_reference_targets_bootstrap_from_the_next_episodes_first_state():
    # Only Q' at the second episode's first state is non-zero: the first episode's targets
    # see it through each step's longest (whole-episode) return, weighted (1-lam) lam^(M-1).
    target_q = torch.zeros(1, 2, 3)
    target_q[0, 1, 0] = 10.0
    targets = reference_td_targets(torch.zeros(1, 2, 3), target_q, 1.0, 0.5)
    left = torch.tensor([3.0, 2.0, 1.0])
    assert torch.allclose(targets[0, 0], 10.0 * 0.5 * 0.5 ** (left - 1))
    assert torch.all(targets[0, 1] == 0)


def test_lagged_rewards_pay_each_step_one_step_late():
    lagged = lagged_rewards(torch.tensor([[1.0, 2.0, 3.0]]), first=-0.5)
    assert lagged.tolist() == [[-0.5, 1.0, 2.0]]


def test_td_lambda_never_bootstraps_across_episodes():
    rewards = torch.tensor([[0.0, 2.0, 5.0, 7.0]])
    huge = torch.tensor([[1.0, 1e6, 1.0, 1e6]])  # the values after each episode's end
    terminal = torch.tensor([[False, True, False, True]])
    targets = td_lambda_targets(rewards, huge, terminal, 1.0, 0.5)
    assert targets[0, 1] == 2.0 and targets[0, 3] == 7.0
    assert targets[0, 0] == pytest.approx(0.0 + 0.5 * 1.0 + 0.5 * 2.0)


def test_td_lambda_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="same shape"):
        td_lambda_targets(torch.zeros(2, 3), torch.zeros(2, 4), torch.zeros(2, 3).bool(),
                          0.9, 0.8)


# ---------------------------------------------------------------------------- advantages


def test_counterfactual_advantage_against_brute_force_sum():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(5, 6))
    mask = rng.random((5, 6)) < 0.7
    mask[:, 2] = True
    logits = torch.tensor(rng.normal(size=(5, 6)))
    policy = bounded_softmax(logits, torch.tensor(mask), 0.3).numpy()
    actions = np.array([np.flatnonzero(row)[0] for row in mask])
    got = counterfactual_advantage(torch.tensor(q), torch.tensor(actions), torch.tensor(policy),
                                   torch.tensor(mask)).numpy()
    for b in range(5):
        baseline = sum(policy[b, a] * q[b, a] for a in range(6) if mask[b, a])
        assert got[b] == pytest.approx(q[b, actions[b]] - baseline)


def test_counterfactual_advantage_ignores_probability_on_masked_actions():
    q = torch.tensor([[1.0, 100.0, 3.0]])
    policy = torch.tensor([[0.25, 0.5, 0.25]])  # gives weight to a masked action
    mask = torch.tensor([[True, False, True]])
    advantage = counterfactual_advantage(q, torch.tensor([0]), policy, mask)
    assert advantage.item() == pytest.approx(1.0 - 2.0)


def test_central_value_advantage():
    q = torch.tensor([[1.0, 4.0], [2.0, 0.0]])
    got = central_value_advantage(q, torch.tensor([1, 0]), torch.tensor([3.0, 5.0]))
    assert torch.equal(got, torch.tensor([1.0, -3.0]))


# ---------------------------------------------------------------------------- policy


def test_bounded_softmax_floor_mask_and_normalisation():
    logits = torch.tensor([[50.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    mask = torch.tensor([[1, 1, 0, 1, 1, 1]])
    probs = bounded_softmax(logits, mask, 0.5)
    assert probs[0, 2] == 0
    assert probs.sum().item() == pytest.approx(1.0)
    # (1 - eps) on action 0 plus eps/6 everywhere, renormalised over the 5 valid actions.
    assert probs[0, 1].item() == pytest.approx((0.5 / 6) / (1 - 0.5 / 6))
    greedy = bounded_softmax(logits, mask, 0.0)
    assert greedy[0, 0].item() == pytest.approx(1.0)


@pytest.mark.parametrize("grid", [11, 13])
def test_channels_last_training_layout_computes_the_default_layouts_outputs_and_gradients(grid):
    # On the 11 x 11 grid the last convolution covers its whole input and the trainer's
    # layout computes it as a matrix product; on 13 x 13 (a 3 x 3 output) it stays a
    # convolution. Either way: the same function of the same weights.
    torch.manual_seed(0)
    default = ConvNet(5, grid, 6, width=8, hidden=16)
    trained = ConvNet(5, grid, 6, width=8, hidden=16)
    trained.load_state_dict(default.state_dict())
    trained.use_channels_last()
    planes = torch.randn(7, 5, grid, grid)
    weights = torch.randn(7, 6)
    out_default, out_trained = default(planes), trained(planes)
    assert out_trained.shape == (7, 6)
    assert torch.allclose(out_trained, out_default, rtol=1e-5, atol=1e-6)
    (out_default * weights).sum().backward()
    (out_trained * weights).sum().backward()
    for (name, a), b in zip(default.named_parameters(), trained.parameters(), strict=True):
        assert torch.allclose(b.grad, a.grad, rtol=1e-4, atol=1e-5), name
    assert trained.state_dict().keys() == default.state_dict().keys()


def test_epsilon_schedule_paper_values():
    assert epsilon_at(0, 0.5, 0.02, 10_000) == 0.5
    assert epsilon_at(5_000, 0.5, 0.02, 10_000) == pytest.approx(0.26)
    assert epsilon_at(10_000, 0.5, 0.02, 10_000) == 0.02
    assert epsilon_at(70_000, 0.5, 0.02, 10_000) == 0.02


def test_the_counterfactual_baseline_ignores_the_agents_own_action():
    q = torch.tensor([[1.0, 3.0, 5.0]])
    policy = torch.tensor([[0.5, 0.25, 0.25]])
    baseline = counterfactual_baseline(q, policy)
    assert baseline.item() == pytest.approx(0.5 + 0.75 + 1.25)
    for action in range(3):
        advantage = counterfactual_advantage(q, torch.tensor([action]), policy)
        assert advantage.item() == pytest.approx(q[0, action].item() - baseline.item())
