"""Run folders never lose a user's files: only the toolkit's own temporary files of runs that
no longer run are removed, a folder holding files of its own is refused without --force, the
lock is held by the process (not by the lock file's existence), runs inside or above another
run's folder are refused, and every command that writes takes the claim."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap

import pytest

from ipp_toolkit.runs.run_folder import RunFolderError, claim
from reports.cli import compare_main, simulate_main, train_main

FAST = ["--resolution", "1", "--budget", "2", "--agents", "2", "--trials", "1",
        "--planners", "random", "--no-progress"]


def _hold(folder, command: str = "ipp-compare", then: str = "sys.stdin.read()"):
    """A child process that claims ``folder`` and runs ``then`` while holding it."""
    code = textwrap.dedent(f"""
        import os, sys
        from ipp_toolkit.runs.run_folder import claim
        with claim({str(folder)!r}, {command!r}):
            print("held", flush=True)
            {then}
    """)
    child = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True,
                             env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert child.stdout.readline().strip() == "held"
    return child


def _end(child) -> None:
    child.stdin.close()
    child.wait(timeout=30)


def _others_files(folder):
    """Temporary files of other programs, as a download or an editor leaves them."""
    files = {folder / ".download.part.tmp": b"download", folder / "sub" / ".editor.swp.tmp":
             b"editor", folder / ".selfcheck.json.tmp": b"pip"}
    for path, data in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return files


def test_a_run_keeps_temporary_files_it_did_not_write(tmp_path, capsys, placeholder_figures):
    out = tmp_path / "proj"
    assert compare_main([*FAST, "--out", str(out)]) == 0
    files = _others_files(out)
    assert compare_main([*FAST, "--out", str(out)]) == 0  # a run of ours: the folder is its
    capsys.readouterr()
    assert {path: path.read_bytes() for path in files} == files


def test_a_forced_run_into_a_users_folder_keeps_their_temporary_files(tmp_path, capsys,
                                                                     placeholder_figures):
    home = tmp_path / "home"
    files = _others_files(home)
    assert compare_main([*FAST, "--force", "--out", str(home)]) == 0
    capsys.readouterr()
    assert {path: path.read_bytes() for path in files} == files


@pytest.mark.parametrize("trainer", [["prior"], ["prior", "--force"], ["coma"]])
def test_a_refused_trainer_deletes_nothing(tmp_path, capsys, trainer):
    out = tmp_path / "proj"
    files = _others_files(out)
    assert train_main([trainer[0], "--out", str(out), *trainer[1:]]) == 2
    capsys.readouterr()
    assert {path: path.read_bytes() for path in files} == files
    assert sorted(p.name for p in out.iterdir()) == [".download.part.tmp",
                                                     ".selfcheck.json.tmp", "sub"]


@pytest.mark.parametrize("own", [["results.csv"], ["summary.md", "curves.png"]])
def test_a_folder_with_files_of_its_own_is_refused_without_force(tmp_path, capsys,
                                                                placeholder_figures, own):
    mine = tmp_path / "mine"
    mine.mkdir()
    for name in own:
        (mine / name).write_text("the user's own\n")
    assert compare_main([*FAST, "--out", str(mine)]) == 2
    err = capsys.readouterr().err
    assert "holds files no run of the toolkit wrote" in err and own[0] in err
    assert "--force" in err and "Traceback" not in err
    assert sorted(p.name for p in mine.iterdir()) == sorted(own)
    assert all((mine / name).read_text() == "the user's own\n" for name in own)
    assert compare_main([*FAST, "--force", "--out", str(mine)]) == 0
    assert (mine / "run.json").is_file()
    assert compare_main([*FAST, "--out", str(mine)]) == 0  # now a run folder of ours
    with pytest.raises(RunFolderError, match="holds files no run"):
        with claim(tmp_path, "ipp-compare"):
            pass


def test_a_deleted_lock_file_lets_no_second_run_in(tmp_path):
    folder = tmp_path / "out"
    child = _hold(folder)
    try:
        (folder / ".lock").unlink()
        with pytest.raises(RunFolderError, match="in use by another run"):
            with claim(folder, "ipp-compare"):
                pass
    finally:
        _end(child)


def test_a_killed_run_leaves_no_stale_lock(tmp_path):
    folder = tmp_path / "out"
    child = _hold(folder)
    child.send_signal(signal.SIGKILL)
    child.wait(timeout=30)
    with claim(folder, "ipp-compare") as run:  # the lock went with the process
        assert (folder / ".lock").read_text().strip() == str(os.getpid())
    assert run.path == folder


def test_runs_inside_or_above_another_runs_folder_are_refused(tmp_path):
    outer, inner = tmp_path / "a", tmp_path / "a" / "b"
    name = ".x.ipptk-{os.getpid()}-0123abcd.tmp"  # a write in flight
    child = _hold(inner, then=f"open(os.path.join({str(inner)!r}, f'{name}'), 'w').write('x'); "
                  "print('written', flush=True); sys.stdin.read()")
    try:
        assert child.stdout.readline().strip() == "written"
        in_flight = inner / f".x.ipptk-{child.pid}-0123abcd.tmp"
        with pytest.raises(RunFolderError, match="holds the folder of another run"):
            with claim(outer, "ipp-compare", force=True):
                pass
        assert in_flight.read_text() == "x"
        assert sorted(p.name for p in outer.iterdir()) == ["b"]  # nothing written above
    finally:
        _end(child)
    outer = tmp_path / "c"
    child = _hold(outer)
    try:
        with pytest.raises(RunFolderError, match="is inside .*the folder of another run"):
            with claim(outer / "d" / "e", "ipp-compare"):
                pass
        assert not (outer / "d").exists()
    finally:
        _end(child)


def test_a_process_may_nest_runs_in_its_own_folder(tmp_path):
    with claim(tmp_path / "study", "ipp-study robustness"):
        with claim(tmp_path / "study" / "run", "ipp-compare"):
            pass


def test_a_symlink_loop_as_out_is_refused(tmp_path, capsys):
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    assert compare_main([*FAST, "--out", str(loop)]) == 2
    err = capsys.readouterr().err
    assert "cannot be used" in err and str(loop) in err and "Traceback" not in err


@pytest.mark.parametrize("holder, message", [("ipp-compare", "was made by ipp-compare"),
                                             ("ipp-simulate", "in use by another run")])
def test_simulate_into_a_folder_another_run_holds_is_refused(tmp_path, capsys, holder, message):
    folder = tmp_path / "out"
    child = _hold(folder, holder)
    try:
        before = sorted(p.name for p in folder.iterdir())
        assert simulate_main(["--resolution", "1", "--out", str(folder)]) == 2
        assert message in capsys.readouterr().err
        assert sorted(p.name for p in folder.iterdir()) == before
    finally:
        _end(child)
    assert simulate_main(["--resolution", "1", "--out", str(tmp_path / "sim")]) == 0
    assert json.loads((tmp_path / "sim" / "run.json").read_text())["command"] == "ipp-simulate"


def test_the_workers_a_run_starts_may_claim_inside_its_folder(tmp_path):
    # A study's training runs go to worker processes (a process pool, a local Ray): they
    # inherit the study's folder as one they may nest in; an unrelated process may not.
    import subprocess
    import sys

    inner = tmp_path / "study" / "runs" / "a"
    code = ("from ipp_toolkit.runs.run_folder import claim\n"
            f"with claim({str(inner)!r}, 'ipp-train coma'):\n    pass\nprint('claimed')")
    with claim(tmp_path / "study", "ipp-study credit"):
        started = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                 timeout=60)
        assert started.stdout.strip() == "claimed", started.stderr
        unrelated = subprocess.run([sys.executable, "-c", code], capture_output=True,
                                   text=True, timeout=60,
                                   env={k: v for k, v in os.environ.items()
                                        if k != "IPP_TOOLKIT_HOSTING_RUNS"})
        assert "the folder of another run" in unrelated.stderr
