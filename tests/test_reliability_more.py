"""More hostile inputs refused before anything is written: unknown study families, a raster
file replaced between runs into one folder, a hand-edited result shard, an inconsistent
COMA update counter on resume, terrain lattices too fine or too coarse, thin rasters."""

from __future__ import annotations

import pytest

from reports.cli import study_main


@pytest.mark.parametrize("flag", ["--families", "--team-families"])
def test_an_unknown_study_family_is_refused_before_anything_flies(tmp_path, capsys, flag):
    out = tmp_path / "study"
    argv = ["generalisation", "--planners", "ig,random", "--trials", "1", "--agents", "2",
            "--comm", "0", "--families", "split", "--team-families", "split",
            "--out", str(out), "--no-progress"]
    argv[argv.index(flag) + 1] = "split,nope"
    assert study_main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert f"{flag}: unknown terrain kind 'nope'" in err and "blobs" in err
    assert not out.exists()
