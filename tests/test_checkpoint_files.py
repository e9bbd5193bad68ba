"""The one owner of checkpoint files (:mod:`ipp_toolkit.io`) and of a run's ``progress.csv``
(:mod:`ipp_toolkit.runs.progress_csv`), which the PPO, SB3, RLlib and COMA files all use."""

from __future__ import annotations

import json
import math

import pytest
import torch

from ipp_toolkit.io import (
    CheckpointError,
    built_from_checkpoint,
    load_checkpoint,
    load_weights,
    save_checkpoint,
)
from ipp_toolkit.runs.progress_csv import parse_cell, read_progress_csv


def test_a_checkpoint_and_its_record_are_written_together(tmp_path):
    path = save_checkpoint(str(tmp_path / "policy.pt"), {"w": torch.ones(2)}, "kind/a",
                           {"format": "kind/a", "steps": 3})
    assert path == tmp_path / "policy.pt"
    assert json.loads((tmp_path / "policy.json").read_text()) == {"format": "kind/a", "steps": 3}
    assert not (tmp_path / "other.json").exists()
    save_checkpoint(tmp_path / "other.pt", {"w": torch.ones(2)}, "kind/a")
    assert not (tmp_path / "other.json").exists()


def test_a_checkpoint_loads_under_any_of_its_kinds_and_else_names_the_first(tmp_path):
    path = save_checkpoint(tmp_path / "c.pt", {"w": torch.ones(2)}, "kind/training")
    assert load_checkpoint(path, "kind/policy", "kind/training")["format"] == "kind/training"
    with pytest.raises(CheckpointError, match="is not an 'kind/policy' file"):
        load_checkpoint(path, "kind/policy", "kind/other")


def test_weights_that_do_not_fit_name_the_file_and_the_problem(tmp_path):
    module = torch.nn.Linear(2, 2)
    load_weights(module, torch.nn.Linear(2, 2).state_dict(), tmp_path / "a.pt", "unused")
    with pytest.raises(CheckpointError, match=r"a\.pt': the actor does not fit \(Error"):
        load_weights(module, torch.nn.Linear(3, 2).state_dict(), tmp_path / "a.pt",
                     "the actor does not fit")

    def too_large():
        raise ValueError("over the limit")

    with pytest.raises(CheckpointError, match=r"b\.pt': over the limit"):
        built_from_checkpoint(tmp_path / "b.pt", too_large)


def test_progress_rows_are_parsed_and_a_damaged_file_is_refused_when_strict(tmp_path):
    assert [parse_cell(text) for text in ("", "3", "3.0", "1e3", "nan")][:4] == \
        [None, 3, 3.0, 1000.0]
    assert math.isnan(parse_cell("nan"))
    path = tmp_path / "progress.csv"
    path.write_text("update,loss\n1,0.5\n2,\n")
    assert read_progress_csv(path, ["update", "loss"]) == [{"update": 1, "loss": 0.5},
                                                           {"update": 2, "loss": None}]
    with pytest.raises(ValueError, match="header is not update,value"):
        read_progress_csv(path, ["update", "value"])
    path.write_text("update,loss\n1,0.5\n2\n3,0.1,9\n")
    with pytest.raises(ValueError, match="line 3 has the wrong number of cells"):
        read_progress_csv(path)
    assert read_progress_csv(path, strict=False) == [
        {"update": 1, "loss": 0.5}, {"update": 2, "loss": None}, {"update": 3, "loss": 0.1}]


def test_equal_contents_save_the_same_bytes_whatever_the_string_objects(tmp_path):
    # A value equal to a key is one string object in one process and two in another (a
    # config sent to a worker); the saved bytes must not depend on it.
    from ipp_toolkit.io import save_torch

    key = "td_lambda"
    shared = {key: 0.8, "targets": key}
    separate = {"td_lambda": 0.8, "targets": "".join(["td_", "lambda"])}
    save_torch(tmp_path / "a.pt", shared, "test/kind")
    save_torch(tmp_path / "b.pt", separate, "test/kind")
    assert (tmp_path / "a.pt").read_bytes() == (tmp_path / "b.pt").read_bytes()
