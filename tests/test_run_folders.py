"""Run folders: one run at a time (a lock held for the run, also across processes), made and
used by one command, stored missions checked against the folder's identity when read, and a
new run never replacing what an earlier one left."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import warnings

import pytest
from helpers import tiny_coma, tiny_env

from coma.learner import train
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.runs.evaluation import evaluate
from ipp_toolkit.runs.run_folder import RunFolderError, claim, folder_command
from reports.cli import compare_main, study_main, train_main

FAST = ["--resolution", "1", "--budget", "3", "--agents", "2", "--trials", "1",
        "--planners", "random", "--no-progress"]


def tiny() -> EnvConfig:
    return EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 2, "budget": 3})


def listing(folder) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")) if folder.exists() \
        else []


@pytest.fixture
def held(tmp_path):
    """A folder claimed by a child process for ``command`` (until the test ends)."""
    children = []

    def hold(name: str, command: str = "ipp-compare"):
        folder = tmp_path / name
        code = textwrap.dedent(f"""
            import sys
            from ipp_toolkit.runs.run_folder import claim
            with claim({str(folder)!r}, {command!r}):
                print("held", flush=True)
                sys.stdin.read()
        """)
        child = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE, text=True,
                                 env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
        children.append(child)
        assert child.stdout.readline().strip() == "held"
        return folder, child.pid

    yield hold
    for child in children:
        child.stdin.close()
        child.wait(timeout=30)


@pytest.mark.parametrize("command, run", [
    ("ipp-compare", lambda out: compare_main([*FAST, "--seed", "1", "--out", str(out)])),
    ("ipp-train coma", lambda out: train_main(["coma", "--out", str(out), "--agents", "2",
                                               "--missions", "2"])),
    ("ipp-train ppo", lambda out: train_main(["ppo", "--out", str(out), "--timesteps", "8"])),
    ("ipp-study robustness", lambda out: study_main(["robustness", "--trials", "1",
                                                     "--out", str(out)])),
])
def test_a_second_run_into_a_held_folder_is_refused_naming_the_holder(held, capsys, command,
                                                                      run):
    folder, pid = held("out", command)
    before = listing(folder)
    assert run(folder) == 2
    err = capsys.readouterr().err
    assert "is in use by another run" in err and f"process {pid}" in err
    assert len(err.strip().splitlines()[-1]) < 400 and "Traceback" not in err
    assert listing(folder) == before  # nothing written


def test_the_lock_is_released_with_the_run_and_refused_input_leaves_nothing(tmp_path):
    out = tmp_path / "out"
    with claim(out, "ipp-compare") as run:
        assert run.path == out and (out / ".lock").read_text().strip() == str(os.getpid())
        with claim(out, "ipp-compare"):  # the same run, nested: shares the claim
            pass
        with pytest.raises(RunFolderError, match="held by ipp-compare"):
            with claim(out, "ipp-train coma"):
                pass
    with claim(out, "ipp-compare"):  # released: a later run takes it
        pass
    with pytest.raises(KeyError):
        with claim(tmp_path / "a" / "b", "ipp-compare"):
            raise KeyError("the run failed before writing")
    assert not (tmp_path / "a").exists()  # failed before writing: the claim's files go


def test_a_folder_that_cannot_be_written_is_refused_by_name(tmp_path):
    out = tmp_path / "out"
    (out / ".lock").mkdir(parents=True)  # as an unwritable folder fails: the lock cannot open
    with pytest.raises(RunFolderError, match="cannot write into"):
        with claim(out, "ipp-train coma"):
            pass
    assert sorted(p.name for p in out.iterdir()) == [".lock"]


@pytest.mark.parametrize("maker, other", [
    ("ipp-compare", lambda out: train_main(["coma", "--out", str(out), "--agents", "2"])),
    ("ipp-compare", lambda out: train_main(["ppo", "--out", str(out), "--timesteps", "8"])),
    ("ipp-train coma", lambda out: compare_main([*FAST, "--out", str(out)])),
    ("ipp-train ppo", lambda out: compare_main([*FAST, "--out", str(out)])),
    ("legacy-compare", lambda out: train_main(["coma", "--out", str(out), "--agents", "2"])),
    ("legacy-coma", lambda out: compare_main([*FAST, "--out", str(out)])),
])
def test_a_folder_made_by_another_command_is_refused(tmp_path, capsys, maker, other):
    out = tmp_path / "out"
    if maker == "legacy-compare":  # written before run.json existed
        out.mkdir()
        (out / "config.json").write_text(json.dumps({"config": {}, "seed": 0,
                                                     "namespace": "test"}))
    elif maker == "legacy-coma":
        out.mkdir()
        (out / "config.json").write_text(json.dumps({"coma": {}, "env": {}}))
    else:
        with claim(out, maker):
            (out / "marker").write_text("x")
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert other(out) == 2
    err = capsys.readouterr().err
    assert "was made by" in err and str(out) in err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_shards_of_another_run_are_not_read_as_this_runs(tmp_path):
    """A folder mixed before the lock existed (config.json says seed 1, shards of seed 0):
    the stored missions are checked against the folder's identity and flown again."""
    out = tmp_path / "out"
    evaluate(tiny(), ["random"], missions=2, seed=0, progress=False, out_dir=out)
    identity = json.loads((out / "config.json").read_text())
    identity["seed"] = 1
    (out / "config.json").write_text(json.dumps(identity))
    for shard in (out / "shards" / "random").glob("mission_*.json"):
        data = json.loads(shard.read_text())
        data.pop("run")  # as written before shards carried their run's key
        shard.write_text(json.dumps(data))
    with pytest.warns(UserWarning, match="of seed 0, the folder's is 1"):
        result = evaluate(tiny(), ["random"], missions=2, seed=1, progress=False, out_dir=out)
    assert {row["seed"] for row in result.rows} == {1}
    fresh = evaluate(tiny(), ["random"], missions=2, seed=1, progress=False)
    assert [r["entropy"] for r in result.rows] == [r["entropy"] for r in fresh.rows]
    # A shard keyed to another run (here: namespace) is refused by its key.
    shard = out / "shards" / "random" / "mission_00000.json"
    data = json.loads(shard.read_text())
    data["run"] = "0" * 16
    shard.write_text(json.dumps(data))
    with pytest.warns(UserWarning, match="belongs to another run"):
        evaluate(tiny(), ["random"], missions=2, seed=1, progress=False, out_dir=out)
    assert folder_command(out) == "ipp-compare"


@pytest.mark.parametrize("left", ["best.pt", "warm_start.pt", "last.pt"])
def test_a_new_training_run_never_replaces_a_policy_or_checkpoint(tmp_path, left):
    out = tmp_path / "run"
    out.mkdir()
    (out / left).write_bytes(b"earlier run")
    with pytest.raises(FileExistsError, match=left):
        train(tiny_coma(), tiny_env(), out, progress=False, tensorboard=False)
    assert (out / left).read_bytes() == b"earlier run"
    assert sorted(p.name for p in out.iterdir()) == [left]


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("coma") / "run"
    train(tiny_coma(), tiny_env(), out, progress=False, tensorboard=False)
    return out


@pytest.mark.parametrize("damage, message", [
    ("best-over-last", "is a policy file"),
    ("no-progress", "progress.csv' is missing"),
    ("truncated-progress", "does not hold one row per update"),
    ("garbled-progress", "is damaged"),
    ("binary-progress", "is damaged"),
])
def test_a_damaged_run_folder_is_refused_on_resume(finished_run, tmp_path, damage, message):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    progress = out / "progress.csv"
    if damage == "best-over-last":
        shutil.copy(out / "best.pt", out / "last.pt")
    elif damage == "no-progress":
        progress.unlink()
    elif damage == "truncated-progress":
        progress.write_text("".join(progress.read_text().splitlines(True)[:-1]))
    elif damage == "garbled-progress":
        progress.write_text(progress.read_text()[:-30] + ",x,y,z,w,v,u,t,s,r,q,p,o,n\n")
    else:
        progress.write_bytes(b"\xff\xfe\x00garbage")
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    with warnings.catch_warnings(), pytest.raises(CheckpointError, match=message):
        train(tiny_coma(missions=6), tiny_env(), out, resume=True, progress=False,
              tensorboard=False)
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
