import numpy as np

from ipp_toolkit.team import ACTION_NAMES, action_masks, communication_matrix, resolve_moves


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
