"""The downward camera: footprint geometry per waypoint and simulated noisy readings.

A reading is simulated per map cell: correct with probability p(h), else flipped.
It is stored as the likelihood of "interesting" (p(h) if it reads 1, 1 - p(h) if it reads 0)
and enters the maps as the log-odds increment logit(z) - logit(prior).
"""

from __future__ import annotations

import math

import numpy as np

from ..config.schema import SensorConfig, WorldConfig
from ..probability import binary_entropy, logit

Rect = tuple[int, int, int, int]
"""A half-open map-cell rectangle (row0, row1, col0, col1): a footprint, or a region of the
maps (:mod:`ipp_toolkit.belief` takes its regions in this form)."""

__all__ = ["Camera", "Rect", "footprint_side"]


def footprint_side(altitude: float, fov_deg: float = 60.0) -> float:
    """Side of the square ground footprint in metres: 2 h tan(fov / 2)."""
    return 2.0 * altitude * math.tan(math.radians(fov_deg) / 2.0)


class Camera:
    """Footprints and readings for every waypoint of the planning grid.

    Attributes:
        rects: (Z, G, G, 4) int64, the half-open map-cell rectangle (row0, row1, col0, col1)
            seen from waypoint [iz, iy, ix]; a map cell belongs to a footprint iff its centre
            lies inside the footprint square, clipped at the area border.
        accuracy: (Z,) probability that a cell reading is correct, per altitude index.
        delta_logodds: (Z, 2) float32 log-odds increment of a reading 0 / 1 per altitude.
        reading_entropy: (Z,) entropy in bits of one stored reading z (p(h) or 1 - p(h)),
            the same for both values of the reading.
        largest_footprint_cells: map cells of the largest footprint (the highest altitude,
            away from the border).
    """

    def __init__(self, world: WorldConfig, sensor: SensorConfig):
        if len(sensor.accuracy) != len(world.altitudes):
            raise ValueError(f"sensor.accuracy {sensor.accuracy} needs one value per altitude "
                             f"{world.altitudes}")
        self.world = world
        self.altitudes = np.asarray(world.altitudes, dtype=np.float64)
        self.accuracy = np.asarray(sensor.accuracy, dtype=np.float64)
        self.half_sides = np.array([footprint_side(h, sensor.fov_deg) / 2 for h in world.altitudes])
        n, r = world.map_cells, world.resolution
        waypoints = np.arange(world.grid_points) * world.grid_spacing
        # A small tolerance keeps cells whose centre lies exactly on the edge inside.
        tol = 1e-9
        lo = np.ceil((waypoints[None, :] - self.half_sides[:, None]) / r - 0.5 - tol)
        hi = np.floor((waypoints[None, :] + self.half_sides[:, None]) / r - 0.5 + tol) + 1
        lo = np.clip(lo, 0, n).astype(np.int64)  # (Z, G)
        hi = np.clip(hi, 0, n).astype(np.int64)
        z, g = len(world.altitudes), world.grid_points
        rects = np.empty((z, g, g, 4), dtype=np.int64)
        rects[..., 0] = lo[:, :, None]  # rows follow y (axis 1 of [iz, iy, ix])
        rects[..., 1] = hi[:, :, None]
        rects[..., 2] = lo[:, None, :]
        rects[..., 3] = hi[:, None, :]
        self.rects = rects
        self.largest_footprint_cells = max(int(((rects[..., 1] - rects[..., 0])
                                                * (rects[..., 3] - rects[..., 2])).max()), 1)
        prior_logodds = float(logit(world.prior))
        self.delta_logodds = np.stack([logit(1 - self.accuracy), logit(self.accuracy)],
                                      axis=1).astype(np.float32) - np.float32(prior_logodds)
        self.reading_entropy = binary_entropy(self.accuracy)

    def altitude_index(self, altitude: float) -> int:
        """Index of a flight level; an unknown altitude is an error, never a perfect sensor."""
        matches = np.flatnonzero(np.isclose(self.altitudes, altitude))
        if len(matches) == 0:
            raise ValueError(f"unknown altitude {altitude!r} m; the sensor knows "
                             f"{tuple(self.altitudes.tolist())}")
        return int(matches[0])

    def footprint(self, position: np.ndarray) -> Rect:
        """Footprint rectangle of a waypoint given as indices (ix, iy, iz)."""
        ix, iy, iz = (int(v) for v in position)
        r0, r1, c0, c1 = self.rects[iz, iy, ix]
        return int(r0), int(r1), int(c0), int(c1)

    def read(self, ground_truth: np.ndarray, rect: Rect, altitude_index: int,
             rng: np.random.Generator) -> np.ndarray:
        """Simulate one reading of the cells inside ``rect``.

        Args:
            ground_truth: (H, W) bool map.
            rect: footprint rectangle.
            altitude_index: flight level of the camera.
            rng: the mission's sensor-noise stream.

        Returns:
            (rows, cols) bool reading, each cell flipped independently with 1 - p(h).
        """
        r0, r1, c0, c1 = rect
        truth = ground_truth[r0:r1, c0:c1]
        flips = rng.random(truth.shape, dtype=np.float32) >= np.float32(
            self.accuracy[altitude_index])
        return truth ^ flips

    def likelihood(self, reading: np.ndarray, altitude_index: int) -> np.ndarray:
        """Stored measurement z: p(h) where the reading is 1, 1 - p(h) where it is 0."""
        acc = self.accuracy[altitude_index]
        return np.where(reading, acc, 1.0 - acc)

    def reading_logodds(self, reading: np.ndarray, altitude_index: int) -> np.ndarray:
        """(rows, cols) float32 log-odds increment logit(z) - logit(prior) of a reading."""
        d0, d1 = self.delta_logodds[altitude_index]
        return np.where(reading, d1, d0)
