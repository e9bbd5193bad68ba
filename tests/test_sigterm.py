"""SIGTERM (``kill PID``, a scheduler ending a job) stops a command the way Ctrl-C does: what is
stored is kept, one line says how to continue, the exit code is 143 (130 for Ctrl-C), and the
previous SIGTERM handler is back afterwards."""

from __future__ import annotations

import os
import signal

import numpy as np

from ipp_toolkit.planning import Planner, register_planner
from ipp_toolkit.runs.progress import Terminated, run_reporting, sigterm_as_interrupt
from reports.cli import compare_main

FAST = ["--resolution", "1", "--budget", "2", "--agents", "2", "--trials", "4", "--workers",
        "1", "--no-progress"]


class _Flags:
    kill_at_mission: int | None = None
    missions = 0


@register_planner("test-sigterm")
class _TerminatedMidRun(Planner):
    """Flies the first valid action; sends this process SIGTERM in its ``kill_at_mission``-th
    mission (counted from 0 over the missions this process flies)."""

    needs_observations = False
    needs_local_maps = False

    def act(self, views):
        if views[0].step == 0:  # a mission's first decision
            _Flags.missions += 1
            if _Flags.missions - 1 == _Flags.kill_at_mission:
                os.kill(os.getpid(), signal.SIGTERM)
        return np.array([int(np.flatnonzero(v.mask)[0]) for v in views])


def test_sigterm_in_ipp_compare_keeps_the_flown_missions_and_the_same_command_continues(
        tmp_path, capsys, placeholder_figures):
    out = tmp_path / "run"
    before = signal.getsignal(signal.SIGTERM)
    _Flags.kill_at_mission, _Flags.missions = 2, 0
    assert compare_main([*FAST, "--planners", "test-sigterm", "--out", str(out)]) == 143
    err = capsys.readouterr().err
    assert "ipp-compare: terminated; the missions already flown are kept in" in err
    assert "run the same command again to continue" in err and "Traceback" not in err
    assert signal.getsignal(signal.SIGTERM) is before
    assert len(list((out / "shards").rglob("mission_*.json"))) == 2
    _Flags.kill_at_mission, _Flags.missions = None, 0
    assert compare_main([*FAST, "--planners", "test-sigterm", "--out", str(out)]) == 0
    assert _Flags.missions == 2  # only the two missions the first run did not store
    assert "reused 2 stored missions" in capsys.readouterr().err


def test_run_reporting_reports_sigterm_as_terminated_and_ctrl_c_as_interrupted(capsys):
    def terminated() -> int:
        os.kill(os.getpid(), signal.SIGTERM)
        raise AssertionError("SIGTERM did not stop the work")

    def interrupted() -> int:
        raise KeyboardInterrupt

    before = signal.getsignal(signal.SIGTERM)
    assert run_reporting("ipp-train x", terminated, "continue with --resume") == 143
    assert "ipp-train x: terminated; continue with --resume" in capsys.readouterr().err
    assert run_reporting("ipp-train x", interrupted, "continue with --resume") == 130
    assert "ipp-train x: interrupted; continue with --resume" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGTERM) is before
    assert issubclass(Terminated, KeyboardInterrupt)


def test_sigterm_outside_the_block_is_left_to_the_previous_handler():
    seen = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: seen.append(signum))
    try:
        with sigterm_as_interrupt():
            pass
        os.kill(os.getpid(), signal.SIGTERM)
        assert seen == [signal.SIGTERM]
    finally:
        signal.signal(signal.SIGTERM, previous)
