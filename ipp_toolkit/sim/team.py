"""Actions, action masks, the same-target rule and the communication graph.

Positions are integer waypoint indices ``(ix, iy, iz)``: x and y index the planning grid,
iz the flight level. Masks are the one owner of "which action is valid" in the toolkit.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = [
    "ACTION_NAMES",
    "ACTION_DELTAS",
    "N_ACTIONS",
    "action_masks",
    "unclaimed_options",
    "choose_in_order",
    "resolve_moves",
    "communication_matrix",
    "positions_in_metres",
]

ACTION_NAMES = ("up", "north", "east", "south", "west", "down")
"""Action indices 0..5: north is +y, east is +x."""

ACTION_DELTAS = np.array(
    [[0, 0, 1], [0, 1, 0], [1, 0, 0], [0, -1, 0], [-1, 0, 0], [0, 0, -1]], dtype=np.int64
)
"""(6, 3) change of (ix, iy, iz) per action."""

N_ACTIONS = len(ACTION_NAMES)

_DELTAS = [tuple(delta) for delta in ACTION_DELTAS.tolist()]


def _deltas_of(actions: np.ndarray) -> list[tuple[int, int, int]]:
    return [_DELTAS[a] for a in actions.tolist()]


def action_masks(positions: np.ndarray, grid_points: int, n_altitudes: int,
                 active: np.ndarray | None = None) -> np.ndarray:
    """Valid actions of every agent.

    An action is invalid if it leaves the area or the altitude range, or moves into a 2-D
    cell currently held by another active agent (up and down keep the agent's own cell).

    Args:
        positions: (N, 3) int waypoint indices (ix, iy, iz).
        grid_points: waypoints per side G.
        n_altitudes: number of flight levels Z.
        active: (N,) bool, agents still flying (all when omitted); a failed UAV holds no
            cell.

    Returns:
        (N, 6) int8 mask, 1 = valid.
    """
    positions = np.asarray(positions, dtype=np.int64)
    # Plain Python over the few agents: a dozen small NumPy calls cost several times more
    # (the simulator asks for the masks at every step).
    cells = positions.tolist()
    flying = [True] * len(cells) if active is None else np.asarray(active, dtype=bool).tolist()
    owner = {(x, y): k for k, (x, y, _) in enumerate(cells) if flying[k]}  # 2-D cell -> agent
    masks = [
        [0 <= x + dx < grid_points and 0 <= y + dy < grid_points and 0 <= z + dz < n_altitudes
         and owner.get((x + dx, y + dy), k) == k  # free, or its own cell (up and down)
         for dx, dy, dz in _DELTAS]
        for k, (x, y, z) in enumerate(cells)]
    return np.array(masks, dtype=np.int8).reshape(len(cells), N_ACTIONS)


def unclaimed_options(position: np.ndarray, mask: np.ndarray,
                      claimed_targets: np.ndarray) -> np.ndarray:
    """The valid options of an agent that avoid the targets teammates already chose.

    Agents that decide in index order and hear lower-index teammates' choices (the ``ig``
    family, the ``coma`` planner) avoid a 2-D cell such a teammate will move to: the
    same-target rule (:func:`resolve_moves`) would hold one of them back.

    Args:
        position: (3,) int the agent's waypoint (x, y, z).
        mask: (6,) valid actions.
        claimed_targets: (K, 3) int next waypoints chosen by heard, already decided teammates.

    Returns:
        (6,) bool: valid and unclaimed; all valid options when every valid one is claimed.
    """
    mask = np.asarray(mask).astype(bool)
    candidates = np.asarray(position)[None, :].astype(np.int64) + ACTION_DELTAS  # (6, 3)
    claimed = (candidates[:, None, :2] == np.asarray(claimed_targets)[None, :, :2]
               ).all(-1).any(-1)
    allowed = mask & ~claimed
    return allowed if allowed.any() else mask


def choose_in_order(scores: np.ndarray, positions: np.ndarray, masks: np.ndarray,
                    heard: np.ndarray,
                    rescore: Callable[[int, np.ndarray], np.ndarray] | None = None
                    ) -> np.ndarray:
    """Each agent's best option, chosen in agent order under :func:`unclaimed_options`.

    Args:
        scores: (N, 6) values of the options (e.g. a policy's logits); higher is better.
        positions: (N, 3) int waypoints.
        masks: (N, 6) valid actions.
        heard: (N, N) bool, ``heard[k, i]``: agent k hears agent i.
        rescore: ``rescore(k, targets)`` -> agent k's (6,) scores given the (K, 3) next
            waypoints its heard, already decided teammates chose (K may be 0); used instead
            of ``scores[k]`` when given (``ig``'s discount of their footprints,
            :class:`ipp_toolkit.planning.discount.TeammateDiscount`).

    Returns:
        (N,) int64 actions, each valid; ties go to the lowest action index.
    """
    n = len(scores)
    masks = np.asarray(masks).astype(bool)
    actions = np.empty(n, dtype=np.int64)
    targets = np.empty((n, 3), dtype=np.int64)
    for k in range(n):
        mates = np.flatnonzero(heard[k, :k])  # heard and already decided
        allowed = unclaimed_options(positions[k], masks[k], targets[mates])
        own = scores[k] if rescore is None else rescore(k, targets[mates])
        actions[k] = int(np.argmax(np.where(allowed, own, -np.inf)))
        targets[k] = positions[k] + ACTION_DELTAS[actions[k]]
    return actions


def resolve_moves(positions: np.ndarray, actions: np.ndarray,
                  moving: np.ndarray | None = None,
                  active: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Apply a joint action under the same-target rule.

    When several agents choose the same 2-D target cell, the lowest index moves and the
    others hold their position (they still measure). Masks already forbid entering a cell
    held by another agent, so afterwards no two agents share a 2-D cell.

    Args:
        positions: (N, 3) int current waypoint indices.
        actions: (N,) int action indices, assumed valid.
        moving: (N,) bool, agents that try to move (False = hold, e.g. an invalid action
            under ``invalid_action="hold"``); all True when omitted.
        active: (N,) bool, agents still flying (all when omitted); the others should not be
            ``moving`` and take part in no same-target contest.

    Returns:
        new positions (N, 3) int and ``blocked`` (N,) bool: held back by the same-target rule.
    """
    positions = np.asarray(positions, dtype=np.int64)
    actions = np.asarray(actions, dtype=np.int64)
    n = len(positions)
    moving = [True] * n if moving is None else np.asarray(moving, dtype=bool).tolist()
    flying = [True] * n if active is None else np.asarray(active, dtype=bool).tolist()
    cells = positions.tolist()
    steps = _deltas_of(actions)
    targets = [[x + dx, y + dy, z + dz] if moving[k] else [x, y, z]
               for k, ((x, y, z), (dx, dy, dz)) in enumerate(zip(cells, steps, strict=True))]
    claimed: set[tuple[int, int]] = set()
    blocked = [False] * n
    for k, (x, y, _) in enumerate(targets):  # in index order: the lowest index wins a cell
        if not flying[k]:  # a failed UAV holds no cell: it never wins nor blocks one
            continue
        if (x, y) in claimed:
            blocked[k] = moving[k]
        claimed.add((x, y))
    for k in range(n):
        if blocked[k]:
            targets[k] = cells[k]
    return (np.array(targets, dtype=np.int64).reshape(n, 3),
            np.array(blocked, dtype=bool))


def positions_in_metres(positions: np.ndarray, spacing: float,
                        altitudes: tuple[float, ...] | np.ndarray) -> np.ndarray:
    """(N, 3) float (x, y, z) metres of (N, 3) int waypoint indices."""
    positions = np.asarray(positions, dtype=np.int64)
    xyz = np.empty(positions.shape, dtype=np.float64)
    xyz[:, :2] = positions[:, :2] * spacing
    xyz[:, 2] = np.asarray(altitudes, dtype=np.float64)[positions[:, 2]]
    return xyz


def communication_matrix(positions_m: np.ndarray, comm_range: float,
                         message_drop: float = 0.0,
                         rng: np.random.Generator | None = None,
                         active: np.ndarray | None = None) -> np.ndarray:
    """Who hears whom after a step.

    Agent k receives agent i's latest measurement iff ||p_i - p_k||_2 <= D (3-D distance)
    and the message is not dropped. Every agent always "hears" itself.

    Args:
        positions_m: (N, 3) float positions in metres.
        comm_range: D in metres; 0 = none, inf = everyone.
        message_drop: probability that one (sender, receiver) message is lost.
        rng: stream for message drops; required when ``message_drop > 0``.
        active: (N,) bool, agents still flying (all when omitted); a failed UAV neither
            sends nor receives.

    Returns:
        (N, N) bool, ``heard[k, i]`` = agent k holds agent i's latest measurement.
    """
    positions_m = np.asarray(positions_m, dtype=np.float64)
    n = len(positions_m)
    difference = positions_m[:, None, :] - positions_m[None, :, :]
    # np.linalg.norm(difference, axis=-1) is this reduction; called bare, without its checks.
    distances = np.sqrt(np.add.reduce(difference * difference, axis=-1))
    heard = distances <= comm_range + 1e-9
    if message_drop > 0:
        if rng is None:
            raise ValueError("communication_matrix needs an rng when message_drop > 0")
        heard &= rng.random((n, n)) >= message_drop
    if active is not None:
        active = np.asarray(active, dtype=bool)
        heard &= active[:, None] & active[None, :]
    np.fill_diagonal(heard, True)
    return heard
