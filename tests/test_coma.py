"""COMA: rollouts, training runs, checkpoints and the planner (its maths: test_coma_maths.py)."""

from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from helpers import small_config, tiny_coma, tiny_env

from coma.config import VARIANTS, COMAConfig, mission_settings, preset
from coma.learner import TrainingDiverged, setting_of_update, train
from coma.persistence import SHIPPED_POLICIES, check_transfer, load_policy
from coma.planner import COMAPlanner
from coma.rollout import collect_rollout
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.runs.evaluation import run_mission
from ipp_toolkit.sim.mission import MissionGeometry
from reports.cli import train_main


def test_rollout_never_samples_masked_actions():
    env = small_config(n_agents=4)
    config = tiny_coma()
    from coma.persistence import build_networks

    torch.manual_seed(0)
    networks = build_networks(config, env)
    with torch.no_grad():  # a policy that wants "up" and "north" (masked at the start) badly
        networks.actor.head[-1].bias.copy_(torch.tensor([30.0, 30.0, 0, 0, 0, 0]))
    rollout = collect_rollout(networks, env, MissionGeometry(env), 0, 0, 3, 0.5)
    taken = rollout.masks.gather(-1, rollout.actions.unsqueeze(-1))
    assert taken.all()
    assert rollout.actor_obs.shape[:3] == (3, 4, env.team.budget)
    assert rollout.transitions == 3 * 4 * env.team.budget


# ---------------------------------------------------------------------------- config


def test_config_validation_names_field_and_value():
    with pytest.raises(ValueError, match=r"variant = 'comma'"):
        COMAConfig(variant="comma")
    with pytest.raises(ValueError, match=r"gamma = 1.5"):
        COMAConfig(gamma=1.5)
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['lr'\]"):
        COMAConfig().replace(lr=1.0)
    assert preset("paper").width == 256 and preset("paper").lr_actor == 1e-5
    assert preset("paper").eps_start == 0.5 and not preset("paper").warm_start.enabled
    assert preset("cpu") == COMAConfig() and COMAConfig().warm_start.planner == "ig"
    with pytest.raises(ValueError, match="unknown COMA preset"):
        preset("gpu")


# ---------------------------------------------------------------------------- training


@pytest.mark.parametrize("variant", VARIANTS)
def test_each_variant_trains_and_its_policy_plays(variant, tmp_path):
    result = train(tiny_coma(variant=variant), tiny_env(), tmp_path, progress=False,
                   tensorboard=False)
    assert result.updates == 2 and result.missions == 4
    assert math.isfinite(result.best_entropy)
    assert (tmp_path / "progress.csv").read_text().count("\n") == 3
    networks, data = load_policy(result.best_policy)
    assert networks.coma_config.variant == variant
    assert (networks.value is not None) == (variant == "central_qv")
    planner = COMAPlanner(result.best_policy)
    outcome = run_mission(tiny_env(), planner, seed=0, mission=0)
    assert len(outcome["rows"]) == tiny_env().team.budget + 1


def test_clipped_normalised_actor_update_trains(tmp_path):
    config = tiny_coma(clip_ratio=0.2, normalise_advantage=True, entropy_coef=0.01, epochs=3)
    result = train(config, tiny_env(), tmp_path, progress=False, tensorboard=False)
    for row in result.history:
        assert math.isfinite(row["actor_loss"]) and math.isfinite(row["critic_loss"])
    with pytest.raises(ValueError, match="clip_ratio = -0.1"):
        tiny_coma(clip_ratio=-0.1)


def test_rollout_records_behaviour_probabilities():
    from coma.persistence import build_networks

    env = tiny_env()
    torch.manual_seed(0)
    networks = build_networks(tiny_coma(), env)
    rollout = collect_rollout(networks, env, MissionGeometry(env), 0, 0, 2, 0.5)
    probs = rollout.behaviour_probs
    assert probs.shape == rollout.actions.shape
    # Bounded softmax with eps = 0.5 over at most 6 valid actions: each is >= 0.5 / 6.
    assert (probs >= 0.5 / 6 - 1e-6).all() and (probs <= 1).all()


def test_tensorboard_and_cli(tmp_path):
    out = tmp_path / "run"
    code = train_main(["coma", "--out", str(out), "--missions", "2", "--agents", "2",
                       "--resolution", "1.0", "--no-progress", "--set", "width=8",
                       "--set", "hidden=16", "--set", "missions_per_update=2",
                       "--set", "eval_missions=1", "--set", "minibatch_size=60",
                       "--warm-start", "none"])
    assert code == 0
    assert any((out / "tb").iterdir())
    assert (out / "training.png").stat().st_size > 5_000 and (out / "training.pdf").exists()
    # A folder that holds a run is never overwritten without --resume.
    assert train_main(["coma", "--out", str(out), "--missions", "2"]) == 2
    assert train_main(["coma", "--out", str(tmp_path / "x"), "--variant", "comma"]) == 2
    assert train_main(["coma", "--out", str(tmp_path / "y"), "--set", "lr_actor=-1"]) == 2


def test_resume_continues_the_same_run(tmp_path):
    # Domain randomisation too: the resumed run must train on the same settings in turn.
    config, env = tiny_coma(missions=6, team_sizes=(2, 3)), tiny_env()
    straight = train(config, env, tmp_path / "a", progress=False, tensorboard=False)
    train(config, env, tmp_path / "b", progress=False, tensorboard=False, max_updates=1)
    resumed = train(config, env, tmp_path / "b", resume=True, progress=False,
                    tensorboard=False)
    assert resumed.updates == straight.updates == 3
    a, _ = load_policy(straight.last_checkpoint)
    b, _ = load_policy(resumed.last_checkpoint)
    for key, value in a.actor.state_dict().items():
        assert torch.equal(value, b.actor.state_dict()[key]), key
    for key, value in a.critic.state_dict().items():
        assert torch.equal(value, b.critic.state_dict()[key]), key
    keys = ("update", "return_mean", "critic_loss", "actor_loss", "eval_entropy_final")
    assert [r[k] for r in straight.history for k in keys] == pytest.approx(
        [r[k] for r in resumed.history for k in keys])
    with pytest.raises(CheckpointError, match="other COMA settings"):
        train(config.replace(lr_actor=1.0), env, tmp_path / "b", resume=True, progress=False,
              tensorboard=False)
    with pytest.raises(FileExistsError, match="resume"):
        train(config, env, tmp_path / "b", progress=False, tensorboard=False)


def test_mission_settings_cover_every_pair_in_balanced_seeded_order():
    env = tiny_env()
    assert mission_settings(tiny_coma(), env) == [env]
    settings = mission_settings(tiny_coma(team_sizes=(2, 3), comm_ranges=(0, "inf")), env)
    assert [(c.team.n_agents, c.team.comm_range, c.team.start) for c in settings] == [
        (2, 0.0, "fixed"), (2, math.inf, "fixed"), (3, 0.0, "random"), (3, math.inf, "random")]
    assert all(c.world == env.world and c.features == env.features for c in settings)
    order = [setting_of_update(4, 7, u) for u in range(12)]
    for block in range(3):
        assert sorted(order[4 * block:4 * block + 4]) == [0, 1, 2, 3]
    assert order == [setting_of_update(4, 7, u) for u in range(12)]
    assert order != [setting_of_update(4, 8, u) for u in range(12)]
    with pytest.raises(ValueError, match=r"team_sizes = \(2, 0\)"):
        tiny_coma(team_sizes=(2, 0))
    with pytest.raises(ValueError, match=r"comm_ranges = \(25, 25\).*repeats"):
        tiny_coma(comm_ranges=[25, 25])
    with pytest.raises(ValueError, match="agent_id_scale"):
        mission_settings(tiny_coma(team_sizes=(2, 9)), env)
    config = tiny_coma(team_sizes=[2, 8], comm_ranges=[0, "inf"])
    assert COMAConfig(**config.to_dict()) == config and config.comm_ranges == (0, math.inf)


def test_randomised_training_and_fine_tuning_from_a_policy(tmp_path):
    env = tiny_env()
    first = train(tiny_coma(missions=8, team_sizes=(2, 3), comm_ranges=(0, "inf")), env,
                  tmp_path / "mixed", progress=False, tensorboard=False)
    trained = {(row["n_agents"], row["comm_range"]) for row in first.history}
    assert trained == {(2, 0.0), (2, math.inf), (3, 0.0), (3, math.inf)}
    assert all(math.isfinite(row["eval_entropy_final"]) for row in first.history)
    planner = COMAPlanner(first.best_policy)
    planner.reset(env.replace(team={"n_agents": 3, "start": "random", "comm_range": "inf"}), 0)
    assert not any(note.startswith("team.") for note in planner.transfer_notes)
    planner.reset(env.replace(team={"n_agents": 4, "comm_range": 0}), 0)
    assert planner.transfer_notes == ["team.n_agents: trained 2, running 4"]
    source, _ = load_policy(first.last_checkpoint)
    tuned = train(tiny_coma(missions=2, init_policy=str(first.last_checkpoint)), env,
                  tmp_path / "tuned", progress=False, tensorboard=False, max_updates=0)
    start, data = load_policy(tuned.best_policy)
    assert data["update"] == 0
    for key, value in source.actor.state_dict().items():
        assert torch.equal(value, start.actor.state_dict()[key]), key
    for key, value in source.critic.state_dict().items():
        assert torch.equal(value, start.critic.state_dict()[key]), key
    with pytest.raises(CheckpointError, match="'coma' policy, this run trains 'decentralised'"):
        train(tiny_coma(variant="decentralised", init_policy=str(first.last_checkpoint)), env,
              tmp_path / "other", progress=False, tensorboard=False)
    with pytest.raises(CheckpointError, match="observes"):
        train(tiny_coma(init_policy=str(first.last_checkpoint)),
              env.replace(features={"footprints": False}), tmp_path / "planes",
              progress=False, tensorboard=False)
    assert train_main(["coma", "--out", str(tmp_path / "cli"), "--team-sizes", "2,x"]) == 2
    assert train_main(["coma", "--out", str(tmp_path / "cli"), "--init", "nope.pt"]) == 2
    assert train_main(["coma", "--out", str(tmp_path / "cli"), "--team-sizes", "2,16"]) == 2


def test_nan_loss_stops_and_keeps_the_last_good_checkpoint(tmp_path, monkeypatch):
    config, env = tiny_coma(missions=6), tiny_env()
    train(config, env, tmp_path, progress=False, tensorboard=False, max_updates=1)
    before = (tmp_path / "last.pt").read_bytes()
    import ipp_toolkit.sim.driver  # the mission loop of COMA's rollouts

    monkeypatch.setattr(ipp_toolkit.sim.driver, "step_mission", lambda state, actions: float("nan"))
    with pytest.raises(TrainingDiverged, match=r"critic loss is nan at update 2.*update 1"):
        train(config, env, tmp_path, resume=True, progress=False, tensorboard=False)
    assert (tmp_path / "last.pt").read_bytes() == before


# ---------------------------------------------------------------------------- checkpoints


@pytest.fixture(scope="module")
def trained_policy(tmp_path_factory):
    folder = tmp_path_factory.mktemp("policy")
    return train(tiny_coma(missions=2), small_config(n_agents=4, resolution=1.0), folder,
                 progress=False, tensorboard=False).best_policy


def test_round_trip_gives_identical_actions(trained_policy):
    networks, _ = load_policy(trained_policy)
    again, _ = load_policy(trained_policy)
    planes = torch.rand(7, networks.actor.in_channels, 11, 11)
    assert torch.equal(networks.actor(planes), again.actor(planes))
    assert torch.equal(networks.critic.state_dict()["head.2.bias"],
                       again.critic.state_dict()["head.2.bias"])


def test_corrupt_and_foreign_files_are_refused_by_name(tmp_path, trained_policy):
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(trained_policy.read_bytes()[:100])
    with pytest.raises(CheckpointError, match="corrupt.pt"):
        COMAPlanner(corrupt)
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(3)}, foreign)
    with pytest.raises(CheckpointError, match="foreign.pt.*format tag"):
        COMAPlanner(foreign)
    with pytest.raises(CheckpointError, match="does not exist"):
        COMAPlanner(tmp_path / "missing.pt")


def test_transfer_to_other_team_sizes_and_feature_mismatch(trained_policy):
    planner = COMAPlanner(trained_policy)
    for n_agents, comm in ((2, 0.0), (8, math.inf)):
        config = small_config(n_agents=n_agents, comm_range=comm, resolution=1.0)
        result = run_mission(config, planner, seed=1, mission=0)
        assert len(result["rows"]) == config.team.budget + 1
        assert f"team.n_agents: trained 4, running {n_agents}" in planner.transfer_notes
    # The policy observes with its own planes whatever the mission config switches off.
    other = small_config(n_agents=4, resolution=1.0, features={"footprints": False})
    result = run_mission(other, planner, seed=1, mission=0)
    assert len(result["rows"]) == other.team.budget + 1
    assert any("footprints False -> True" in note for note in planner.transfer_notes)
    with pytest.raises(CheckpointError, match="9-waypoint grid|trained on a 11-waypoint"):
        planner.reset(small_config(world={"area_size": 40.0}), 0)
    with pytest.raises(CheckpointError, match="agent_id_scale = 8; requested 9 agents"):
        planner.reset(small_config(n_agents=9), 0)
    assert check_transfer(planner.trained_config, planner.trained_config) == []


def test_planner_is_greedy_and_deterministic(trained_policy):
    config = small_config(n_agents=4, resolution=1.0)
    first = run_mission(config, COMAPlanner(trained_policy), seed=2, mission=3)
    second = run_mission(config, COMAPlanner(trained_policy), seed=2, mission=3)
    assert [r["entropy"] for r in first["rows"]] == [r["entropy"] for r in second["rows"]]


def test_variants_are_all_distinct_in_what_the_critic_sees():
    from coma.inputs import critic_channels

    features = small_config().features
    counts = {v: critic_channels(v, features) for v in VARIANTS}
    assert counts["coma"] == counts["central_qv"] == counts["actor_independent"] + 6
    assert counts["decentralised"] == 7
    with_own = dataclasses.replace(features, own_position=True)
    assert critic_channels("decentralised", with_own) == 8
    assert len(set(itertools.chain(counts.values()))) == 3


# ---------------------------------------------------------------------------- warm start


def test_warm_start_imitates_the_demonstrator(tmp_path):
    from coma.warm_start import WarmStartConfig

    env = tiny_env()
    warm = WarmStartConfig(planner="coverage", missions=6, missions_per_batch=3, epochs=30,
                           minibatch_size=40, lr=3e-3, holdout=0.34)
    result = train(tiny_coma(missions=2), env, tmp_path, progress=False, tensorboard=False,
                   warm_start=warm)
    import json

    info = json.loads((tmp_path / "config.json").read_text())["warm_start"]
    assert info["planner"] == "coverage"
    # Coverage is a fixed path: an imitating actor reproduces most of its held-out choices.
    assert info["result"]["imitation_accuracy"] > 0.5
    networks, data = load_policy(tmp_path / "warm_start.pt")
    assert data["warm_start"]["demo_return"] == pytest.approx(info["result"]["demo_return"])
    assert result.updates == 1
    with pytest.raises(ValueError, match="missions = 0"):
        WarmStartConfig(missions=0)
    code = train_main(["coma", "--out", str(tmp_path / "bad"), "--warm-start", "nosuch"])
    assert code == 2


def test_warm_start_settings_come_from_the_coma_config(tmp_path):
    import json

    config = tiny_coma(missions=2, warm_start={"planner": "coverage", "missions": 2,
                                               "epochs": 3})
    train(config, tiny_env(), tmp_path, progress=False, tensorboard=False)
    stored = json.loads((tmp_path / "config.json").read_text())
    info = stored["warm_start"]
    assert (info["planner"], info["missions"], info["epochs"]) == ("coverage", 2, 3)
    # The run folder records the nested form, not the old flat names.
    assert stored["coma"]["warm_start"]["missions"] == 2
    assert not {"warm_start_missions", "warm_start_epochs"} & set(stored["coma"])
    with pytest.raises(ValueError, match=r"warm_start\.epochs = 0"):
        tiny_coma(warm_start={"epochs": 0})


@pytest.mark.parametrize("name", sorted(SHIPPED_POLICIES))
def test_shipped_policies_load_by_name_and_fly(name):
    from ipp_toolkit.planning import make_planner

    planner = make_planner("coma", checkpoint=f"shipped:{name}")
    assert Path(planner.checkpoint).stat().st_size < 2_000_000
    config = small_config(n_agents=8, comm_range=math.inf, resolution=1.0)
    result = run_mission(config, planner, seed=0, mission=0)
    assert len(result["rows"]) == config.team.budget + 1
    transferred = [note for note in planner.transfer_notes if note.startswith("team.")]
    assert transferred == ["team.n_agents: trained 4, running 8",
                           "team.comm_range: trained 25.0, running inf"]


def test_cli_agents_keeps_the_configs_start_choice(tmp_path):
    from coma.cli import build_parser, configs_from_args
    from ipp_toolkit.config.files import config_to_dict

    random_starts = config_to_dict(tiny_env().replace(team={"start": "random"}))
    path = tmp_path / "mission.yaml"
    path.write_text(yaml.safe_dump(random_starts))
    for argv, start in ((["--config", str(path), "--agents", "4"], "random"),
                        (["--agents", "4"], "fixed"),
                        (["--agents", "3"], "random")):  # no documented fixed starts for 3
        _, env = configs_from_args(build_parser().parse_args(["--out", "x", *argv]))
        assert env.team.start == start, argv


def test_critic_warmup_leaves_the_actor_alone(tmp_path):
    env = tiny_env()
    source = train(tiny_coma(missions=2), env, tmp_path / "source", progress=False,
                   tensorboard=False).last_checkpoint
    config = tiny_coma(missions=4, critic_warmup_updates=1, init_policy=str(source))
    result = train(config, env, tmp_path / "run", progress=False, tensorboard=False,
                   max_updates=1)
    start, _ = load_policy(source)
    warmed, _ = load_policy(result.last_checkpoint)
    for key, value in start.actor.state_dict().items():
        assert torch.equal(value, warmed.actor.state_dict()[key]), key
    assert any(not torch.equal(v, warmed.critic.state_dict()[k])
               for k, v in start.critic.state_dict().items())
    assert "actor_loss" not in result.history[0]  # no actor step, no actor diagnostics
    # After the warm-up the actor trains again.
    result = train(config, env, tmp_path / "run", resume=True, progress=False,
                   tensorboard=False)
    assert math.isfinite(result.history[-1]["actor_loss"])
    trained, _ = load_policy(result.last_checkpoint)
    assert any(not torch.equal(v, trained.actor.state_dict()[k])
               for k, v in start.actor.state_dict().items())
    with pytest.raises(ValueError, match="critic_warmup_updates = -1"):
        tiny_coma(critic_warmup_updates=-1)


# ---------------------------------------------------------------- gain-prior actor


def test_gain_prior_actor_reads_each_options_waypoint():
    from coma.networks import GainPriorActor
    from ipp_toolkit.sim.team import ACTION_DELTAS

    actor = GainPriorActor(5, 11, (2, 3, 4), width=8, hidden=16, beta=50.0)
    c = 5
    for action, (dx, dy, dz) in enumerate(ACTION_DELTAS):
        planes = torch.zeros(1, 5, 11, 11)
        planes[0, 0] = 1.0  # other planes never count
        channel = 3 if dz > 0 else 4 if dz < 0 else 2
        planes[0, channel, c + dy, c + dx] = 0.2
        with torch.no_grad():
            logits = actor(planes)[0]
        assert int(logits.argmax()) == action
        assert float(logits[action]) == pytest.approx(50.0)  # relative gain 1, residual 0
    with pytest.raises(ValueError, match="beta = 0"):
        GainPriorActor(5, 11, (2, 3, 4), width=8, hidden=16, beta=0.0)


def test_gain_prior_policy_starts_at_the_best_expected_gain(tmp_path):
    import json

    from coma.networks import greedy_actions
    from coma.persistence import build_networks
    from ipp_toolkit.sim.features import actor_observations, footprint_gain
    from ipp_toolkit.sim.mission import reset_mission, step_mission
    from ipp_toolkit.sim.team import ACTION_DELTAS

    env = tiny_env(4).replace(features={"gain": True})
    config = tiny_coma(gain_prior=30.0, missions=2)
    with pytest.raises(ValueError, match="gain_prior = 30.0 needs the gain planes"):
        train(config, tiny_env(4), tmp_path / "refused", progress=False, tensorboard=False)
    train(config, env, tmp_path / "run", progress=False, tensorboard=False)
    start = json.loads((tmp_path / "run" / "config.json").read_text())["gain_prior_start"]
    assert math.isfinite(start["validation_entropy"])  # the start is scored (update 0)
    trained, _ = load_policy(tmp_path / "run" / "last.pt")
    assert type(trained.actor).__name__ == "GainPriorActor"
    assert float(trained.actor.log_beta.detach().exp()) != 30.0  # beta is learned
    # Untrained, the greedy choice is the best waypoint by footprint_gain.
    untrained = build_networks(config, env).actor
    state = reset_mission(env, 0, 0, "validation")
    while not state.done:
        masks = state.masks()
        actions = greedy_actions(untrained, actor_observations(state, env.features), masks)
        gain = footprint_gain(state)
        for k, (x, y, z) in enumerate(state.positions):
            options = [gain[k, z + dz, y + dy, x + dx] if masks[k, a] else -1.0
                       for a, (dx, dy, dz) in enumerate(ACTION_DELTAS)]
            assert options[actions[k]] == pytest.approx(max(options), abs=1e-6)
        step_mission(state, actions)
    with pytest.raises(ValueError, match="gain_prior = -1"):
        tiny_coma(gain_prior=-1)


def test_residual_penalty_keeps_the_gain_prior_actor_near_its_prior(tmp_path):
    import torch

    from ipp_toolkit.sim.features import actor_observations
    from ipp_toolkit.sim.mission import reset_mission

    env = tiny_env(4).replace(features={"gain": True})
    sizes = {}
    for penalty in (0.0, 50.0):
        config = tiny_coma(gain_prior=30.0, missions=8, lr_actor=3e-3, residual_penalty=penalty)
        train(config, env, tmp_path / f"run{penalty}", progress=False, tensorboard=False)
        actor = load_policy(tmp_path / f"run{penalty}" / "last.pt")[0].actor
        state = reset_mission(env, 0, 0, "validation")
        planes = torch.as_tensor(actor_observations(state, env.features))
        with torch.no_grad():
            residual, _ = actor.parts(planes)
        sizes[penalty] = float((residual - residual.mean(-1, keepdim=True)).abs().mean())
    assert sizes[0.0] > 0.0 and sizes[50.0] < 0.5 * sizes[0.0], sizes
    with pytest.raises(ValueError, match="residual_penalty"):
        tiny_coma(residual_penalty=-1.0)


def test_shipped_names_resolve_everywhere_and_removed_ones_say_why(tmp_path):
    from coma.cli import build_parser, configs_from_args
    from coma.persistence import DEFAULT_SHIPPED, SHIPPED_POLICIES, resolve_policy, shipped_policy
    from ipp_toolkit.planning import make_planner

    assert resolve_policy("shipped:paper-actor") == shipped_policy(SHIPPED_POLICIES["paper-actor"])
    assert resolve_policy("runs/x/best.pt") == Path("runs/x/best.pt")
    with pytest.raises(ValueError, match="unknown shipped policy 'nope'; shipped policies: "
                                         "shipped:paper-actor, shipped:scratch"):
        resolve_policy("shipped:nope")
    default = make_planner("coma")
    assert Path(default.checkpoint) == resolve_policy(f"shipped:{DEFAULT_SHIPPED}")
    coma_config, _ = configs_from_args(build_parser().parse_args(
        ["--out", str(tmp_path), "--init", "shipped:paper-actor"]))
    assert coma_config.init_policy == str(resolve_policy("shipped:paper-actor"))
    with pytest.raises(ValueError, match="unknown shipped policy"):
        configs_from_args(build_parser().parse_args(["--out", "x", "--init", "shipped:x"]))
    # The gain-prior policies and their planner alias were removed: asking says where their
    # records are and what to use instead.
    for name in ("prior", "prior-mixture", "spatial-mixture", "learned-mixture"):
        with pytest.raises(ValueError, match="removed 2026-12-03.*experiments/shipped-policies"):
            resolve_policy(f"shipped:{name}")
    with pytest.raises(ValueError, match="coma_prior.*removed 2026-12-03"):
        make_planner("coma_prior")


def test_selection_by_the_worst_gap_to_ig_over_validation_terrains(tmp_path):
    import csv
    import json

    from coma.validation import reference_scores, validation_settings

    env = tiny_env(2)
    config = tiny_coma(missions=4, validation_terrains=("split", "blobs"),
                       selection="worst_vs_ig")
    checks = validation_settings(config, [env])
    assert [c.terrain.kind for c in checks] == ["split", "blobs"]
    train(config, env, tmp_path / "run", progress=False, tensorboard=False)
    info = json.loads((tmp_path / "run" / "config.json").read_text())
    reference = info["validation_reference"]
    assert reference["terrains"] == ["split", "blobs"]
    assert reference["final_entropy"] == pytest.approx(reference_scores(checks, 0, 2))
    with open(tmp_path / "run" / "progress.csv", newline="") as handle:
        gaps = [float(row["eval_gap_worst"]) for row in csv.DictReader(handle)]
    assert gaps and all(math.isfinite(g) for g in gaps)
    best = load_policy(tmp_path / "run" / "best.pt")[1]
    assert best["validation"]["gap_worst"] <= min(gaps) + 1e-12
    assert tiny_coma(validation_terrains="split+real").validation_terrains == ("split", "real")
    assert reference["resolutions"] == [env.world.resolution] * 2
    with pytest.raises(ValueError, match="selection"):
        tiny_coma(selection="best")


def test_validation_at_other_resolutions_flies_every_check_at_each(tmp_path):
    import json

    from coma.validation import validation_settings

    env = tiny_env(2)
    config = tiny_coma(missions=4, validation_terrains=("split", "blobs"),
                       validation_resolutions=(2.0, 1.0), selection="worst_vs_ig")
    checks = validation_settings(config, [env])
    assert [(c.terrain.kind, c.world.resolution) for c in checks] == [
        ("split", 2.0), ("split", 1.0), ("blobs", 2.0), ("blobs", 1.0)]
    train(config, env, tmp_path / "run", progress=False, tensorboard=False)
    info = json.loads((tmp_path / "run" / "config.json").read_text())
    assert info["validation_reference"]["resolutions"] == [2.0, 1.0, 2.0, 1.0]
    assert info["coma"]["validation_resolutions"] == [2.0, 1.0]
    assert tiny_coma(validation_resolutions="0.1+0.5").validation_resolutions == (0.1, 0.5)
    assert tiny_coma(validation_resolutions=0.1).validation_resolutions == (0.1,)
    for bad, why in (("0.1+x", "'x' is not a positive number"),
                     ((0.5, 0.5), "repeats a value"), ((-1.0,), "-1.0 is not a positive")):
        with pytest.raises(ValueError, match=f"validation_resolutions = .*{why}"):
            tiny_coma(validation_resolutions=bad)


def test_coma_sees_what_the_pettingzoo_env_shows_on_the_same_missions():
    """The learner's rollout and the native API are two drivers of one simulator: the same
    missions and actions must give the same actor planes, critic planes, masks and rewards."""
    from coma.persistence import build_networks
    from coma.rollout import collect_rollout
    from ipp_toolkit.config.schema import EnvConfig
    from ipp_toolkit.env import IPPEnv
    from ipp_toolkit.sim.mission import MissionGeometry

    config = EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 2},
                                 terrain={"kind": "blobs"},
                                 features={"own_position": True, "gain": True,
                                           "gain_smoothing": 4.0})
    networks = build_networks(COMAConfig(width=8, hidden=16, warm_start=""), config)
    rollout = collect_rollout(networks, config, MissionGeometry(config), seed=5,
                              first_mission=3, n_missions=2, eps=0.5)
    env = IPPEnv(config, namespace="train")
    for e in range(2):
        observations, _ = env.reset(seed=5, options={"mission": 3 + e})
        for t in range(config.team.budget):
            agents = env.possible_agents
            planes = np.stack([observations[a]["observation"] for a in agents])
            np.testing.assert_array_equal(planes, rollout.actor_obs[e, :, t].numpy())
            masks = np.stack([observations[a]["action_mask"] for a in agents]).astype(bool)
            np.testing.assert_array_equal(masks, rollout.masks[e, :, t].numpy())
            actions = rollout.actions[e, :, t].numpy()
            np.testing.assert_array_equal(env.critic_observations(actions),
                                          rollout.critic_obs[e, :, t].numpy())
            observations, rewards, *_ = env.step(dict(zip(agents, actions.tolist(),
                                                          strict=True)))
            assert rewards[agents[0]] == pytest.approx(float(rollout.rewards[e, t]), abs=1e-6)
