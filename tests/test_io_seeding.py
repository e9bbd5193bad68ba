"""Atomic files (ipp_toolkit.io) and the mission's random streams (ipp_toolkit.world.seeding)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ipp_toolkit.io import atomic_write, write_json
from ipp_toolkit.world.seeding import mission_streams


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "sub" / "results.json"
    write_json(path, {"rows": 1})
    assert json.loads(path.read_text()) == {"rows": 1}

    def crash(handle) -> None:
        handle.write(b"half a fi")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        atomic_write(path, crash)
    assert json.loads(path.read_text()) == {"rows": 1}
    assert sorted(p.name for p in path.parent.iterdir()) == ["results.json"]


def test_streams_are_reproducible_and_independent():
    first, again = mission_streams("test", 3, 7), mission_streams("test", 3, 7)
    draw = lambda streams, name: streams.generator(name).random(4)  # noqa: E731
    for name in ("terrain", "starts", "drops"):
        assert np.array_equal(draw(first, name), draw(again, name))
    assert np.array_equal(first.sensor(2, 1).random(4), again.sensor(2, 1).random(4))
    samples = {
        "terrain": draw(first, "terrain"), "starts": draw(first, "starts"),
        "drops": draw(first, "drops"), "sensor(0,0)": first.sensor(0, 0).random(4),
        "sensor(0,1)": first.sensor(0, 1).random(4), "sensor(1,0)": first.sensor(1, 0).random(4),
        "mission 8": draw(mission_streams("test", 3, 8), "terrain"),
        "seed 4": draw(mission_streams("test", 4, 7), "terrain"),
        "validation": draw(mission_streams("validation", 3, 7), "terrain"),
    }
    values = list(samples.values())
    for i in range(len(values)):
        for j in range(i + 1, len(values)):
            assert not np.array_equal(values[i], values[j]), (list(samples)[i], list(samples)[j])


@pytest.mark.parametrize("seed, mission", [(-1, 0), (0, -2), (1.5, 0), (True, 0)])
def test_bad_seeds_are_named(seed, mission):
    with pytest.raises(ValueError, match="must be a non-negative integer"):
        mission_streams("test", seed, mission)
