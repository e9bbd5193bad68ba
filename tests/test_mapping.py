import numpy as np
import pytest

from ipp_toolkit.belief.block_grid import BlockGrid
from ipp_toolkit.belief.mapping import (
    LOGODDS_CLIP,
    BeliefMaps,
    binary_entropy,
    class_weights,
    entropy_from_logodds,
    f1_score,
    fuse_measurement,
    logit,
    weighted_entropy,
)


def test_fusion_hand_case():
    p = fuse_measurement(0.5, 0.99)
    assert p == pytest.approx(0.99)
    p = fuse_measurement(p, 0.99)
    assert p == pytest.approx(0.9999, abs=1e-5)
    # A contradicting reading pulls it back: 0.9999 (+) 0.01 = 0.99.
    assert fuse_measurement(p, 0.01) == pytest.approx(0.99, abs=1e-4)


def test_fusion_stays_inside_clip():
    p = 0.5
    for _ in range(20):
        p = fuse_measurement(p, 0.99)
    assert p <= 1 - 1e-4 + 1e-12
    assert p == pytest.approx(1 - 1e-4)


def test_beliefmaps_match_scalar_fusion():
    blocks = BlockGrid(10, 3, 1.0, 5.0)
    maps = BeliefMaps(1, blocks)
    rect = (2, 5, 3, 7)
    delta = np.full((3, 4), logit(0.99), dtype=np.float32)
    for _ in range(2):
        maps.add_evidence(0, rect, delta)
        maps.refresh(0, rect)
    assert maps.prob[0, 3, 4] == pytest.approx(0.9999, abs=1e-5)
    assert maps.prob[0, 0, 0] == 0.5  # untouched cells keep the prior
    maps.add_evidence(0, rect, np.full((3, 4), 30.0, dtype=np.float32))
    assert maps.logodds[0].max() == pytest.approx(LOGODDS_CLIP)


def test_entropy_values():
    assert binary_entropy(0.5) == pytest.approx(1.0)
    assert binary_entropy(0.0) == pytest.approx(binary_entropy(1e-4))
    assert binary_entropy(0.11) == pytest.approx(0.4999, abs=1e-3)
    logodds = np.linspace(-12, 12, 101).astype(np.float32)
    p = 1 / (1 + np.exp(-logodds.astype(np.float64)))
    np.testing.assert_allclose(entropy_from_logodds(logodds), binary_entropy(p), atol=1e-5)


def test_weighted_entropy_weights():
    p = np.array([0.9, 0.1, 0.5, 0.5005, 0.52])
    np.testing.assert_allclose(class_weights(p), [1, 0, 0.5, 0.5, 1])
    np.testing.assert_allclose(class_weights(p, 0.7, 0.2), [0.7, 0.2, 0.5, 0.5, 0.7])
    we = weighted_entropy(p)
    assert we[1] == 0 and we[2] == pytest.approx(0.5)
    assert we[0] == pytest.approx(binary_entropy(0.9))


def test_f1_tiny_maps():
    truth = np.array([[1, 1], [0, 0]], dtype=bool)
    assert f1_score(truth, truth) == 1.0
    assert f1_score(truth, np.zeros_like(truth)) == 0.0
    # tp 1, fp 1, fn 1 -> precision 0.5, recall 0.5.
    assert f1_score(truth, np.array([[1, 0], [1, 0]], dtype=bool)) == pytest.approx(0.5)


def test_block_grid_partitions_map():
    blocks = BlockGrid(500, 11, 0.1, 5.0)
    assert blocks.edges[0] == 0 and blocks.edges[-1] == 500
    sizes = np.diff(blocks.edges)
    # Border waypoints own a half block (2.5 m), inner ones a full 5 m block.
    assert sizes[0] == 25 and sizes[-1] == 25 and np.all(sizes[1:-1] == 50)
    values = np.random.default_rng(0).random((500, 500))
    means = blocks.block_means(values)
    assert means[0, 0] == pytest.approx(values[:25, :25].mean())
    assert means[3, 4] == pytest.approx(values[125:175, 175:225].mean())


def test_incremental_block_sums_match_full():
    blocks = BlockGrid(100, 11, 0.5, 5.0)
    maps = BeliefMaps(2, blocks)
    rng = np.random.default_rng(1)
    for _ in range(30):
        r0, c0 = rng.integers(0, 90, size=2)
        rect = (int(r0), int(r0 + rng.integers(1, 11)), int(c0), int(c0 + rng.integers(1, 11)))
        delta = rng.normal(0, 2, size=(rect[1] - rect[0], rect[3] - rect[2])).astype(np.float32)
        maps.add_evidence(1, rect, delta)
        maps.refresh(1, rect)
    np.testing.assert_allclose(maps.prob_plane(1), blocks.block_means(maps.prob[1]), atol=1e-6)
    full_we = weighted_entropy(maps.prob[1].astype(np.float64))
    np.testing.assert_allclose(maps.wentropy_plane(1), blocks.block_means(full_we), atol=1e-5)
    np.testing.assert_allclose(maps.prob_plane(0), 0.5)


def test_coverage_fraction():
    blocks = BlockGrid(100, 11, 0.5, 5.0)
    cover = blocks.coverage((0, 5, 0, 10))  # rows 0..4 (half of block 0), cols 0..9
    assert cover[0, 0] == pytest.approx(1.0)  # block 0 is 5 x 5 cells
    assert cover[0, 1] == pytest.approx(0.5)
    assert cover[1, 0] == 0
