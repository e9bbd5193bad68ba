"""The ``scratch`` preset: COMA from random networks, and the options it is made of."""

from __future__ import annotations

import copy

import pytest
import torch
from helpers import tiny_coma, tiny_env

from coma.cli import build_parser, configs_from_args
from coma.config import PRESETS, preset
from coma.learner import make_optimisers, train
from coma.persistence import build_networks
from coma.rollout import collect_rollout
from coma.update_step import update
from ipp_toolkit.sim.mission import MissionGeometry
from reports.study_cli import _study_parser


def test_scratch_trains_the_paper_learner_on_the_papers_inputs(tmp_path):
    coma_config, env = configs_from_args(build_parser().parse_args(
        ["--out", str(tmp_path), "--preset", "scratch", "--seed", "7"]))
    assert coma_config == preset("scratch", seed=7)  # the recipe of shipped:scratch
    assert not coma_config.warm_start.enabled and coma_config.gain_prior == 0
    assert coma_config.advantage == "return" and coma_config.variant == "coma"
    assert not env.features.own_position and not env.features.gain
    paper = preset("paper")
    for name in ("minibatch_size", "epochs", "lr_critic", "td_lambda", "gamma",
                 "target_update_transitions", "eps_start", "eps_end", "eps_anneal_missions",
                 "missions_per_update"):
        assert getattr(coma_config, name) == getattr(paper, name), name


def test_the_credit_study_offers_every_preset():
    action = next(a for a in _study_parser()._actions if a.dest == "preset")
    assert sorted(action.choices) == sorted(PRESETS)


def _actor_change(advantage: str) -> float:
    """How far one update (one mini-batch, so the actor sees the critic before its step)
    moves the actor when the critic separates nothing (Q = 0)."""
    config = tiny_coma(advantage=advantage, normalise_advantage=False, clip_ratio=0.0,
                       lr_actor=1e-2, epochs=1, minibatch_size=64)  # one mini-batch
    env = tiny_env()
    torch.manual_seed(0)
    networks = build_networks(config, env)
    last = networks.critic.head[-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.zero_()
    before = copy.deepcopy(networks.actor.state_dict())
    rollout = collect_rollout(networks, env, MissionGeometry(env), 0, 0, 4, eps=0.3)
    target = copy.deepcopy(networks.critic)
    update(networks, target, make_optimisers(networks), rollout, 0.3,
           torch.Generator().manual_seed(0))
    after = networks.actor.state_dict()
    return max(float((after[k] - before[k]).abs().max()) for k in before)


def test_the_flown_return_moves_the_actor_where_the_papers_advantage_cannot():
    # Q = 0 everywhere: the paper's advantage Q(s,u) - b is exactly 0 and the actor keeps its
    # weights; the flown return G - b still carries what the missions collected.
    assert _actor_change("critic") == 0.0
    assert _actor_change("return") > 1e-4


@pytest.mark.parametrize("changes", [{"advantage": "return"},
                                     {"critic_targets": "reference"}])
def test_the_options_train_and_are_checked_by_name(changes, tmp_path):
    result = train(tiny_coma(**changes), tiny_env(), tmp_path, progress=False,
                   tensorboard=False)
    assert result.updates == 2
    name = next(iter(changes))
    with pytest.raises(ValueError, match=f"{name} = 'nope'"):
        tiny_coma(**{name: "nope"})
