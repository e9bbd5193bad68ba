"""The non-adaptive coverage baseline: a lawnmower over the planning grid, split among the UAVs."""

from __future__ import annotations

import itertools

import numpy as np

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import AgentView, Planner
from ipp_toolkit.sim.team import ACTION_NAMES

__all__ = ["CoveragePlanner", "PaperCoveragePlanner", "boustrophedon", "paper_lawnmower_paths"]

# Beyond this team size the segment assignment is greedy instead of exhaustive (8! = 40320
# permutations is still cheap once per mission; 9! and up is not worth it for a baseline).
_EXHAUSTIVE_MAX_AGENTS = 8

# Action indices by name, so the move rule does not depend on the order of ACTION_NAMES.
_UP, _NORTH, _EAST, _SOUTH, _WEST, _DOWN = (
    ACTION_NAMES.index(name) for name in ("up", "north", "east", "south", "west", "down"))


def boustrophedon(grid_points: int) -> np.ndarray:
    """(G*G, 2) int waypoints (ix, iy) of one lawnmower path over a G x G grid.

    Row iy = 0 runs west to east, row 1 east to west, and so on, so consecutive waypoints are
    always one grid step apart.
    """
    g = grid_points
    iy = np.repeat(np.arange(g), g)
    ix = np.tile(np.arange(g), g)
    odd = iy % 2 == 1
    ix[odd] = g - 1 - ix[odd]
    return np.stack([ix, iy], axis=1).astype(np.int64)


class CoveragePlanner(Planner):
    """Lawnmower coverage at a fixed altitude; ignores every measurement (non-adaptive).

    The plan, built once per mission at the first :meth:`act` (the start positions are only
    known from the first views):

    1. one boustrophedon path over the whole G x G planning grid (rows along x, alternating
       direction, 5 m = one step between waypoints) is cut into N consecutive segments of
       equal length (``np.array_split``: lengths differ by at most one);
    2. each segment may be flown from either end; agent k's cost for a segment is the 2-D
       Manhattan distance from its start to the nearer end. Segments are assigned to agents
       by minimising the total cost (exhaustively for N <= 8, greedily in agent order above;
       ties go to the first permutation), and each agent enters at its nearer end (the first
       end on a tie);
    3. agent k's lane is its segment in that direction at flight level ``altitude_index``.

    Flying it, each agent targets the first lane waypoint it has not reached yet (entering
    the lane is the first one, so the transit is the same rule): the planned move is the
    first action, in the order altitude, x, y, that reduces the 3-D Manhattan distance to the
    target — the UAV descends or climbs to the survey altitude first, then flies. When that
    move is masked (a border, or another UAV holds the cell) it takes the next valid action
    that still reduces the distance, else the first valid action in index order. A lane
    flown to its end is flown back in reverse. A UAV held back by the same-target rule simply
    tries again at the next step.

    ``altitude_index`` default 0 (5 m): with only B = 15 steps the accurate low camera
    (p = 0.99) beats the wide, noisy high ones although it covers the least. Measured on 20
    validation missions (``evaluate(..., missions=20, seed=0, namespace="validation")``, the
    default split terrain, 4 agents, D = 25 m, r_M = 0.1 m, B = 15), mean final entropy over
    interesting cells (sd) / mean final F1 of the global map::

        altitude_index 0 (5 m):   entropy 0.548 (sd 0.030)  F1 0.702
        altitude_index 1 (10 m):  entropy 0.687 (sd 0.016)  F1 0.701
        altitude_index 2 (15 m):  entropy 0.796 (sd 0.007)  F1 0.670

    Attributes:
        lanes: after the first act(), one (L_k, 3) int array (ix, iy, iz) per agent, its lane.
    """

    name = "coverage"
    needs_observations = False
    needs_local_maps = False

    def __init__(self, altitude_index: int = 0) -> None:
        if not isinstance(altitude_index, int | np.integer) or altitude_index < 0:
            raise ValueError(f"altitude_index must be an integer >= 0, got {altitude_index!r}")
        self.altitude_index = int(altitude_index)
        self._grid_points = 0
        self._n_altitudes = 0
        self.lanes: list[np.ndarray] = []
        self._next: np.ndarray = np.zeros(0, dtype=np.int64)

    def reset(self, config: EnvConfig, seed: int) -> None:
        """Forget the last mission's plan; the new one is built at the first act()."""
        n_altitudes = len(config.world.altitudes)
        if self.altitude_index >= n_altitudes:
            raise ValueError(f"altitude_index {self.altitude_index} is out of range: the world "
                             f"has {n_altitudes} altitudes {config.world.altitudes}")
        self._grid_points = config.world.grid_points
        self._n_altitudes = n_altitudes
        self.lanes = []
        self._next = np.zeros(0, dtype=np.int64)

    def _plan(self, starts: np.ndarray) -> None:
        """Build one lane per agent from the (N, 3) start positions."""
        if self._grid_points == 0:
            raise RuntimeError("call reset(config, seed) before act()")
        n = len(starts)
        path = boustrophedon(self._grid_points)
        segments = np.array_split(path, n)
        firsts = np.stack([s[0] for s in segments])  # (N, 2)
        lasts = np.stack([s[-1] for s in segments])
        to_first = np.abs(starts[:, None, :2] - firsts[None]).sum(axis=-1)  # (agent, segment)
        to_last = np.abs(starts[:, None, :2] - lasts[None]).sum(axis=-1)
        cost = np.minimum(to_first, to_last)
        assignment = _assign(cost)
        self.lanes = []
        for k in range(n):
            s = assignment[k]
            lane = segments[s] if to_first[k, s] <= to_last[k, s] else segments[s][::-1]
            heights = np.full((len(lane), 1), self.altitude_index, dtype=np.int64)
            self.lanes.append(np.concatenate([lane, heights], axis=1))
        self._next = np.zeros(n, dtype=np.int64)

    def act(self, views: list[AgentView]) -> np.ndarray:
        """(N,) int64 actions following each agent's lane, always valid under its mask."""
        positions = np.stack([view.position for view in views]).astype(np.int64)
        if len(self.lanes) != len(views):
            self._plan(positions)
        actions = np.empty(len(views), dtype=np.int64)
        for k, view in enumerate(views):
            target = self._target(k, positions[k])
            actions[k] = _move_towards(positions[k], target, view.mask)
        return actions

    def _target(self, k: int, position: np.ndarray) -> np.ndarray:
        """Agent k's next lane waypoint, advancing past the ones it has reached."""
        lane = self.lanes[k]
        while self._next[k] < len(lane) and np.array_equal(lane[self._next[k]], position):
            self._next[k] += 1
        if self._next[k] == len(lane):
            # Lane done (only with budgets longer than a segment): fly it back.
            self.lanes[k] = lane = lane[::-1].copy()
            self._next[k] = 1 if len(lane) > 1 else 0
        return lane[self._next[k]]


def paper_lawnmower_paths() -> np.ndarray:
    """(4, 15, 2) float (x, y) waypoints in metres of the paper authors' four lawnmower paths.

    Their ``lawn_mower.py`` hard-codes them, 5 m apart, all inside x, y in [10, 40] m (so the
    10 m border strips are never seen):

    * path 1: y = 10 m from x = 10 to 40 m, one step north to (40, 15), y = 20 m back to x = 10;
    * path 2: path 1 shifted 20 m north (y = 30 m, (40, 35), y = 40 m);
    * path 3: path 1 mirrored on the diagonal (x = 10 m from y = 10 to 40 m, (15, 40),
      x = 20 m back to y = 10);
    * path 4: path 3 shifted 20 m east (x = 30 m, (35, 40), x = 40 m).

    Consecutive waypoints are one 5 m step apart.
    """
    sweep = np.arange(10.0, 45.0, 5.0)  # (7,) 10, 15, ..., 40
    path1 = np.concatenate([np.stack([sweep, np.full(7, 10.0)], axis=1), [[40.0, 15.0]],
                            np.stack([sweep[::-1], np.full(7, 20.0)], axis=1)])  # (15, 2)
    path3 = path1[:, ::-1]
    return np.stack([path1, path1 + [0.0, 20.0], path3, path3 + [20.0, 0.0]])


class PaperCoveragePlanner(CoveragePlanner):
    """The paper authors' coverage baseline: their four fixed lawnmower paths at 5 m.

    The team flies paths ``k mod 4 + 1`` (k = 0..N-1) of :func:`paper_lawnmower_paths`, as a
    set (step 1 says which UAV flies which): paths 1..N for N <= 4, and beyond that the paths
    repeat, as in the authors' code, whose paths 5-8 duplicate paths 1-4 (with 8 UAVs every
    path is flown twice). The
    authors place each UAV on its path's first waypoint and take 15 readings along it. Here
    the UAVs start where every planner starts (SPEC §8: 15 m, e.g. the corners (10, 10),
    (40, 10), (40, 40), (10, 40) of the paths' square for 4 UAVs), so the plan, built at the
    first :meth:`act`, is:

    1. each UAV's entry is the waypoint of a path nearest its start (2-D Manhattan; the
       first in path order on a tie), and the paths are assigned to UAVs by minimising the
       summed distance to the entries (:func:`_assign`; exhaustive for N <= 8). Flying path k
       with UAV k from its first waypoint would spend up to 10 of the 15 steps in transit;
       with the fixed starts of 2 and 4 UAVs every UAV starts on a waypoint of its path;
    2. each path is flown as a loop (its two ends are 10 m apart, so the loop closes through
       one extra waypoint), from the entry on, every loop counter-clockwise: the paths share
       stretches of waypoints (path 4's x = 40 m leg holds the short legs of paths 1 and 2;
       the closed loops of paths 1 and 3 share legs around (10, 10) m), and one direction
       of travel for all makes UAVs on a shared stretch follow each other instead of meeting
       head-on, which the one-UAV-per-cell masks would turn into a deadlock (two copies of a
       path, N > 4, simply follow each other too);
    3. flying is :class:`CoveragePlanner`'s rule: descend to the survey altitude first, then
       the next lane waypoint, a valid action when the preferred one is masked; the lane is
       cut at the budget (16 readings: the start one at 15 m, 10 m, then 14 on the path when
       the UAV starts on it).

    Non-adaptive; ignores the seed.

    Args:
        altitude_index: survey flight level, default 0 (5 m, the authors' altitude).
    """

    name = "coverage_paper"

    def reset(self, config: EnvConfig, seed: int) -> None:
        """Check that the paths lie on this world's planning grid; forget the last plan."""
        super().reset(config, seed)
        cells = paper_lawnmower_paths() / config.world.grid_spacing
        indices = np.rint(cells).astype(np.int64)
        if not np.allclose(cells, indices) or indices.max() >= self._grid_points:
            raise ValueError("coverage_paper needs the authors' paths (x, y in [10, 40] m, "
                             f"5 m apart) on the planning grid; the world has grid_spacing "
                             f"{config.world.grid_spacing} m and area_size "
                             f"{config.world.area_size} m")
        self._paths = indices  # (4, 15, 2) int (ix, iy)

    def _plan(self, starts: np.ndarray) -> None:
        """Build one lane per agent from the (N, 3) start positions."""
        if self._grid_points == 0:
            raise RuntimeError("call reset(config, seed) before act()")
        n = len(starts)
        paths = self._paths[np.arange(n) % len(self._paths)]  # (N, L, 2)
        length = paths.shape[1]
        # dist[agent, path, waypoint]: 2-D Manhattan steps from the agent's start.
        dist = np.abs(starts[:, None, None, :2] - paths[None]).sum(axis=-1)
        assignment = _assign(dist.min(axis=-1))
        steps = np.arange(length)
        self.lanes = []
        for k in range(n):
            path = paths[assignment[k]]
            entry = int(np.argmin(dist[k, assignment[k]]))  # first nearest waypoint
            # Shoelace: twice the signed area of the closed loop, > 0 when counter-clockwise.
            x, y = path[:, 0], path[:, 1]
            counter_clockwise = np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0
            order = (entry + steps) % length if counter_clockwise else (entry - steps) % length
            heights = np.full((length, 1), self.altitude_index, dtype=np.int64)
            self.lanes.append(np.concatenate([path[order], heights], axis=1))
        self._next = np.zeros(n, dtype=np.int64)


def _assign(cost: np.ndarray) -> np.ndarray:
    """(N,) segment of each agent minimising the summed (N, N) ``cost[agent, segment]``."""
    n = len(cost)
    if n <= _EXHAUSTIVE_MAX_AGENTS:
        perms = np.array(list(itertools.permutations(range(n))), dtype=np.int64)  # (n!, n)
        totals = cost[np.arange(n)[None, :], perms].sum(axis=1)
        # argmin takes the first minimum: permutations come in lexicographic order.
        return perms[int(np.argmin(totals))]
    free = np.ones(n, dtype=bool)
    assignment = np.empty(n, dtype=np.int64)
    for k in range(n):
        s = int(np.argmin(np.where(free, cost[k], np.iinfo(np.int64).max)))
        assignment[k] = s
        free[s] = False
    return assignment


def _move_towards(position: np.ndarray, target: np.ndarray, mask: np.ndarray) -> int:
    """A valid action towards ``target``: preferred reducing move, other reducing, any valid.

    Args:
        position: (3,) int (ix, iy, iz).
        target: (3,) int (ix, iy, iz).
        mask: (6,) valid actions.
    """
    dx, dy, dz = (int(v) for v in target - position)
    # Reducing moves in order altitude, x, y: a UAV reaches the survey altitude first, so it
    # measures its transit at that altitude too.
    preferred = []
    if dz:
        preferred.append(_UP if dz > 0 else _DOWN)
    if dx:
        preferred.append(_EAST if dx > 0 else _WEST)
    if dy:
        preferred.append(_NORTH if dy > 0 else _SOUTH)
    for action in preferred:
        if mask[action]:
            return action
    valid = np.flatnonzero(mask)
    if len(valid) == 0:
        raise ValueError(f"no valid action at position {position.tolist()}")
    return int(valid[0])

