"""The fixed start positions of the paper's teams and how they snap to a world's waypoints.

Owned here, apart from the config classes (:mod:`ipp_toolkit.config.schema` imports and
re-exports these names, with ``start_for_team_size``): a
:class:`~ipp_toolkit.config.schema.TeamConfig` with ``start: fixed`` uses them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .schema import WorldConfig

__all__ = ["START_POSITIONS", "fixed_start_waypoints", "fixed_starts_fit"]

START_POSITIONS: dict[int, tuple[tuple[float, float], ...]] = {
    2: ((10, 10), (40, 40)),
    4: ((10, 10), (40, 10), (40, 40), (10, 40)),
    8: ((10, 10), (40, 10), (40, 40), (10, 40), (25, 10), (40, 25), (25, 40), (10, 25)),
}


def fixed_start_waypoints(world: WorldConfig, n_agents: int) -> np.ndarray | None:
    """(n_agents, 2) int waypoint indices (ix, iy) of the fixed starts in ``world``.

    The starts of :data:`START_POSITIONS` are metres of the paper's 50 m field; each
    coordinate snaps to the nearest waypoint of ``world`` (halves round up) inside its area,
    so they are unchanged where they are waypoints (the paper's worlds), and in the paper's
    real-world field (40 m, waypoints every 4 m) (10, 10) becomes (12, 12) and 40 stays 40.
    None when the team size has no fixed starts or two starts snap to the same waypoint.
    """
    starts = START_POSITIONS.get(n_agents)
    if starts is None:
        return None
    metres = np.asarray(starts, dtype=np.float64)
    # A grid too fine for int64 indices (refused later by the memory check) gets no fixed
    # starts: its snapped indices are capped where a cast cannot overflow.
    top = min(world.grid_points - 1, 2 ** 62)
    waypoints = np.clip(np.floor(metres / world.grid_spacing + 0.5), 0, top).astype(np.int64)
    if waypoints.max() >= 2 ** 62:
        return None
    if len({tuple(w) for w in waypoints.tolist()}) < n_agents:
        return None
    return waypoints


def fixed_starts_fit(world: WorldConfig, n_agents: int) -> bool:
    """Whether ``n_agents`` has fixed starts in ``world`` (:func:`fixed_start_waypoints`)."""
    return fixed_start_waypoints(world, n_agents) is not None
