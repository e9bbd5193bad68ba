"""What the console scripts tell a user about what they did: missions reused or flown, default
folders that do not collide, training missions rounded up to whole updates, the reward."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from ipp_toolkit.config.settings import build_env_config
from reports.cli import compare_main, default_compare_out, simulate_main, train_main

TINY = ["--agents", "2", "--trials", "2", "--resolution", "0.5", "--budget", "3",
        "--workers", "1", "--no-progress"]


def test_a_rerun_says_what_it_reused_and_what_it_flew(tmp_path, capsys, placeholder_figures):
    out = tmp_path / "run"
    assert compare_main([*TINY, "--planners", "random", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"reused 0 stored missions from {out}; flew 2 new of 1 planner (random)" in err
    # Partly stored: the stored planner's missions are read back, the new one's flown.
    assert compare_main([*TINY, "--planners", "random,coverage", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert (f"reused 2 stored missions of 1 planner (random) from {out}; flew 2 new of 1 "
            "planner (coverage)") in err
    # The same command again flies nothing, and says so.
    assert compare_main([*TINY, "--planners", "random,coverage", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert (f"reused 4 stored missions of 2 planners (random, coverage) from {out}; flew 0 "
            "new") in err


def test_default_folders_of_other_settings_do_not_collide(tmp_path, monkeypatch, capsys,
                                                          placeholder_figures):
    monkeypatch.chdir(tmp_path)
    argv = ["--agents", "2", "--trials", "1", "--budget", "2", "--planners", "random",
            "--workers", "1", "--no-progress"]
    assert compare_main([*argv, "--resolution", "0.5"]) == 0
    # Another resolution went into the same default folder, which refused it (exit 2).
    assert compare_main([*argv, "--resolution", "1"]) == 0
    folders = sorted(path.name for path in (tmp_path / "results").iterdir())
    assert len(folders) == 2, folders
    assert folders[0].startswith("compare-a2-d25-r0.5-b2-"), folders
    assert folders[1].startswith("compare-a2-d25-r1-b2-"), folders
    # The same settings again find their folder: nothing new is flown.
    assert compare_main([*argv, "--resolution", "1"]) == 0
    assert "flew 0 new" in capsys.readouterr().err
    assert len(list((tmp_path / "results").iterdir())) == 2


def test_the_default_folder_names_the_run_key_and_keeps_the_papers_name(tmp_path):
    paper = build_env_config(None, agents=4, comm=25.0)
    assert default_compare_out(paper, 0, "test", "default") == "results/compare-a4-d25"
    # Planners without weight files of their own grow the same folder.
    assert default_compare_out(paper, 0, "test", "ig,coverage") == "results/compare-a4-d25"
    assert default_compare_out(paper, 0, "validation", "ig") == "results/validate-a4-d25"
    seeded = default_compare_out(paper, 3, "test", "ig")
    assert seeded.startswith("results/compare-a4-d25-seed3-")
    blobs = build_env_config(None, agents=4, comm=25.0, terrain="blobs")
    assert default_compare_out(blobs, 0, "test", "ig").startswith("results/compare-a4-d25-blobs-")
    # A planner's weight file: retrained weights (another content) get another folder.
    weights = tmp_path / "best.pt"
    weights.write_bytes(b"first")
    first = default_compare_out(paper, 0, "test", f"ig,coma={weights}")
    weights.write_bytes(b"second")
    second = default_compare_out(paper, 0, "test", f"ig,coma={weights}")
    assert first != second and first.startswith("results/compare-a4-d25-")
    assert len({first, second, seeded}) == 3


def test_ipp_train_coma_says_it_rounds_the_missions_up_to_whole_updates(tmp_path, capsys,
                                                                         monkeypatch):
    import coma.learner

    asked = []

    def no_training(coma_config, *args, **kwargs):  # what the run would train, not trained
        asked.append(coma_config.missions)
        return SimpleNamespace(updates=1, missions=50, best_entropy=0.5,
                               best_policy=tmp_path / "best.pt")

    monkeypatch.setattr(coma.learner, "train", no_training)
    argv = ["coma", "--out", str(tmp_path / "run"), "--agents", "2", "--warm-start", "none"]
    assert train_main([*argv, "--missions", "8"]) == 0
    err = capsys.readouterr().err
    assert ("ipp-train coma: note: 8 training missions are not whole updates of "
            "missions_per_update = 50: training 50 missions (1 update)") in err
    assert train_main([*argv, "--missions", "100"]) == 0  # whole updates: no note
    assert "note:" not in capsys.readouterr().err
    assert asked == [8, 100]


def test_ipp_simulate_says_what_its_reward_is(tmp_path, capsys):
    argv = ["--out", str(tmp_path), "--resolution", "1.0", "--agents", "2"]
    assert simulate_main(argv) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "reward = 22 (H_t - H_t+1) / H_t - 0.5 per step: H is the weighted entropy" in out
    assert "less than 2.3% is rewarded below 0 even while the entropy falls" in out
    # The config's own weights: without a time penalty a reward is never below 0.
    config = tmp_path / "reward.yaml"
    config.write_text("reward: {alpha: 10, beta: 0}\n")
    assert simulate_main([*argv, "--config", str(config), "--force"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "reward = 10 (H_t - H_t+1) / H_t + 0 per step" in out and "below 0" not in out
    with pytest.raises(SystemExit):
        simulate_main(["--help"])
    assert "rewarded below 0 even while the entropy falls" in " ".join(
        capsys.readouterr().out.split())
