"""Inputs that used to be accepted and then ignored, truncated or misread: each refused with
a message naming the value (exit 2 from a command, nothing written)."""

from __future__ import annotations

import numpy as np
import pytest

from ipp_toolkit import EnvConfig, IPPEnv
from ipp_toolkit.config.files import config_from_dict
from reports import compare_planners as compare
from reports.cli import compare_main, study_main


def test_compare_refuses_what_it_would_ignore(tmp_path, capsys):
    raster = tmp_path / "flat.npy"
    np.save(raster, np.full((10, 10), 3.0))
    folder = tmp_path / "policy-folder"
    folder.mkdir()
    cases = [
        (["--terrain", "split", "--threshold-quantile", "0.5"], "does not use it"),
        (["--terrain", "blobs", "--threshold-quantile", "0.5"], "does not use it"),
        (["--terrain", str(raster), "--threshold", "1"], "every map cell reaches"),
        (["--planners", f"coma={folder}"], "is a folder, not a checkpoint file"),
    ]
    for flags, message in cases:
        out = tmp_path / "out"
        argv = ["--planners", "random", "--no-progress", "--resolution", "1", "--workers", "1",
                *flags, "--out", str(out)]
        assert compare_main(argv) == 2, flags
        err = capsys.readouterr().err.strip().splitlines()[-1]
        assert message in err, (flags, err)
        assert not out.exists()


@pytest.mark.parametrize("agents, message", [
    ("", "has an empty value"),
    ("2,,4", "has an empty value"),
    ("2,2", "gives 2 more than once"),
])
def test_study_lists_with_no_or_repeated_values_are_refused(tmp_path, capsys, agents,
                                                             message):
    out = tmp_path / "study"
    assert study_main(["robustness", "--agents", agents, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_study_refuses_an_empty_out(capsys):
    assert study_main(["robustness", "--out", ""]) == 2
    assert "--out must name a folder" in capsys.readouterr().err


@pytest.mark.parametrize("call, message", [
    (lambda: compare(planners=["random"], trials=1, seed=1.5, progress=False),
     "seed must be an integer"),
    (lambda: config_from_dict({"reward": {"weight_interesting": 0.0}}),
     "both 0: the reward would count no entropy"),
    (lambda: _truth_env(np.full((50, 50), "no", dtype=object)),
     "ground_truth must hold booleans"),
    (lambda: _truth_env(np.full((50, 50), 0.3)), "ground_truth must hold booleans"),
])
def test_python_inputs_that_were_truncated_or_misread(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def _truth_env(truth: np.ndarray) -> None:
    config = EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 2})
    IPPEnv(config, ground_truth=truth).reset(seed=0)
