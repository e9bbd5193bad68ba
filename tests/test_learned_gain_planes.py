"""The ``gain`` planes with a learned field prior (``features.gain_interest``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import zero_residual_coma

from ipp_toolkit.belief.field_prior import (
    SHIPPED_PRIOR,
    FieldPrior,
    prior_file,
    shared_prior,
)
from ipp_toolkit.belief.gain import recomputed_footprint_sums
from ipp_toolkit.belief.interest import block_means, square_cells
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.config.settings import parse_feature_flags
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.sim.features import actor_observations, footprint_gain, gain_planes
from ipp_toolkit.sim.mission import reset_mission, step_mission

LEARNED = {"gain": True, "gain_interest": "learned"}


@pytest.mark.parametrize("agents, comm, resolution", [(4, 25.0, 0.5), (2, math.inf, 0.25)])
def test_learned_gain_planes_equal_a_full_recomputation(agents, comm, resolution):
    """The planes weight every cell's interesting-class gain by the prior's prediction from
    the agent's own local map, predicted afresh from the whole maps at every step."""
    config = EnvConfig().replace(world={"resolution": resolution},
                                 team={"n_agents": agents, "comm_range": comm},
                                 features=LEARNED)
    prior = FieldPrior.load(SHIPPED_PRIOR)
    size = config.world.map_cells
    square = square_cells(size, resolution)
    state = reset_mission(config, seed=2, mission=0, namespace="validation")
    camera = state.geometry.camera
    rng = np.random.default_rng(4)
    for _ in range(4):
        step_mission(state, [rng.choice(np.flatnonzero(m)) for m in state.masks()])
        prob = state.maps.prob[:agents]
        weight = prior.fine_values(prob, resolution, square)
        cells = np.repeat(np.repeat(weight, square, axis=-2), square, axis=-1)
        full = recomputed_footprint_sums(state.maps, agents, camera, (1.0, 0.0),
                                         objective="interesting", cell_weight=cells)
        np.testing.assert_allclose(footprint_gain(state), full / camera.largest_footprint_cells,
                                   rtol=0, atol=2e-6)


def test_square_values_equal_the_fine_values_of_the_maps():
    prior = shared_prior("learned")
    rng = np.random.default_rng(0)
    prob = rng.random((3, 500, 500), dtype=np.float32)
    square = square_cells(500, 0.1)
    assert square == 5
    # Bit for bit (ig_learned predicts from the squares): the same inputs, the same network.
    np.testing.assert_array_equal(prior.square_values(block_means(prob, square), 0.1, 500),
                                  prior.fine_values(prob, 0.1, square))
    squares = np.stack([block_means(p, square) for p in prob])  # map by map, as ig_learned
    np.testing.assert_array_equal(squares, block_means(prob, square))


def test_learned_planes_differ_from_the_smoothed_ones_and_a_policy_reads_its_own():
    smoothed = EnvConfig().replace(world={"resolution": 0.5},
                                   features={"gain": True, "gain_smoothing": 5.0})
    learned = smoothed.replace(features=LEARNED)
    state = reset_mission(smoothed, seed=0, mission=0)
    reference = reset_mission(learned, seed=0, mission=0)
    for _ in range(3):  # the same moves on both missions (same starts and terrain)
        actions = [int(np.flatnonzero(m)[-1]) for m in state.masks()]
        step_mission(state, actions)
        step_mission(reference, actions)
    planes = actor_observations(state, learned.features)[:, -3:]
    np.testing.assert_array_equal(planes, gain_planes(reference))
    assert not np.allclose(planes, actor_observations(state, smoothed.features)[:, -3:])
    assert np.all(planes <= 1.0 + 1e-6)


def test_gain_interest_is_validated_and_parsed(tmp_path):
    with pytest.raises(ValueError, match=r"features.gain_interest = 'guess'.*field-prior file"):
        EnvConfig().replace(features={"gain_interest": "guess"})
    with pytest.raises(ValueError, match="gain_interest"):
        EnvConfig().replace(features={"gain_interest": str(tmp_path / "missing.pt")})
    parsed = parse_feature_flags(["gain=true", "gain_interest=learned"])
    assert parsed == {"gain": True, "gain_interest": "learned"}
    assert EnvConfig().replace(features=parsed).features.gain_interest == "learned"
    # a path names a prior file
    own = tmp_path / "prior.pt"
    own.write_bytes(SHIPPED_PRIOR.read_bytes())
    config = EnvConfig().replace(world={"resolution": 0.5},
                                 features={"gain": True, "gain_interest": str(own)})
    state = reset_mission(config, seed=0, mission=0)
    np.testing.assert_array_equal(footprint_gain(state), footprint_gain(state, None, "learned"))


def test_prior_file_names_the_missing_or_folder(tmp_path):
    assert prior_file("learned") == SHIPPED_PRIOR
    with pytest.raises(CheckpointError, match="is a folder"):
        prior_file(tmp_path)
    with pytest.raises(CheckpointError, match="does not exist"):
        prior_file(tmp_path / "nope.pt")


def test_shared_prior_is_loaded_once_and_again_when_the_file_changes(tmp_path):
    own = tmp_path / "prior.pt"
    own.write_bytes(SHIPPED_PRIOR.read_bytes())
    first = shared_prior(own)
    assert shared_prior(own) is first
    shared_prior("learned").save(own)  # rewritten: another version of the file
    assert shared_prior(own) is not first


@pytest.mark.parametrize("false_positive, steps", [(0.0, 0), (0.5, 0), (0.5, 6)])
def test_the_first_agents_best_learned_option_is_ig_learneds_choice(false_positive, steps):
    """Agent 0 hears no lower-index teammate, so ``ig_learned`` flies the argmax of its
    planes: the planes hold that planner's objective, with or without the false-positive
    term, at every step or in the last ``steps``."""
    from baselines.field_prior.planner import LearnedPriorPlanner
    from ipp_toolkit.planning import planner_views
    from ipp_toolkit.sim.features import option_gain_cells

    config = EnvConfig().replace(world={"resolution": 0.5},
                                 features={**LEARNED, "gain_false_positive": false_positive,
                                           "gain_false_positive_steps": steps})
    # one step: the planes hold one-step values (the lookahead: tests/test_lookahead.py)
    planner = LearnedPriorPlanner(false_positive_weight=false_positive,
                                  false_positive_steps=steps or None, lookahead_steps=1)
    planner.reset(config, 0)
    state = reset_mission(config, seed=0, mission=1)
    channel, row, col = option_gain_cells([0, 1, 2], state.geometry.grid_points)
    while not state.done:
        actions = planner.act(planner_views(state, planner))
        options = gain_planes(state)[0, channel, row, col]
        options[~state.masks()[0].astype(bool)] = -np.inf
        best = np.flatnonzero(options >= options.max() - 1e-6)
        assert actions[0] in best  # float32 planes vs the planner's float64 sums
        step_mission(state, actions)


def test_false_positive_planes_equal_a_full_recomputation():
    """w > 0 adds w times the false-positive gain weighted by 1 - the prior, summed over
    every footprint; the interesting-class part is unchanged."""
    w = 0.4
    config = EnvConfig().replace(world={"resolution": 0.5},
                                 features={**LEARNED, "gain_false_positive": w})
    prior = FieldPrior.load(SHIPPED_PRIOR)
    square = square_cells(config.world.map_cells, 0.5)
    state = reset_mission(config, seed=3, mission=0, namespace="validation")
    camera = state.geometry.camera
    rng = np.random.default_rng(5)
    for _ in range(5):
        # Up to 15 m: noisy readings leave cells believed interesting that are not.
        step_mission(state, [rng.choice(np.flatnonzero(m)) for m in state.masks()])
        weight = prior.fine_values(state.maps.prob[:4], 0.5, square)
        cells = np.repeat(np.repeat(weight, square, axis=-2), square, axis=-1)
        interesting = recomputed_footprint_sums(state.maps, 4, camera, (1.0, 0.0),
                                                objective="interesting", cell_weight=cells)
        checking = recomputed_footprint_sums(state.maps, 4, camera, (1.0, 0.0),
                                             objective="false_positive",
                                             cell_weight=1.0 - cells)
        full = (interesting + w * checking) / camera.largest_footprint_cells
        got = footprint_gain(state)
        np.testing.assert_allclose(got, full, rtol=0, atol=2e-6)
    assert np.abs(checking).max() > 0  # the term is not empty on this mission
    plain = footprint_gain(state, false_positive=0.0)
    assert not np.allclose(got, plain)


def test_false_positive_steps_add_the_term_only_in_the_last_steps():
    """With k steps the planes are the prior's alone until k steps are left, then those of the
    term at every step (its cache, built late, agrees with one kept from the start)."""
    k, features = 6, {**LEARNED, "gain_false_positive": 0.5}
    late, always = (reset_mission(EnvConfig().replace(
        world={"resolution": 0.5}, features={**features, "gain_false_positive_steps": steps}),
        seed=3, mission=0, namespace="validation") for steps in (k, 0))
    rng = np.random.default_rng(5)
    while not late.done:
        got = footprint_gain(late)
        if late.budget - late.step > k:
            np.testing.assert_array_equal(got, footprint_gain(late, false_positive=0.0))
            assert late.false_positive_cache is None
        else:
            np.testing.assert_allclose(got, footprint_gain(always), rtol=0, atol=1e-6)
            assert not np.allclose(got, footprint_gain(late, false_positive=0.0))
        actions = [rng.choice(np.flatnonzero(m)) for m in late.masks()]
        step_mission(late, actions)
        step_mission(always, actions)


@pytest.mark.parametrize("bad", [-1, 2.5, True])
def test_gain_false_positive_steps_is_validated(bad):
    with pytest.raises(ValueError, match="gain_false_positive_steps"):
        EnvConfig().replace(features={"gain_false_positive_steps": bad})


@pytest.mark.parametrize("bad", [-0.1, math.inf, math.nan, True])
def test_gain_false_positive_is_validated(bad):
    with pytest.raises(ValueError, match="gain_false_positive"):
        EnvConfig().replace(features={"gain_false_positive": bad})


def test_a_bad_gain_interest_on_the_command_line_exits_2_naming_it(tmp_path, capsys):
    from coma.cli import main as coma_main

    out = tmp_path / "run"
    assert coma_main(["--out", str(out), "--feature", "gain=true",
                      "--feature", "gain_interest=guess"]) == 2
    err = capsys.readouterr().err
    assert "features.gain_interest = 'guess'" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("value, shown", [("-0.2", "-0.2"), ("inf", "inf"), ("lots", None)])
def test_a_bad_gain_false_positive_on_the_command_line_exits_2_naming_it(tmp_path, capsys,
                                                                          value, shown):
    from coma.cli import main as coma_main

    out = tmp_path / "run"
    assert coma_main(["--out", str(out), "--feature", "gain=true",
                      "--feature", f"gain_false_positive={value}"]) == 2
    err = capsys.readouterr().err
    assert "gain_false_positive" in err and "Traceback" not in err
    if shown is not None:
        assert f"features.gain_false_positive = {shown}" in err
    assert not out.exists()


@pytest.mark.parametrize("value, message", [
    ("-1", "features.gain_false_positive_steps = -1: must be an integer >= 0"),
    ("1.5", "gain_false_positive_steps takes an integer"),
])
def test_a_bad_gain_false_positive_steps_on_the_command_line_exits_2_naming_it(
        tmp_path, capsys, value, message):
    from coma.cli import main as coma_main

    out = tmp_path / "run"
    assert coma_main(["--out", str(out), "--feature", "gain=true",
                      "--feature", f"gain_false_positive_steps={value}"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_ig_learned_and_coma_on_its_planes_clean_up_in_the_same_last_steps(tmp_path):
    """``ig_learned``'s default objective and the planes of a ``coma`` policy trained on
    them are the same: the learned prior with the false-positive term in the last 10 steps;
    the prior alone stays one option away, and a zero-residual ``coma`` flies
    ``ig_learned``'s planes' argmax for agent 0."""
    from baselines.field_prior.planner import LearnedPriorPlanner
    from ipp_toolkit.planning import make_planner, planner_views

    default = LearnedPriorPlanner()
    assert (default.false_positive_weight, default.false_positive_steps) == (0.5, 10)
    assert LearnedPriorPlanner(false_positive_weight=0).false_positive_weight == 0
    coma = make_planner("coma", checkpoint=zero_residual_coma(tmp_path / "start.pt"))
    trained = coma.trained_config
    features = trained.features
    assert (features.gain_interest, features.gain_false_positive,
            features.gain_false_positive_steps) == ("learned", 0.5, 10)
    config = trained.replace(world={"resolution": 1.0})
    for planner in (default, coma):
        planner.reset(config, 0)
    alone = LearnedPriorPlanner(false_positive_weight=0)
    alone.reset(config, 0)
    state = reset_mission(config, seed=0, mission=9)  # where the clean-up changes agent 0
    changed = 0
    while not state.done:
        ours = default.act(planner_views(state, default))
        assert coma.act(planner_views(state, coma))[0] == ours[0]
        changed += alone.act(planner_views(state, alone))[0] != ours[0]
        step_mission(state, ours)
    assert changed > 0


def test_the_prior_answers_the_same_squares_again_without_a_second_forward_pass(monkeypatch):
    """The gain planes and a planner's teammate discount ask for the same team's squares in
    one step: the second call returns a copy of the first's answer; other squares are
    predicted afresh."""
    prior = FieldPrior.load(SHIPPED_PRIOR)
    forwards = []
    forward = prior._forward
    monkeypatch.setattr(prior, "_forward", lambda planes: forwards.append(1) or forward(planes))
    rng = np.random.default_rng(1)
    squares = rng.random((2, 100, 100), dtype=np.float32)
    first = prior.square_values(squares, 0.5, 100)
    again = prior.square_values(squares.copy(), 0.5, 100)
    assert len(forwards) == 1 and again is not first
    np.testing.assert_array_equal(again, first)
    first[0, 0, 0] = -1.0  # a caller's change does not reach the kept answer
    assert prior.square_values(squares, 0.5, 100)[0, 0, 0] != -1.0 and len(forwards) == 1
    changed = squares.copy()
    changed[1, 3, 4] += 0.25
    other = prior.square_values(changed, 0.5, 100)
    assert len(forwards) == 2 and not np.array_equal(other, again)
    np.testing.assert_array_equal(other[0], again[0])
    prior.square_values(squares, 0.25, 100)  # another resolution: another prediction
    assert len(forwards) == 3


def test_the_planning_prior_predicts_what_the_file_predicts_in_channels_last_order():
    """The shared prior of planning steps runs its convolutions in channels-last order (about
    twice as fast on one thread); its predictions match a freshly loaded prior's to float32
    rounding, and loading (what training and its validation use) keeps the default order."""
    import torch

    planning = shared_prior("learned")
    plain = FieldPrior.load(SHIPPED_PRIOR)
    assert planning._channels_last and not plain._channels_last
    weight = plain.network.enc1[0].weight
    assert weight.is_contiguous() and not weight.is_contiguous(
        memory_format=torch.channels_last)
    rng = np.random.default_rng(1)
    prob = rng.random((4, 250, 250), dtype=np.float32)
    ours, theirs = planning.predict(prob, 0.2), plain.predict(prob, 0.2)
    assert ours.dtype == np.float32 and ours.shape == theirs.shape
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-5)
