"""``ig``'s discount of decided teammates' footprints for planners that read the gain planes
(:class:`ipp_toolkit.planning.discount.TeammateDiscount`), and the gain-prior actors' use of
it and of the planes' relative gains."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from helpers import zero_residual_coma

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import choose_for_views, planner_views
from ipp_toolkit.planning.discount import TeammateDiscount
from ipp_toolkit.sim.features import gain_planes, option_gain_cells
from ipp_toolkit.sim.mission import reset_mission, step_mission
from ipp_toolkit.sim.team import ACTION_DELTAS

SPATIAL = {"gain": True, "gain_smoothing": 5.0}
LEARNED_CLEANUP = {"gain": True, "gain_interest": "learned", "gain_false_positive": 0.5,
                   "gain_false_positive_steps": 10}


def _config(features: dict, agents: int = 4, comm: float = math.inf,
            resolution: float = 1.0) -> EnvConfig:
    return EnvConfig().replace(world={"resolution": resolution}, features=features,
                               team={"n_agents": agents, "comm_range": comm},
                               terrain={"kind": "blobs"})


def _plane_option_gains(state) -> np.ndarray:
    """(N, 6) each agent's options' values as the gain planes hold them."""
    planes = gain_planes(state)
    channel, row, col = option_gain_cells((0, 1, 2), planes.shape[-1])
    return planes[:, channel, row, col].astype(np.float64)


def _ig_planner(name: str):
    from baselines.field_prior.planner import LearnedPriorPlanner
    from baselines.heuristics.information_gain import InformationGainPlanner
    from baselines.heuristics.spatial_gain import SpatialGainPlanner

    # one step: the planes' values are one-step values (the lookahead is tested below)
    return {"ig": InformationGainPlanner, "ig_spatial": SpatialGainPlanner,
            "ig_learned": LearnedPriorPlanner}[name](lookahead_steps=1)


def _fly_beside(reference, discounting, plain, config: EnvConfig, missions) -> int:
    """Fly validation ``missions`` with ``reference``'s actions, asserting at every step that
    ``discounting`` chooses the same joint action; return the steps where ``plain`` did not."""
    differs = 0
    for mission in missions:
        for planner in (reference, discounting, plain):
            planner.reset(config, 0)
        state = reset_mission(config, seed=0, mission=mission, namespace="validation")
        while not state.done:
            expected = reference.act(planner_views(state, reference))
            assert discounting.act(planner_views(state, discounting)).tolist() == \
                expected.tolist()
            differs += plain.act(planner_views(state, plain)).tolist() != expected.tolist()
            step_mission(state, expected)
    return differs


@pytest.mark.parametrize("features, name", [({"gain": True}, "ig"), (SPATIAL, "ig_spatial"),
                                            (LEARNED_CLEANUP, "ig_learned")])
def test_the_planes_argmax_with_the_discount_chooses_what_the_ig_planner_chooses(
        features, name):
    """Every agent, every step of a mission with every teammate heard: the planes' best
    option with the decided teammates' footprints discounted is the ``ig`` planner's choice
    for the planes' objective; without the discount some choice differs."""
    config = _config(features)
    planner = _ig_planner(name)
    planner.reset(config, 0)
    discount = TeammateDiscount(config, config.features)
    # A mission where the discount changes a choice of each planner.
    state = reset_mission(config, seed=0, mission=4, namespace="validation")
    undiscounted_differs = 0
    while not state.done:
        views = planner_views(state, planner)
        expected = planner.act(views)
        gains = _plane_option_gains(state)
        discount.start_step(views)

        def rescore(k: int, targets: np.ndarray, gains=gains, views=views) -> np.ndarray:
            return discount.discounted(views[k], gains[k], targets)

        assert choose_for_views(gains, views, rescore).tolist() == expected.tolist()
        undiscounted_differs += choose_for_views(gains, views).tolist() != expected.tolist()
        step_mission(state, expected)
    assert undiscounted_differs > 0


def test_a_teammate_on_the_same_waypoint_covers_the_whole_option_and_a_far_one_none():
    config = _config(LEARNED_CLEANUP, agents=2)
    state = reset_mission(config, seed=1, mission=0, namespace="validation")
    rng = np.random.default_rng(0)
    for _ in range(3):
        step_mission(state, [rng.choice(np.flatnonzero(m)) for m in state.masks()])
    views = planner_views(state, type("LocalMaps", (), {"needs_observations": False})())
    discount = TeammateDiscount(config, config.features, overlap_discount=0.25)
    discount.start_step(views)
    gains = _plane_option_gains(state)[1]
    view = views[1]
    north = 1
    same = (view.position + ACTION_DELTAS[north])[None, :]
    covered = discount.covered_gains(view, same)
    assert covered[north] == pytest.approx(gains[north], rel=1e-5, abs=1e-9)
    assert discount.discounted(view, gains, same)[north] == pytest.approx(
        0.25 * gains[north], rel=1e-4, abs=1e-9)
    grid = state.geometry.grid_points
    far = np.array([[0 if view.position[0] > grid // 2 else grid - 1,
                     0 if view.position[1] > grid // 2 else grid - 1, 0]])
    assert not discount.covered_gains(view, far).any()
    assert discount.discounted(view, gains, np.empty((0, 3), dtype=int)).tolist() == \
        gains.tolist()


def test_the_covered_part_of_each_option_is_the_cell_by_cell_sum_under_a_neighbour():
    """A teammate one waypoint east: every option's covered part is the ``ig_spatial``
    objective summed cell by cell over its footprint's cells inside the teammate's (the
    smoothing on 2 x 2 cell squares at r_M = 0.25 m)."""
    config = _config(SPATIAL, agents=2, resolution=0.25)
    state = reset_mission(config, seed=1, mission=0, namespace="validation")
    rng = np.random.default_rng(1)
    for _ in range(4):
        step_mission(state, [rng.choice(np.flatnonzero(m)) for m in state.masks()])
    reference = _ig_planner("ig_spatial")
    reference.reset(config, 0)
    views = planner_views(state, reference)
    discount = TeammateDiscount(config, config.features)
    discount.start_step(views)
    view = views[1]
    east = 2
    mate = (view.position + ACTION_DELTAS[east])[None, :]
    rects = reference.camera.rects
    r0, r1, c0, c1 = rects[mate[0, 2], mate[0, 1], mate[0, 0]]
    size = view.local_logodds.shape[0]
    under = np.zeros((size, size), dtype=bool)
    under[r0:r1, c0:c1] = True
    covered = discount.covered_gains(view, mate)
    assert covered.any()
    for action, (x, y, z) in enumerate(view.position + ACTION_DELTAS):
        if not (0 <= z < rects.shape[0] and 0 <= min(x, y) and max(x, y) < rects.shape[1]):
            assert covered[action] == 0.0
            continue
        q0, q1, s0, s1 = rects[z, y, x]
        cells = reference.cell_gains(view, z, (slice(0, size), slice(0, size)))
        want = cells[q0:q1, s0:s1][under[q0:q1, s0:s1]].sum(dtype=np.float64)
        assert covered[action] == pytest.approx(want / discount._normaliser, rel=1e-5,
                                                abs=1e-12)


def test_the_greedy_discount_keeps_no_per_agent_sums_for_missions_flown_in_lock_step():
    """COMA's validation flies several missions through one discount: without a lookahead
    its covered parts come from each box's cells, so no agent's map is kept (a kept map
    would be summed again almost whole at every call, one mission after another)."""
    config = _config(SPATIAL, agents=2)
    discount = TeammateDiscount(config, config.features)
    local = type("LocalMaps", (), {"needs_observations": False})()
    states = [reset_mission(config, seed=1, mission=m, namespace="validation") for m in (0, 1)]
    for state in states * 2:
        views = planner_views(state, local)
        discount.start_step(views)
        mate = (views[1].position + ACTION_DELTAS[2])[None, :]
        assert discount.covered_gains(views[1], mate).any()
    assert discount._kept_sums._maps == {}


@pytest.mark.parametrize("value", [-0.1, 1.5, math.nan])
def test_a_discount_outside_zero_to_one_is_refused_naming_it(value):
    from coma.planner import COMAPlanner

    config = _config(LEARNED_CLEANUP)
    with pytest.raises(ValueError, match="overlap_discount"):
        TeammateDiscount(config, config.features, value)
    with pytest.raises(ValueError, match=f"overlap_discount must lie in \\[0, 1\\], got {value}"):
        COMAPlanner(overlap_discount=value)
    from baselines.sb3.planner import PPOPlanner

    with pytest.raises(ValueError, match=f"overlap_discount must lie in \\[0, 1\\], got {value}"):
        PPOPlanner(overlap_discount=value)


def test_a_zero_residual_coma_flies_ig_learneds_choices_for_every_agent(tmp_path):
    """A ``coma`` policy whose residual is its untrained start, greedy, chooses what a greedy
    ``ig_learned`` chooses for every UAV at every step, teammates heard; with
    ``overlap_discount=1`` (the planes' values as they are) it does not."""
    from baselines.field_prior.planner import LearnedPriorPlanner
    from ipp_toolkit.planning import make_planner

    policy = zero_residual_coma(tmp_path / "start.pt")
    ig_learned = LearnedPriorPlanner(lookahead_steps=1)
    coma = make_planner("coma", checkpoint=policy, lookahead_steps=1)
    plain = make_planner("coma", checkpoint=policy, overlap_discount=1.0, lookahead_steps=1)
    assert coma.needs_local_maps and not plain.needs_local_maps
    config = coma.trained_config.replace(world={"resolution": 1.0},
                                         team={"n_agents": 4, "comm_range": math.inf})
    assert _fly_beside(ig_learned, coma, plain, config, missions=(0, 1)) > 0


SILENT = {"lookahead_steps": 3, "lookahead_discount": 0.5, "lookahead_silent": True}


@pytest.mark.parametrize("options, comm", [(SILENT, 0.0), (SILENT, math.inf), ({}, 25.0)])
def test_coma_looking_ahead_flies_ig_learneds_choices_with_the_same_lookahead(options, comm,
                                                                              tmp_path):
    """With a three-step lookahead (without communication too) a zero-residual ``coma``
    values each option's continuation as ``ig_learned`` with the same options does, and so
    flies its choices (a greedy ``coma`` does not, on these missions); so do the defaults of
    both planners."""
    from baselines.field_prior.planner import LearnedPriorPlanner
    from ipp_toolkit.planning import make_planner

    policy = zero_residual_coma(tmp_path / "start.pt")
    ig_learned = LearnedPriorPlanner(**options)
    coma = make_planner("coma", checkpoint=policy, **options)
    greedy = make_planner("coma", checkpoint=policy, lookahead_steps=1)
    assert coma.needs_local_maps
    config = coma.trained_config.replace(world={"resolution": 1.0},
                                         team={"n_agents": 4, "comm_range": comm})
    assert _fly_beside(ig_learned, coma, greedy, config, missions=(0, 1)) > 0


def test_relative_option_gains_keep_the_gains_order_when_every_gain_is_negative():
    """Late in a mission every option's gain can be negative (only cells believed
    uninteresting left): the best option must still score highest."""
    from ipp_toolkit.sim.features import relative_option_gains

    gains = torch.tensor([[-0.0007, -0.0013, -0.0015, -0.001, -0.0009, -0.004],
                          [0.002, 0.001, 0.0, -0.001, 0.0005, 0.0]])
    relative = relative_option_gains(gains)
    assert relative.argmax(dim=1).tolist() == [0, 0]
    assert relative[0, 0].item() == pytest.approx(-1.0, rel=1e-4)
    assert relative[1, 0].item() == pytest.approx(1.0, rel=1e-4)
    assert (relative.argsort(dim=1) == gains.argsort(dim=1)).all()


def test_ppos_gain_prior_reads_negative_gains_in_their_order():
    from gymnasium import spaces

    from baselines.sb3.ppo import GainPriorExtractor

    grid = 11
    space = spaces.Box(-1.0, 1.0, (3, grid, grid), dtype=np.float32)
    extractor = GainPriorExtractor(space, (0, 1, 2), width=4, features_dim=8)
    channel, row, col = option_gain_cells((0, 1, 2), grid)
    planes = torch.zeros((1, 3, grid, grid))
    gains = torch.tensor([-0.003, -0.001, -0.002, -0.004, -0.005, -0.006])
    planes[0, torch.from_numpy(channel), torch.from_numpy(row), torch.from_numpy(col)] = gains
    relative = extractor(planes)[0, -6:]
    assert relative.argmax().item() == 1
    assert (relative.argsort() == gains.argsort()).all()


def test_an_untrained_gain_prior_ppo_flies_the_ig_planner_of_its_planes(tmp_path):
    """A gain-prior PPO policy whose action layer reads only the gains (its untrained start)
    flown by the ``ppo`` planner chooses what ``ig_spatial`` chooses for every UAV once the
    decided teammates' footprints are discounted; with ``overlap_discount=1`` it does not.
    With a lookahead it chooses what ``ig_spatial`` with the same lookahead chooses."""
    from types import SimpleNamespace

    from gymnasium import spaces

    from baselines.heuristics.spatial_gain import SpatialGainPlanner
    from baselines.sb3 import ppo
    from baselines.sb3.planner import PPOPlanner
    from baselines.sb3.ppo_training import training_env_config

    train = ppo.PPOTrainConfig(gain_prior=20.0, n_envs=1, n_steps=64, batch_size=128)
    env_config = training_env_config(train, _config(SPATIAL))
    shape = (len(ppo.actor_plane_names(env_config.features)), 11, 11)
    policy = ppo._build_policy(train, env_config, shape)
    model = SimpleNamespace(policy=policy, num_timesteps=0,
                            observation_space=spaces.Box(-1.0, 1.0, shape, dtype=np.float32))
    path = ppo.save_policy(tmp_path / "prior.pt", model, train, env_config)
    planner, plain, spatial = (PPOPlanner(path, lookahead_steps=1),
                               PPOPlanner(path, overlap_discount=1.0, lookahead_steps=1),
                               SpatialGainPlanner())
    assert planner.needs_local_maps and not plain.needs_local_maps
    config = env_config.replace(team={"n_agents": 4, "comm_range": math.inf})
    assert _fly_beside(spatial, planner, plain, config, missions=(4,)) > 0
    # with a lookahead, as ig_spatial with the same one
    ahead = PPOPlanner(path)  # the default: three steps with communication
    assert _fly_beside(SpatialGainPlanner(lookahead_steps=3), ahead, planner, config,
                       missions=(4,)) > 0


def test_a_discount_is_kept_for_the_next_mission_of_the_same_setting_only():
    """A planner's next mission of the same configuration and options keeps its discount
    (tables and segments built once; the kept sums restart with the mission); any other
    argument builds a new one."""
    config = _config({"gain": True, "gain_smoothing": 5.0}, comm=25.0)
    features = config.features
    first = TeammateDiscount.for_mission(None, config, features, 0.5, 3)
    assert TeammateDiscount.for_mission(first, config, features, 0.5, 3) is first
    other_team = config.replace(team={"comm_range": 0.0})
    for changed in [(other_team, features, 0.5, 3), (config, features, 0.4, 3),
                    (config, features, 0.5, 2),
                    (config, features.__class__(**{**features.__dict__, "gain_smoothing": 4.0}),
                     0.5, 3)]:
        assert TeammateDiscount.for_mission(first, *changed) is not first
