"""Trainer flags whose memory was not estimated (simulator copies, rollouts, replay buffers,
COMA updates) are refused with their estimate before anything is built or written."""

from __future__ import annotations

import pytest

from reports.cli import train_main


@pytest.mark.parametrize("argv, needle", [
    (["ppo", "--n-envs", "20000"], "20000 at once, needs"),
    (["ppo", "--n-steps", "10000000"], "a rollout of n_steps 10000000 x n_envs 4 x 4 UAVs"),
    (["sb3", "--algo", "DQN", "--set", "buffer_size=100000000"],
     "a replay buffer of 100000000 transitions"),
    (["coma", "--set", "missions_per_update=1000000"], "an update of 1000000 missions"),
])
def test_trainer_sizes_that_cannot_fit_are_refused(tmp_path, capsys, argv, needle):
    out = tmp_path / "out"
    assert train_main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    line = err.splitlines()[-1]
    assert "Traceback" not in err and needle in line and "over the limit of" in line
    assert "IPP_MAX_" in line
    assert not out.exists()
