"""A COMA run stopped at any moment, even between writing its checkpoint and its progress
log, resumes: the two files never disagree the unrecoverable way."""

from __future__ import annotations

import warnings

import pytest
from helpers import tiny_coma, tiny_env

import coma.learner as learner
from coma.learner import train
from ipp_toolkit.runs.progress_csv import read_progress_csv


def test_a_run_stopped_between_its_checkpoint_files_resumes(tmp_path, monkeypatch):
    """Ctrl-C (or SIGKILL) just after the first of the second checkpoint's two files was
    written, whichever it is, then ``--resume``: the run continues to the end."""
    out = tmp_path / "run"
    writes = []
    save_policy, write_progress = learner.save_policy, learner.write_progress

    def stop_after(write):
        def wrapped(path, *args, **kwargs):
            write(path, *args, **kwargs)
            if path.name in ("last.pt", "progress.csv"):
                writes.append(path.name)
                if len(writes) == 3:  # the first file of the second checkpoint is written
                    raise KeyboardInterrupt
        return wrapped

    monkeypatch.setattr(learner, "save_policy", stop_after(save_policy))
    monkeypatch.setattr(learner, "write_progress", stop_after(write_progress))
    with pytest.raises(KeyboardInterrupt):
        train(tiny_coma(), tiny_env(), out, progress=False, tensorboard=False)
    monkeypatch.undo()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = train(tiny_coma(), tiny_env(), out, resume=True, progress=False,
                       tensorboard=False)
    assert result.updates == 2
    rows = read_progress_csv(out / "progress.csv")
    assert [row["update"] for row in rows] == [1, 2]
