import numpy as np

from ipp_toolkit.sim.team import ACTION_NAMES, action_masks, communication_matrix, resolve_moves


def test_action_order():
    assert ACTION_NAMES == ("up", "north", "east", "south", "west", "down")


def test_masks_at_borders_and_altitudes():
    masks = action_masks(np.array([[0, 0, 2], [10, 10, 0]]), grid_points=11, n_altitudes=3)
    # Corner (0, 0) at the top level: no up, south, west.
    assert masks[0].tolist() == [0, 1, 1, 0, 0, 1]
    # Corner (10, 10) at the bottom level: no north, east, down.
    assert masks[1].tolist() == [1, 0, 0, 1, 1, 0]
    assert masks.dtype == np.int8


def test_masks_forbid_occupied_cells():
    positions = np.array([[5, 5, 1], [6, 5, 0], [5, 6, 2]])
    masks = action_masks(positions, 11, 3)
    assert masks[0, 2] == 0  # east is held by agent 1
    assert masks[0, 1] == 0  # north is held by agent 2
    assert masks[0, 0] == 1 and masks[0, 5] == 1  # up/down keep its own cell


def test_same_target_lowest_index_moves():
    positions = np.array([[4, 5, 2], [6, 5, 2]])
    new, blocked = resolve_moves(positions, np.array([2, 4]))  # both to (5, 5)
    assert new[0].tolist() == [5, 5, 2] and new[1].tolist() == [6, 5, 2]
    assert blocked.tolist() == [False, True]


def test_same_target_three_agents():
    positions = np.array([[5, 4, 0], [4, 5, 1], [6, 5, 2]])
    new, blocked = resolve_moves(positions, np.array([1, 2, 4]))  # all into (5, 5)
    assert blocked.tolist() == [False, True, True]
    assert len({(x, y) for x, y, _ in new.tolist()}) == 3


def test_communication_sets():
    positions = np.array([[10, 10, 15], [40, 10, 15], [40, 40, 15], [10, 30, 15]], float)
    heard = communication_matrix(positions, 25.0)
    assert heard.diagonal().all()
    assert not heard[0, 1]  # 30 m apart
    assert heard[0, 3] and heard[3, 0]  # 20 m apart
    assert heard.sum() == 6
    assert communication_matrix(positions, 0.0).sum() == 4
    assert communication_matrix(positions, np.inf).all()
    # 3-D distance: 20 m apart horizontally, 10 m vertically -> 22.4 m.
    pair = np.array([[0, 0, 5], [20, 0, 15]], float)
    assert communication_matrix(pair, 22.0).sum() == 2
    assert communication_matrix(pair, 22.5).sum() == 4


def test_message_drop_is_seeded():
    positions = np.zeros((6, 3))
    positions[:, 0] = np.arange(6)
    a = communication_matrix(positions, np.inf, 0.5, np.random.default_rng(3))
    b = communication_matrix(positions, np.inf, 0.5, np.random.default_rng(3))
    assert (a == b).all() and 6 < a.sum() < 36


def _reference_masks(positions, grid_points, n_altitudes, active=None):
    """The NumPy formulation action_masks replaced (kept as its reference)."""
    from ipp_toolkit.sim.team import ACTION_DELTAS

    positions = np.asarray(positions, dtype=np.int64)
    targets = positions[:, None, :] + ACTION_DELTAS[None, :, :]
    inside = np.all((targets[..., :2] >= 0) & (targets[..., :2] < grid_points), axis=-1)
    inside &= (targets[..., 2] >= 0) & (targets[..., 2] < n_altitudes)
    owner = np.full((grid_points, grid_points), -1, dtype=np.int64)
    holders = np.arange(len(positions)) if active is None else np.flatnonzero(active)
    owner[positions[holders, 1], positions[holders, 0]] = holders
    holder = owner[np.clip(targets[..., 1], 0, grid_points - 1),
                   np.clip(targets[..., 0], 0, grid_points - 1)]
    free = (holder < 0) | (holder == np.arange(len(positions))[:, None])
    return (inside & free).astype(np.int8)


def _reference_moves(positions, actions, moving=None, active=None):
    """The NumPy formulation resolve_moves replaced (kept as its reference)."""
    from ipp_toolkit.sim.team import ACTION_DELTAS

    n = len(positions)
    moving = np.ones(n, dtype=bool) if moving is None else np.asarray(moving, dtype=bool)
    targets = np.where(moving[:, None], positions + ACTION_DELTAS[actions], positions)
    cell_ids = targets[:, 1] * (1 << 20) + targets[:, 0]
    if active is not None:
        inactive = ~np.asarray(active, dtype=bool)
        cell_ids[inactive] = -1 - np.flatnonzero(inactive)
    _, first = np.unique(cell_ids, return_index=True)
    winner = np.zeros(n, dtype=bool)
    winner[first] = True
    blocked = moving & ~winner
    return np.where(blocked[:, None], positions, targets), blocked


def test_masks_and_moves_match_their_numpy_reference():
    rng = np.random.default_rng(3)
    for _ in range(400):
        n, g, z = int(rng.integers(1, 9)), int(rng.integers(2, 6)), int(rng.integers(1, 4))
        cells = rng.choice(g * g, size=min(n, g * g), replace=False)
        positions = np.stack([cells % g, cells // g, rng.integers(0, z, len(cells))], axis=1)
        active = rng.random(len(cells)) < 0.8 if rng.random() < 0.5 else None
        masks = action_masks(positions, g, z, active)
        np.testing.assert_array_equal(masks, _reference_masks(positions, g, z, active))
        assert masks.dtype == np.int8 and masks.shape == (len(cells), 6)
        # Moves are valid (the rule assumes it; masks are all 0 only when boxed in).
        moving = masks.any(axis=1) & (rng.random(len(cells)) < 0.8)
        if active is not None:
            moving &= active
        actions = np.array([rng.choice(np.flatnonzero(row)) if move else rng.integers(0, 6)
                            for row, move in zip(masks, moving, strict=True)])
        if moving.all() and rng.random() < 0.5:
            moving = None
        moved, blocked = resolve_moves(positions, actions, moving, active)
        expected_moved, expected_blocked = _reference_moves(positions, actions, moving, active)
        np.testing.assert_array_equal(moved, expected_moved)
        np.testing.assert_array_equal(blocked, expected_blocked)
        assert moved.dtype == np.int64 and blocked.dtype == bool


def test_unclaimed_options_on_a_hand_sized_case():
    from ipp_toolkit.sim.team import ACTION_NAMES, unclaimed_options

    position = np.array([2, 2, 1])
    mask = np.ones(6, dtype=bool)
    # A teammate goes to (3, 2) at another altitude: east is claimed (2-D cells), the rest not.
    allowed = unclaimed_options(position, mask, np.array([[3, 2, 0]]))
    assert allowed.tolist() == [name != "east" for name in ACTION_NAMES]
    # Up and down keep the agent's cell: a teammate moving onto it claims both.
    allowed = unclaimed_options(position, mask, np.array([[2, 2, 2]]))
    assert not allowed[ACTION_NAMES.index("up")] and not allowed[ACTION_NAMES.index("down")]
    # Nothing claimed, or everything valid claimed: the mask itself.
    assert unclaimed_options(position, mask, np.empty((0, 3), dtype=int)).all()
    only_east = np.array([name == "east" for name in ACTION_NAMES])
    assert unclaimed_options(position, only_east, np.array([[3, 2, 0]])).tolist() == \
        only_east.tolist()


def test_choose_in_order_on_a_hand_sized_case():
    from ipp_toolkit.sim.team import ACTION_NAMES, choose_in_order

    east, north = ACTION_NAMES.index("east"), ACTION_NAMES.index("north")
    # Agents at (1, 2) and (3, 2) both like the cell (2, 2) between them most.
    positions = np.array([[1, 2, 1], [3, 2, 1]])
    scores = np.zeros((2, 6))
    scores[0, east] = 2.0
    scores[1, ACTION_NAMES.index("west")] = 2.0
    scores[1, north] = 1.0
    masks = np.ones((2, 6), dtype=bool)
    hears = np.ones((2, 2), dtype=bool)
    # Agent 1 hears agent 0's choice: it takes its second best.
    assert choose_in_order(scores, positions, masks, hears).tolist() == [east, north]
    # Out of range: both go for the cell (the same-target rule will settle it).
    alone = np.eye(2, dtype=bool)
    assert choose_in_order(scores, positions, masks, alone).tolist() == [
        east, ACTION_NAMES.index("west")]


def test_choose_in_order_rescores_each_agent_with_its_decided_teammates_targets():
    """``rescore(k, targets)`` replaces agent k's scores and is given the next waypoints of
    exactly the heard teammates that decided before it."""
    from ipp_toolkit.sim.team import ACTION_NAMES, choose_in_order

    east, north, south = (ACTION_NAMES.index(name) for name in ("east", "north", "south"))
    positions = np.array([[1, 2, 1], [3, 2, 1], [5, 5, 1]])
    scores = np.zeros((3, 6))
    scores[:, east] = 1.0
    masks = np.ones((3, 6), dtype=bool)
    hears = np.ones((3, 3), dtype=bool)
    hears[2, 0] = False  # agent 2 hears agent 1 only
    seen: dict[int, list[list[int]]] = {}

    def rescore(k: int, targets: np.ndarray) -> np.ndarray:
        seen[k] = targets.tolist()
        own = scores[k].copy()
        own[north if len(targets) else south] = 2.0
        return own

    actions = choose_in_order(scores, positions, masks, hears, rescore)
    assert seen == {0: [], 1: [[1, 1, 1]], 2: [[3, 3, 1]]}
    assert actions.tolist() == [south, north, north]
