import math

import numpy as np
import pytest

from ipp_toolkit.config.schema import SensorConfig, WorldConfig
from ipp_toolkit.world.sensor import Camera, footprint_side


def test_footprint_side_per_altitude():
    assert [round(footprint_side(h), 2) for h in (5, 10, 15)] == [5.77, 11.55, 17.32]


@pytest.mark.parametrize("resolution", [0.1, 0.5])
def test_footprint_cells_per_altitude(resolution):
    camera = Camera(WorldConfig(resolution=resolution), SensorConfig())
    for iz, altitude in enumerate((5, 10, 15)):
        r0, r1, c0, c1 = camera.footprint((5, 5, iz))  # centre of the area (25, 25)
        side = footprint_side(altitude)
        # Cells whose centre lies inside the square: side / r, rounded either way.
        assert abs((r1 - r0) - side / resolution) <= 1
        assert r1 - r0 == c1 - c0
        centre = (r0 + r1) / 2 * resolution
        assert centre == pytest.approx(25.0, abs=resolution)


def test_footprint_rule_cell_centres_inside():
    world = WorldConfig(resolution=0.1)
    camera = Camera(world, SensorConfig())
    r0, r1, c0, c1 = camera.footprint((2, 3, 0))  # (10, 15) at 5 m
    half = footprint_side(5) / 2
    centres = (np.arange(500) + 0.5) * 0.1
    inside_x = np.flatnonzero(np.abs(centres - 10) <= half)
    inside_y = np.flatnonzero(np.abs(centres - 15) <= half)
    assert (c0, c1) == (inside_x[0], inside_x[-1] + 1)
    assert (r0, r1) == (inside_y[0], inside_y[-1] + 1)


def test_footprint_clipped_at_border():
    camera = Camera(WorldConfig(resolution=0.1), SensorConfig())
    r0, r1, c0, c1 = camera.footprint((0, 10, 2))  # (0, 50) at 15 m: a quarter
    assert (r1, c0) == (500, 0)
    assert r1 - r0 == pytest.approx(footprint_side(15) / 2 / 0.1, abs=1)
    assert c1 - c0 == pytest.approx(footprint_side(15) / 2 / 0.1, abs=1)


@pytest.mark.parametrize("iz,accuracy", [(0, 0.99), (1, 0.735), (2, 0.625)])
def test_flip_rates(iz, accuracy):
    camera = Camera(WorldConfig(resolution=0.1), SensorConfig())
    truth = np.zeros((500, 500), dtype=bool)
    truth[:, 250:] = True
    rng = np.random.default_rng(7)
    rect = camera.footprint((5, 5, iz))
    flips = []
    for _ in range(20):
        reading = camera.read(truth, rect, iz, rng)
        r0, r1, c0, c1 = rect
        flips.append(np.mean(reading != truth[r0:r1, c0:c1]))
    n = 20 * (rect[1] - rect[0]) * (rect[3] - rect[2])
    tolerance = 5 * math.sqrt(accuracy * (1 - accuracy) / n) + 1e-4
    assert np.mean(flips) == pytest.approx(1 - accuracy, abs=tolerance)


def test_likelihood_values():
    camera = Camera(WorldConfig(), SensorConfig())
    reading = np.array([[True, False]])
    np.testing.assert_allclose(camera.likelihood(reading, 1), [[0.735, 0.265]])
    d = camera.reading_logodds(reading, 0)
    assert d[0, 0] == pytest.approx(math.log(99), rel=1e-5) and d[0, 1] == pytest.approx(
        -math.log(99), rel=1e-5)


def test_unknown_altitude_is_an_error():
    camera = Camera(WorldConfig(), SensorConfig())
    assert camera.altitude_index(10.0) == 1
    with pytest.raises(ValueError, match="unknown altitude 20"):
        camera.altitude_index(20.0)
