"""The learned field prior: its input planes, labels, resampling, file format and planner."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from baselines.field_prior.planner import LearnedPriorPlanner
from baselines.heuristics.spatial_gain import SpatialGainPlanner
from ipp_toolkit import EnvConfig
from ipp_toolkit.belief.field_prior import (
    INPUT_PLANES,
    FieldPrior,
    PriorNetConfig,
    block_cells,
    block_labels,
    build_network,
    parameter_count,
    prior_inputs,
    resample_matrix,
)
from ipp_toolkit.belief.interest import interest_smoother
from ipp_toolkit.io import CheckpointError, save_torch
from ipp_toolkit.planning import planner_views
from ipp_toolkit.sim.driver import fly_missions, start_missions


def test_input_planes_on_a_hand_sized_map():
    # r_M = 0.5 m: 2 m blocks are 4 x 4 cells; a 6 x 6 map has 2 x 2 blocks, the last
    # row and column of blocks only half inside.
    prob = np.full((1, 6, 6), 0.5, dtype=np.float32)
    prob[0, :4, :4] = 0.9   # block (0, 0): all read interesting
    prob[0, 4:, 4:] = 0.0   # block (1, 1): its 2 x 2 inside cells read uninteresting
    planes = prior_inputs(prob, 0.5)
    assert planes.shape == (1, len(INPUT_PLANES), 2, 2)
    prob_plane, certainty, interesting, uninteresting, inside = planes[0]
    np.testing.assert_allclose(inside, [[1.0, 0.5], [0.5, 0.25]])
    np.testing.assert_allclose(prob_plane, [[0.4, 0.0], [0.0, -0.5]], atol=1e-6)
    np.testing.assert_allclose(certainty, [[0.8, 0.0], [0.0, 1.0]], atol=1e-6)
    np.testing.assert_allclose(interesting, [[1.0, 0.0], [0.0, 0.0]])
    np.testing.assert_allclose(uninteresting, [[0.0, 0.0], [0.0, 1.0]])


def test_input_planes_mean_the_same_at_every_resolution():
    rng = np.random.default_rng(0)
    coarse = rng.choice([0.02, 0.5, 0.97], size=(2, 100, 100)).astype(np.float32)  # 0.5 m
    fine = np.repeat(np.repeat(coarse, 5, axis=1), 5, axis=2)  # the same map at 0.1 m
    assert block_cells(0.5, 100) * 5 == block_cells(0.1, 500) == 20
    np.testing.assert_allclose(prior_inputs(fine, 0.1), prior_inputs(coarse, 0.5), atol=1e-6)


def test_labels_are_the_share_of_interesting_cells():
    truth = np.zeros((6, 6), dtype=bool)
    truth[0, 0:2] = True  # 2 of block (0, 0)'s 16 cells
    truth[5, 5] = True    # 1 of block (1, 1)'s 4 inside cells
    np.testing.assert_allclose(block_labels(truth, 0.5), [[2 / 16, 0.0], [0.0, 1 / 4]])


def test_resampling_keeps_constants_and_interpolates_between_block_centres():
    matrix = resample_matrix(8, 1, 2, 4)  # 8 fine blocks of 1 cell from 2 coarse of 4
    np.testing.assert_allclose(matrix.sum(axis=1), 1.0, rtol=1e-6)
    values = matrix @ np.array([0.0, 1.0], dtype=np.float32)
    # fine centres 0.5..7.5 cells; coarse centres 2 and 6: flat outside, linear between
    np.testing.assert_allclose(values, [0, 0, 0.125, 0.375, 0.625, 0.875, 1, 1], atol=1e-6)
    assert np.array_equal(resample_matrix(3, 4, 3, 4), np.eye(3, dtype=np.float32))


def test_network_shapes_and_parameter_count():
    config = PriorNetConfig(4)
    network = build_network(config)
    assert sum(p.numel() for p in network.parameters()) == parameter_count(config)
    logits = network(torch.zeros(3, len(INPUT_PLANES), 25, 25))
    assert logits.shape == (3, 25, 25)
    with pytest.raises(ValueError, match="width must be an integer in"):
        PriorNetConfig(10**6)


def _tiny_prior(path, width=2, seed=0):
    torch.manual_seed(seed)
    prior = FieldPrior(build_network(PriorNetConfig(width)), PriorNetConfig(width), {"x": 1})
    prior.save(path)
    return prior


def test_prior_file_round_trip_and_refusals(tmp_path):
    prior = _tiny_prior(tmp_path / "prior.pt")
    loaded = FieldPrior.load(tmp_path / "prior.pt")
    prob = np.random.default_rng(1).random((2, 50, 50), dtype=np.float32)
    np.testing.assert_array_equal(loaded.predict(prob, 1.0), prior.predict(prob, 1.0))
    assert loaded.record == {"x": 1}
    save_torch(tmp_path / "foreign.pt", {"state_dict": {}}, "ipp-toolkit/coma")
    save_torch(tmp_path / "huge.pt", {"network": {"width": 10**6}, "state_dict": {}},
               "ipp-toolkit/field-prior")
    save_torch(tmp_path / "misfit.pt", {"network": {"width": 3},
                                        "state_dict": prior.network.state_dict()},
               "ipp-toolkit/field-prior")
    for name, message in (("foreign.pt", "not an 'ipp-toolkit/field-prior' file"),
                          ("huge.pt", "malformed: width must be"),
                          ("misfit.pt", "does not fit its network")):
        with pytest.raises(CheckpointError, match=message):
            FieldPrior.load(tmp_path / name)


def _fly(planner, config, mission=0):
    state, = start_missions(config, 0, mission, 1, "validation")
    planner.reset(config, seed=0)
    actions = []

    def policy(states):
        joint = planner.act(planner_views(states[0], planner))
        actions.append(joint)
        return [joint]

    fly_missions([state], policy)
    return np.array(actions)


def test_the_learned_planner_with_the_gaussian_prior_flies_as_ig_spatial(tmp_path):
    """With the prior's prediction replaced by ig_spatial's smoothing, the planner makes
    ig_spatial's every choice (with the same false-positive term and lookahead): the plumbing
    (blocks, windows, agents) is the same."""
    config = EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 4},
                                 terrain={"kind": "blobs"})
    _tiny_prior(tmp_path / "prior.pt")
    smoother = interest_smoother(config.world.map_cells, config.world.resolution, 5.0)
    for weight, steps in ((0.0, 1), (0.2, 1), (0.2, 3)):
        learned = LearnedPriorPlanner(tmp_path / "prior.pt", false_positive_weight=weight,
                                      false_positive_steps=None, lookahead_steps=steps)
        learned.prior.square_values = lambda squares, resolution, size: smoother.smooth(squares)
        spatial = SpatialGainPlanner(false_positive_weight=weight, lookahead_steps=steps)
        np.testing.assert_array_equal(_fly(learned, config), _fly(spatial, config))


def test_the_learned_planner_flies_valid_missions_and_names_bad_files(tmp_path):
    config = EnvConfig().replace(world={"resolution": 0.5}, team={"n_agents": 2})
    _tiny_prior(tmp_path / "prior.pt", seed=3)
    actions = _fly(LearnedPriorPlanner(tmp_path / "prior.pt"), config)
    assert actions.shape == (config.team.budget, 2)
    (tmp_path / "folder").mkdir()
    with pytest.raises(CheckpointError, match="is a folder"):
        LearnedPriorPlanner(tmp_path / "folder")
    with pytest.raises(CheckpointError, match="does not exist"):
        LearnedPriorPlanner(tmp_path / "missing.pt")


TINY = ["--rounds", "2", "--missions", "3", "--validation-missions", "3", "--epochs", "1",
        "--width", "2", "--resolution", "1", "--team-sizes", "2", "--comm-ranges", "25",
        "--no-progress"]


def test_ipp_train_prior_trains_resumes_and_refuses(tmp_path, capsys):
    from reports.cli import train_main

    out = tmp_path / "run"
    assert train_main(["prior", "--out", str(out), *TINY]) == 0
    prior = FieldPrior.load(out / "best.pt")
    assert prior.record["command"].startswith("ipp-train prior --out")
    assert np.isfinite(prior.record["validation_bce"])
    rows = (out / "progress.csv").read_text().splitlines()
    assert rows[0].startswith("round,epoch") and len(rows) == 3  # 2 rounds x 1 epoch
    assert json.loads((out / "config.json").read_text())["kind"] == "ipp-train prior"
    # a finished run resumes to nothing new; the folder is refused without --resume
    assert train_main(["prior", "--out", str(out), *TINY, "--resume"]) == 0
    assert len((out / "progress.csv").read_text().splitlines()) == 3
    capsys.readouterr()
    assert train_main(["prior", "--out", str(out), *TINY]) == 2
    assert "not an empty folder" in capsys.readouterr().err
    # other settings are refused on --resume, naming the section
    assert train_main(["prior", "--out", str(out), *TINY[:-1], "--epochs", "2",
                       "--resume"]) == 2
    assert "settings differ" in capsys.readouterr().err


def test_ipp_train_prior_repeats_itself_and_continues_after_an_interruption(tmp_path,
                                                                            monkeypatch):
    import baselines.field_prior.training as training
    from reports.cli import train_main

    whole, cut = tmp_path / "whole", tmp_path / "cut"
    assert train_main(["prior", "--out", str(whole), *TINY]) == 0
    # the same run, stopped by Ctrl-C in its second round's training, then resumed
    epochs = training.train_epoch
    calls = []

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return epochs(*args, **kwargs)

    monkeypatch.setattr(training, "train_epoch", interrupted)
    assert train_main(["prior", "--out", str(cut), *TINY]) == 130
    monkeypatch.setattr(training, "train_epoch", epochs)
    assert train_main(["prior", "--out", str(cut), *TINY, "--resume"]) == 0

    def losses(run):
        return [row.split(",")[:5] for row in (run / "progress.csv").read_text().splitlines()]

    assert losses(whole) == losses(cut)
    a, b = FieldPrior.load(whole / "best.pt"), FieldPrior.load(cut / "best.pt")
    for key, value in a.network.state_dict().items():
        assert torch.equal(value, b.network.state_dict()[key])


def test_ipp_train_prior_stopped_before_its_first_checkpoint_starts_again(tmp_path,
                                                                          monkeypatch, capsys):
    import baselines.field_prior.training as training
    from reports.cli import train_main

    out = tmp_path / "run"
    epochs = training.train_epoch

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt  # in the first epoch: before last.pt is written

    monkeypatch.setattr(training, "train_epoch", stopped)
    assert train_main(["prior", "--out", str(out), *TINY]) == 130
    err = capsys.readouterr().err
    assert "no checkpoint was written yet" in err and "start afresh" in err
    assert not (out / "last.pt").exists() and (out / "config.json").is_file()
    monkeypatch.setattr(training, "train_epoch", epochs)
    # Nothing to resume, said precisely; the same command starts the run again.
    assert train_main(["prior", "--out", str(out), *TINY, "--resume"]) == 2
    assert "the run stopped before its first checkpoint" in capsys.readouterr().err
    assert train_main(["prior", "--out", str(out), *TINY]) == 0
    assert (out / "best.pt").is_file()
    # A folder holding anything else is still refused.
    other = tmp_path / "other"
    other.mkdir()
    (other / "config.json").write_text('{"kind": "ipp-train prior"}')
    (other / "notes.txt").write_text("mine")
    assert train_main(["prior", "--out", str(other), *TINY, "--force"]) == 2
    assert "not an empty folder" in capsys.readouterr().err


def test_continue_hint_names_resume_only_where_a_checkpoint_was_written(tmp_path):
    from ipp_toolkit.runs.progress import continue_hint

    hint = continue_hint(tmp_path / "run", "last.pt", "continue with --resume")
    assert "no checkpoint was written yet" in hint()  # no folder at all
    (tmp_path / "run" / "stage-1-a").mkdir(parents=True)
    assert "start afresh" in hint()
    (tmp_path / "run" / "stage-1-a" / "last.pt").write_bytes(b"")
    assert hint() == "continue with --resume"  # a recipe's stage folder
    (tmp_path / "run" / "stage-1-a" / "last.pt").unlink()
    (tmp_path / "run" / "last.pt").write_bytes(b"")
    assert hint() == "continue with --resume"


@pytest.mark.parametrize("flags, message", [
    (["--width", "0"], "argument --width: must be an integer >= 1, got '0'"),
    (["--team-sizes", "2,x"], "argument --team-sizes: must be an integer >= 1, got 'x'"),
    (["--comm-ranges", "-5"], "argument --comm-ranges: --comm-ranges must be >= 0 metres"),
    (["--resolution", "0"], "resolution"),
])
def test_ipp_train_prior_refuses_bad_flags_before_writing(tmp_path, capsys, flags, message):
    from reports.cli import train_main

    out = tmp_path / "run"
    assert train_main(["prior", "--out", str(out), *TINY, *flags]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_ipp_train_prior_refuses_another_command_s_folder(tmp_path, capsys):
    from ipp_toolkit.runs.run_folder import claim
    from reports.cli import train_main

    out = tmp_path / "compare"
    with claim(out, "ipp-compare"):
        (out / "results.csv").write_text("planner\n")
    assert train_main(["prior", "--out", str(out), *TINY]) == 2
    assert "was made by ipp-compare" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == [".lock", "results.csv", "run.json"]


def test_ipp_train_prior_cleanup_flies_the_deployed_objective_in_later_rounds(tmp_path):
    import baselines.field_prior.training as training
    from baselines.field_prior.planner import CLEANUP_WEIGHT
    from reports.cli import train_main

    out = tmp_path / "run"
    assert train_main(["prior", "--out", str(out), *TINY, "--cleanup"]) == 0
    assert json.loads((out / "config.json").read_text())["training"]["cleanup"] is True
    assert type(training._round_planner(out, 0, True)).__name__ == "SpatialGainPlanner"
    assert training._round_planner(out, 1, True).false_positive_weight == CLEANUP_WEIGHT
    assert training._round_planner(out, 1, False).false_positive_weight == 0
    with pytest.raises(ValueError, match="cleanup must be True or False, got 1"):
        training.PriorTrainingConfig(cleanup=1)


def test_ipp_train_prior_resumes_a_run_recorded_before_the_cleanup_setting(tmp_path):
    from reports.cli import train_main

    out = tmp_path / "run"
    assert train_main(["prior", "--out", str(out), *TINY]) == 0
    record = json.loads((out / "config.json").read_text())
    del record["training"]["cleanup"]
    (out / "config.json").write_text(json.dumps(record))
    assert train_main(["prior", "--out", str(out), *TINY, "--resume"]) == 0
    assert train_main(["prior", "--out", str(out), *TINY, "--cleanup", "--resume"]) == 2
