"""Tests of the pure-numpy mission renderer."""

from __future__ import annotations

import os

import numpy as np
import pytest
from PIL import Image

from ipp_toolkit.sim.rendering import PALETTE, prob_to_rgb, render_mission, save_png

H = 100
AREA = 50.0
P = 120
SEP = max(2, P // 60)
EMPTY_FP = (0, 0, 0, 0)


def _gt_panel(img: np.ndarray) -> np.ndarray:
    return img[SEP:SEP + P, SEP:SEP + P]


def _global_panel(img: np.ndarray) -> np.ndarray:
    return img[SEP:SEP + P, 2 * SEP + P:2 * SEP + 2 * P]


def _small_panel(img: np.ndarray, i: int) -> np.ndarray:
    width = 2 * P + 3 * SEP
    small = (width - 5 * SEP) // 4
    row, col = divmod(i, 4)
    y0 = 2 * SEP + P + row * (small + SEP)
    x0 = SEP + col * (small + SEP)
    return img[y0:y0 + small, x0:x0 + small]


def _has_color(panel: np.ndarray, color: np.ndarray) -> np.ndarray:
    return np.all(panel == color, axis=-1)


def _scene(n: int = 4, seed: int = 0, **overrides):
    """Arguments for render_mission: a split terrain (interesting at high y), n UAVs."""
    rng = np.random.default_rng(seed)
    gt = np.zeros((H, H), dtype=bool)
    gt[H // 2:] = True
    corners = [(0.1, 0.1), (0.9, 0.1), (0.1, 0.9), (0.9, 0.9)]
    positions = np.array(
        [(corners[i % 4][0] * AREA, corners[i % 4][1] * AREA, 5.0 + 5.0 * (i % 3))
         for i in range(n)]
    ).reshape(n, 3)
    args = dict(
        ground_truth=gt,
        global_prob=rng.random((H, H)),
        local_probs=rng.random((n, H, H)),
        positions=positions,
        footprints=np.array([EMPTY_FP] * n, dtype=np.int64).reshape(n, 4),
        area_size=AREA,
        panel_px=P,
    )
    args.update(overrides)
    return args


def test_dtype_shape_and_determinism():
    args = _scene(4)
    copies = {k: np.copy(v) for k, v in args.items() if isinstance(v, np.ndarray)}
    a = render_mission(**args)
    b = render_mission(**args)
    assert a.dtype == np.uint8 and a.ndim == 3 and a.shape[2] == 3
    assert a.shape[1] == 2 * P + 3 * SEP
    np.testing.assert_array_equal(a, b)
    for k, v in copies.items():
        np.testing.assert_array_equal(args[k], v)


def test_ground_truth_high_y_appears_in_upper_part():
    gt = np.zeros((H, H), dtype=bool)
    gt[H // 2:] = True  # interesting at high y
    img = render_mission(**_scene(0, ground_truth=gt, global_prob=gt.astype(float)))
    panel = _gt_panel(img).astype(int)
    upper, lower = panel[: P // 2 - 2], panel[P // 2 + 2:]
    assert np.all(upper == upper[0, 0]) and np.all(lower == lower[0, 0])
    # The interesting colour is warm: more red than blue, and differs from the lower half.
    assert upper[0, 0, 0] > upper[0, 0, 2]
    assert not np.array_equal(upper[0, 0], lower[0, 0])
    # The global map colours 1 red at the top and 0 blue at the bottom.
    glob = _global_panel(img)
    np.testing.assert_array_equal(glob[5, 5], prob_to_rgb(1.0))
    np.testing.assert_array_equal(glob[-5, -5], prob_to_rgb(0.0))


def test_uav_marker_at_expected_pixel():
    n = 2
    positions = np.array([[0.9 * AREA, 0.1 * AREA, 10.0], [0.2 * AREA, 0.75 * AREA, 5.0]])
    args = _scene(n, positions=positions, global_prob=np.full((H, H), 0.5))
    img = render_mission(**args)
    for panel in (_global_panel(img), _gt_panel(img)):
        for i, (fx, fy) in enumerate([(0.9, 0.1), (0.2, 0.75)]):
            rows, cols = np.nonzero(_has_color(panel, PALETTE[i]))
            assert rows.size > 0
            assert abs(rows.mean() - (1 - fy) * P) <= 2
            assert abs(cols.mean() - fx * P) <= 2
    # UAV 0 (high x, low y) is in the right-bottom quadrant of the global panel.
    rows, cols = np.nonzero(_has_color(_global_panel(img), PALETTE[0]))
    assert rows.min() > P // 2 and cols.min() > P // 2


def test_marker_grows_with_altitude():
    def marker_pixels(z: float) -> int:
        args = _scene(1, positions=np.array([[AREA / 2, AREA / 2, z]]))
        return int(_has_color(_global_panel(render_mission(**args)), PALETTE[0]).sum())

    assert marker_pixels(5.0) < marker_pixels(10.0) < marker_pixels(15.0)


def test_footprint_outline_drawn():
    fp = np.array([[10, 30, 20, 40]])  # rows = y cells, cols = x cells
    args = _scene(1, footprints=fp, positions=np.array([[0.9 * AREA, 0.9 * AREA, 5.0]]),
                  global_prob=np.full((H, H), 0.5))
    img = render_mission(**args)
    scale = P / H
    top, bottom = round((H - 30) * scale), round((H - 10) * scale)
    left, right = round(20 * scale), round(40 * scale)
    for panel in (_global_panel(img), _gt_panel(img)):
        hit = _has_color(panel, PALETTE[0])
        assert hit[top, left:right].all() and hit[bottom - 1, left:right].all()
        assert hit[top:bottom, left].all() and hit[top:bottom, right - 1].all()
        assert not hit[(top + bottom) // 2, (left + right) // 2]
    # The local panel also outlines its own footprint.
    assert _has_color(_small_panel(img, 0)[4:-4, 4:-4], PALETTE[0]).any()


def test_small_panels_follow_n():
    img2 = render_mission(**_scene(2))
    img8 = render_mission(**_scene(8))
    assert img2.shape[1] == img8.shape[1]
    assert img8.shape[0] > img2.shape[0]
    for i in range(8):
        assert _has_color(img8, PALETTE[i]).any()
        assert _has_color(img2, PALETTE[i]).any() == (i < 2)
        border = _small_panel(img8, i)
        assert np.all(border[0] == PALETTE[i]) and np.all(border[:, -1] == PALETTE[i])
    # Beyond the palette, colours cycle without error.
    assert render_mission(**_scene(9)).shape[0] > img8.shape[0]


def test_small_panels_show_local_maps():
    local = np.stack([np.zeros((H, H)), np.ones((H, H))])
    img = render_mission(**_scene(2, local_probs=local))
    for i, p in enumerate((0.0, 1.0)):
        panel = _small_panel(img, i)
        c = panel.shape[0] // 2
        np.testing.assert_array_equal(panel[c, c], prob_to_rgb(p))


def test_progress_bar():
    base = render_mission(**_scene(2))
    half = render_mission(**_scene(2), step=50, budget=100)
    done = render_mission(**_scene(2), step=100, budget=100)
    assert half.shape[0] > base.shape[0]
    bar_row = half.shape[0] - SEP - 2
    light_half = (half[bar_row, :, 0] > 150).sum()
    light_done = (done[bar_row, :, 0] > 150).sum()
    assert 0 < light_half < light_done
    assert abs(light_done - 2 * light_half) <= 2


@pytest.mark.parametrize(
    ("override", "name"),
    [
        ({"ground_truth": np.zeros(H, dtype=bool)}, "ground_truth"),
        ({"global_prob": np.zeros((H, H + 1))}, "global_prob"),
        ({"local_probs": np.zeros((4, H, H - 1))}, "local_probs"),
        ({"local_probs": np.zeros((H, H))}, "local_probs"),
        ({"positions": np.zeros((4, 2))}, "positions"),
        ({"positions": np.zeros((3, 3))}, "positions"),
        ({"footprints": np.zeros((4, 3), dtype=int)}, "footprints"),
        ({"footprints": np.full((4, 4), 0.5)}, "footprints"),
        ({"area_size": 0.0}, "area_size"),
        ({"panel_px": 8}, "panel_px"),
        ({"altitudes": ()}, "altitudes"),
        ({"step": 3}, "step"),
        ({"step": 3, "budget": 0}, "budget"),
    ],
)
def test_bad_arguments_raise(override, name):
    with pytest.raises(ValueError, match=name):
        render_mission(**_scene(4, **override))


def test_bad_shape_message_names_shape():
    with pytest.raises(ValueError, match=r"local_probs.*\(4, 100, 99\)"):
        render_mission(**_scene(4, local_probs=np.zeros((4, H, H - 1))))


def test_save_png_round_trip(tmp_path):
    img = render_mission(**_scene(3), step=1, budget=4)
    path = tmp_path / "frame.png"
    save_png(img, path)
    save_png(img, str(path))  # overwriting works too
    with Image.open(path) as im:
        assert im.format == "PNG"
        back = np.asarray(im.convert("RGB"))
    np.testing.assert_array_equal(back, img)
    assert os.listdir(tmp_path) == ["frame.png"]


def test_save_png_rejects_bad_image(tmp_path):
    with pytest.raises(ValueError, match="rgb"):
        save_png(np.zeros((4, 4), dtype=np.uint8), tmp_path / "x.png")
    assert os.listdir(tmp_path) == []
