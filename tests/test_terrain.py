"""Ground-truth generators: shares, geometry, determinism, resolution independence, rasters."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import tifffile
from PIL import Image

from ipp_toolkit.config.schema import EnvConfig, TerrainConfig, WorldConfig, terrain_kinds
from ipp_toolkit.sim.mission import reset_mission
from ipp_toolkit.world import registry
from ipp_toolkit.world.terrain import (
    TERRAIN_GENERATORS,
    generate_terrain,
    half_plane,
    load_raster,
    prepare_raster,
    register_terrain,
    resample_area_average,
    resampled_raster,
    split_offset,
    split_parameters,
)

FINE = WorldConfig()  # 0.1 m: 500 x 500 cells
COARSE = WorldConfig(resolution=0.5)  # 100 x 100 cells
TINY = WorldConfig(resolution=25.0)  # 2 x 2 cells: one map cell per raster pixel of a 2 x 2
SEEDS = range(20)


def _terrain(kind: str, seed: int, world: WorldConfig = COARSE, **fields) -> np.ndarray:
    return generate_terrain(TerrainConfig(kind=kind, **fields), world,
                            np.random.default_rng(seed))


def _raster(raster: np.ndarray, threshold: float, world: WorldConfig = COARSE,
            **fields) -> np.ndarray:
    config = TerrainConfig(kind="raster", raster="unused.npy", threshold=threshold, **fields)
    return generate_terrain(config, world, np.random.default_rng(0), raster=raster)


def _centres(world: WorldConfig) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) x and y of the cell centres, measured from the area centre."""
    c = (np.arange(world.map_cells) + 0.5) * world.resolution - world.area_size / 2
    return np.meshgrid(c, c)


def _majority_5x5(fine: np.ndarray) -> np.ndarray:
    n = fine.shape[0] // 5
    return fine.reshape(n, 5, n, 5).mean(axis=(1, 3)) > 0.5


def _axis_aligned(truth: np.ndarray) -> bool:
    rows_constant = (truth == truth[:, :1]).all()
    columns_constant = (truth == truth[:1, :]).all()
    return bool(rows_constant or columns_constant)


def _components(mask: np.ndarray) -> int:
    """Number of 4-connected components of ``mask`` (label propagation; small maps only)."""
    big = mask.size
    labels = np.where(mask, np.arange(big).reshape(mask.shape), big)
    while True:
        padded = np.pad(labels, 1, constant_values=big)
        neighbours = np.minimum.reduce([padded[1:-1, 1:-1], padded[:-2, 1:-1], padded[2:, 1:-1],
                                        padded[1:-1, :-2], padded[1:-1, 2:]])
        new = np.where(mask, neighbours, big)
        if (new == labels).all():
            return len(np.unique(labels[mask]))
        labels = new


# --------------------------------------------------------------------------- all kinds


@pytest.mark.parametrize("kind", ["split", "split-axis", "blobs"])
@pytest.mark.parametrize("world", [FINE, COARSE], ids=["0.1m", "0.5m"])
def test_shape_and_dtype(kind, world):
    truth = _terrain(kind, 3, world)
    assert truth.shape == (world.map_cells, world.map_cells)
    assert truth.dtype == bool
    assert 0 < truth.sum() < truth.size


@pytest.mark.parametrize("kind", ["split", "split-axis", "blobs"])
def test_same_seed_same_terrain_other_seed_other_terrain(kind):
    np.testing.assert_array_equal(_terrain(kind, 7), _terrain(kind, 7))
    maps = [_terrain(kind, seed) for seed in range(8)]
    distinct = {m.tobytes() for m in maps}
    # split-axis has only 4 orientations, but the share is continuous: all maps differ.
    assert len(distinct) == len(maps)


def test_registry_holds_the_builtins():
    assert set(TERRAIN_GENERATORS) >= {"split", "split-axis", "blobs", "raster"}


def test_register_terrain_and_dispatch(monkeypatch):
    monkeypatch.setattr(registry, "TERRAIN_GENERATORS", dict(TERRAIN_GENERATORS))

    @register_terrain("stripes")
    def stripes(config, world, rng, raster):
        truth = np.zeros((world.map_cells, world.map_cells), dtype=bool)
        truth[:, ::2] = True
        return truth

    assert registry.TERRAIN_GENERATORS["stripes"] is stripes
    with pytest.raises(ValueError, match="'stripes' is already registered"):
        register_terrain("stripes")(stripes)
    register_terrain("stripes", replace=True)(stripes)
    # A registered kind is chosen through the config like a built-in one.
    truth = _terrain("stripes", 0)
    assert truth[:, ::2].all() and not truth[:, 1::2].any()
    assert "stripes" in terrain_kinds()
    state = reset_mission(EnvConfig().replace(world={"resolution": 0.5},
                                              terrain={"kind": "stripes"}), 0, 0)
    assert state.ground_truth[:, ::2].all()


def test_unknown_terrain_kind_is_refused_by_name():
    with pytest.raises(ValueError, match="'stipes'.*unknown terrain kind.*'blobs'"):
        TerrainConfig(kind="stipes")


def test_generator_results_are_checked(monkeypatch):
    monkeypatch.setitem(TERRAIN_GENERATORS, "split",
                        lambda config, world, rng, raster: np.zeros((world.map_cells,) * 2))
    with pytest.raises(ValueError, match="'split' produced no interesting cell"):
        _terrain("split", 0)
    monkeypatch.setitem(TERRAIN_GENERATORS, "split",
                        lambda config, world, rng, raster: np.ones((3, 4)))
    with pytest.raises(ValueError, match=r"returned shape \(3, 4\), expected \(100, 100\)"):
        _terrain("split", 0)


# --------------------------------------------------------------------------- split


@pytest.mark.parametrize("kind", ["split", "split-axis"])
def test_split_share_matches_the_drawn_share(kind):
    config = TerrainConfig(kind=kind)
    for seed in SEEDS:
        truth = _terrain(kind, seed, FINE)
        _, share = split_parameters(config, np.random.default_rng(seed), kind == "split-axis")
        assert 0.30 <= share <= 0.60
        assert 0.30 - 0.005 <= truth.mean() <= 0.60 + 0.005
        assert abs(truth.mean() - share) < 0.01


def test_split_angles_vary_and_are_not_only_axis_aligned():
    config = TerrainConfig(kind="split")
    thetas = np.array([split_parameters(config, np.random.default_rng(s))[0] for s in SEEDS])
    assert ((0 <= thetas) & (thetas < 2 * math.pi)).all()
    assert thetas.std() > 1.0  # spread over the circle, not clustered
    quadrants = set((thetas // (math.pi / 2)).astype(int))
    assert len(quadrants) >= 3
    oblique = [not _axis_aligned(_terrain("split", seed)) for seed in SEEDS]
    assert sum(oblique) >= 15


def test_split_boundary_is_a_straight_line():
    config = TerrainConfig(kind="split")
    x, y = _centres(COARSE)
    for seed in SEEDS:
        truth = _terrain("split", seed)
        theta, _ = split_parameters(config, np.random.default_rng(seed))
        projection = x * math.cos(theta) + y * math.sin(theta)
        # A half-plane: every interesting centre lies beyond every uninteresting one.
        assert projection[truth].min() > projection[~truth].max()


def test_split_axis_only_axis_aligned_in_all_four_directions():
    sides = set()
    for seed in SEEDS:
        truth = _terrain("split-axis", seed)
        assert _axis_aligned(truth)
        theta, _ = split_parameters(TerrainConfig(kind="split-axis"),
                                    np.random.default_rng(seed), axis_aligned=True)
        assert theta in (0.0, math.pi / 2, math.pi, 3 * math.pi / 2)
        # Which edge is interesting: the normal points into the interesting side.
        side = {0: truth[:, -1].all(), 1: truth[-1, :].all(), 2: truth[:, 0].all(),
                3: truth[0, :].all()}
        assert side[round(theta / (math.pi / 2))]
        sides.add(round(theta / (math.pi / 2)))
    assert sides == {0, 1, 2, 3}


@pytest.mark.parametrize("theta", [0.0, 0.3, math.pi / 4, 2.0, math.pi, 4.0, 5.9])
@pytest.mark.parametrize("share", [0.3, 0.5, 0.6, 0.05, 0.95])
def test_split_offset_matches_a_fine_quantile(theta, share):
    world = WorldConfig(resolution=0.05)  # 1000 x 1000 centres approximate the continuum
    x, y = _centres(world)
    projection = x * math.cos(theta) + y * math.sin(theta)
    expected = np.quantile(projection, 1.0 - share)
    assert split_offset(theta, share, world.area_size) == pytest.approx(expected, abs=0.06)
    assert half_plane(theta, share, world).mean() == pytest.approx(share, abs=0.002)


@pytest.mark.parametrize("kind", ["split", "split-axis", "blobs"])
def test_resolution_independence(kind):
    for seed in range(10):
        fine = _terrain(kind, seed, FINE)
        coarse = _terrain(kind, seed, COARSE)
        assert (_majority_5x5(fine) == coarse).mean() > 0.97


# --------------------------------------------------------------------------- blobs


def test_blobs_share_smoothness_and_several_blobs():
    several = 0
    for seed in range(10):
        truth = _terrain("blobs", seed)
        assert 0.30 - 0.005 <= truth.mean() <= 0.60 + 0.005
        # White noise would agree with its neighbour half the time; blobs almost always.
        assert (truth[:, 1:] == truth[:, :-1]).mean() > 0.9
        assert (truth[1:, :] == truth[:-1, :]).mean() > 0.9
        assert not _axis_aligned(truth)
        several += _components(truth) + _components(~truth) > 2
    assert several >= 3  # not a half-plane in disguise


def test_blob_scale_sets_the_smoothness():
    def agreement(scale):
        truth = _terrain("blobs", 1, blob_scale=scale)
        return (truth[:, 1:] == truth[:, :-1]).mean()

    assert agreement(1.0) < agreement(5.0) < agreement(15.0)


# --------------------------------------------------------------------------- raster files


def _bright_top_image(dtype) -> np.ndarray:
    """(20, 20) image as displayed: the top (north) 6 rows bright, the rest dark."""
    image = np.zeros((20, 20), dtype=dtype)
    image[:6] = 200
    return image


def _check_north_is_interesting(truth: np.ndarray) -> None:
    # 6 of 20 rows -> the top 30 % of the 100 map rows, i.e. high y.
    assert truth[70:].all() and not truth[:70].any()


def test_png_round_trip_puts_the_top_rows_at_high_y(tmp_path):
    path = tmp_path / "field.png"
    Image.fromarray(_bright_top_image(np.uint8)).save(path)
    values = load_raster(path)
    assert values.dtype == np.float64 and values.shape == (20, 20)
    assert values[-1, 0] == 200 and values[0, 0] == 0
    config = TerrainConfig(kind="raster", raster=str(path), threshold=100.0)
    _check_north_is_interesting(generate_terrain(config, COARSE, np.random.default_rng(0)))


def test_jpeg_round_trip(tmp_path):
    path = tmp_path / "field.JPG"  # the extension is case-insensitive
    Image.fromarray(_bright_top_image(np.uint8)).save(path, format="JPEG", quality=95)
    config = TerrainConfig(kind="raster", raster=str(path), threshold=100.0)
    _check_north_is_interesting(generate_terrain(config, COARSE, np.random.default_rng(0)))


def test_tif_float32_round_trip(tmp_path):
    path = tmp_path / "thermal.tif"
    image = _bright_top_image(np.float32) / 10 + 20  # 40 degrees north, 20 south
    tifffile.imwrite(path, image)
    values = load_raster(path)
    np.testing.assert_array_equal(values, image[::-1])
    config = TerrainConfig(kind="raster", raster=str(path), threshold=30.0)
    _check_north_is_interesting(generate_terrain(config, COARSE, np.random.default_rng(0)))


def test_npy_is_already_in_map_convention(tmp_path):
    path = tmp_path / "field.npy"
    array = _bright_top_image(np.float64)  # row 0 (y = 0) bright this time
    np.save(path, array)
    np.testing.assert_array_equal(load_raster(path), array)
    config = TerrainConfig(kind="raster", raster=str(path), threshold=100.0)
    truth = generate_terrain(config, COARSE, np.random.default_rng(0))
    assert truth[:30].all() and not truth[30:].any()


def test_array_overrides_the_file(tmp_path):
    path = tmp_path / "field.npy"
    np.save(path, np.zeros((4, 4)))
    config = TerrainConfig(kind="raster", raster=str(path), threshold=0.5)
    array = np.zeros((4, 4))
    array[:, 2:] = 1.0
    truth = generate_terrain(config, COARSE, np.random.default_rng(0), raster=array)
    assert truth[:, 50:].all() and not truth[:, :50].any()


def test_missing_file_names_the_path(tmp_path):
    path = tmp_path / "missing.tif"
    with pytest.raises(ValueError, match="missing.tif.*no such file"):
        load_raster(path)
    config = TerrainConfig(kind="raster", raster=str(path), threshold=0.5)
    with pytest.raises(ValueError, match="missing.tif"):
        generate_terrain(config, COARSE, np.random.default_rng(0))


def test_unknown_extension_directory_and_corrupt_file(tmp_path):
    text = tmp_path / "field.txt"
    text.write_text("1 2\n3 4\n")
    with pytest.raises(ValueError, match=r"field\.txt.*unknown extension '\.txt'"):
        load_raster(text)
    folder = tmp_path / "folder.png"
    folder.mkdir()
    with pytest.raises(ValueError, match=r"folder\.png.*not a file"):
        load_raster(folder)
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"not an image")
    with pytest.raises(ValueError, match=r"cannot read raster file .*corrupt\.png"):
        load_raster(corrupt)
    pickled = tmp_path / "objects.npy"
    np.save(pickled, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match=r"objects\.npy"):
        load_raster(pickled)


def test_rgb_file_must_be_single_band(tmp_path):
    path = tmp_path / "photo.png"
    Image.fromarray(np.zeros((8, 6, 3), dtype=np.uint8)).save(path)
    with pytest.raises(ValueError, match=r"photo\.png.*\(8, 6, 3\).*single band"):
        load_raster(path)


def test_cache_returns_copies_and_sees_a_rewritten_file(tmp_path):
    path = tmp_path / "field.npy"
    np.save(path, np.full((4, 4), 2.0))
    first = resampled_raster(path, (8, 8))
    np.testing.assert_array_equal(first, 2.0)
    first[:] = -1.0  # must not reach the cache
    np.testing.assert_array_equal(resampled_raster(path, (8, 8)), 2.0)
    np.save(path, np.full((5, 5), 3.0))  # another size: the cache key changes
    np.testing.assert_array_equal(resampled_raster(path, (8, 8)), 3.0)
    np.testing.assert_array_equal(resampled_raster(path, (2, 2)), 3.0)


def test_non_square_file_warns_every_time(tmp_path):
    path = tmp_path / "strip.npy"
    np.save(path, np.ones((2, 4)))
    for _ in range(2):  # a cache hit must still warn
        with pytest.warns(UserWarning, match=r"strip\.npy.*\(2, 4\).*stretched"):
            resampled_raster(path, (4, 4))


# --------------------------------------------------------------------------- raster values


def test_area_average_hand_cases():
    values = np.arange(4.0).reshape(2, 2)
    np.testing.assert_allclose(resample_area_average(values, (1, 1)), [[1.5]])
    # 3 -> 2: each target cell takes 1 source pixel fully and half of the middle one.
    nine = np.arange(9.0).reshape(3, 3)
    np.testing.assert_allclose(resample_area_average(nine, (2, 2)),
                               [[4 / 3, 8 / 3], [16 / 3, 20 / 3]], rtol=1e-12)
    np.testing.assert_array_equal(resample_area_average(values, (4, 4)),
                                  np.kron(values, np.ones((2, 2))))
    # 2 -> 3 upsampling: the middle cell straddles both pixels equally.
    np.testing.assert_allclose(resample_area_average(np.array([[0.0, 6.0]]), (1, 3)),
                               [[0.0, 3.0, 6.0]])
    # Non-square source stretched onto a square grid.
    np.testing.assert_allclose(resample_area_average(np.array([[0.0, 4.0, 8.0]]), (2, 2)),
                               [[4 / 3, 20 / 3]] * 2)


def test_area_average_preserves_the_mean_for_any_ratio():
    rng = np.random.default_rng(0)
    for source, target in [((7, 13), (5, 5)), ((3, 3), (10, 10)), ((100, 90), (7, 11)),
                           ((1, 1), (4, 4)), ((6, 6), (6, 6))]:
        values = rng.normal(size=source)
        out = resample_area_average(values, target)
        assert out.shape == target
        assert out.mean() == pytest.approx(values.mean(), abs=1e-12)
        assert values.min() - 1e-12 <= out.min() and out.max() <= values.max() + 1e-12
    same = rng.normal(size=(6, 6))
    np.testing.assert_allclose(resample_area_average(same, (6, 6)), same, rtol=1e-12)
    with pytest.raises(ValueError, match="shape"):
        resample_area_average(same, (0, 3))


def test_uniform_patches_keep_their_exact_value():
    # Plain float sums of the weights miss 0.1 by an ulp for most of these ratios.
    for source in range(2, 25):
        for target in (3, 7, 10, 13):
            out = resample_area_average(np.full((source, source), 0.1), (target, target))
            assert (out == 0.1).all(), (source, target)
    # A 0/1 mask thresholded at 1: exactly the cells wholly inside the ones are interesting.
    mask = np.zeros((30, 30))
    mask[:, :20] = 1.0  # x < 33.3 m; map cells of 0.5 m: columns 0..65 lie wholly inside
    truth = _raster(mask, threshold=1.0)
    assert truth[:, :66].all() and not truth[:, 66:].any()


@pytest.mark.parametrize(("policy", "fill"), [("min", 1.0), ("max", 3.0), ("mean", 2.0)])
def test_nan_policies_fill(policy, fill):
    raster = np.array([[np.nan, 1.0], [2.0, 3.0]])
    np.testing.assert_array_equal(prepare_raster(raster, policy), [[fill, 1.0], [2.0, 3.0]])
    truth = _raster(raster, threshold=2.5, world=TINY, nan_policy=policy)
    np.testing.assert_array_equal(truth, [[fill >= 2.5, False], [False, True]])
    assert np.isnan(raster[0, 0])  # the caller's array is not modified


def test_nan_policy_raise_counts_the_cells():
    raster = np.array([[np.nan, 1.0], [np.nan, 3.0]])
    with pytest.raises(ValueError, match="2 NaN cell.*nan_policy"):
        _raster(raster, threshold=0.0)
    with pytest.raises(ValueError, match="all NaN"):
        _raster(np.full((3, 3), np.nan), threshold=0.0, nan_policy="mean")
    with pytest.raises(ValueError, match="1 infinite"):
        _raster(np.array([[np.inf, 1.0], [2.0, 3.0]]), threshold=0.0, nan_policy="mean")
    with pytest.raises(ValueError, match="infinite"):
        prepare_raster(np.array([[-np.inf]]))


def test_array_checks():
    with pytest.raises(ValueError, match=r"\(4, 4, 3\).*single band"):
        _raster(np.zeros((4, 4, 3)), threshold=0.0)
    with pytest.raises(ValueError, match=r"\(4,\).*2-D"):
        _raster(np.zeros(4), threshold=0.0)
    with pytest.raises(ValueError, match="numeric"):
        _raster(np.array([["a", "b"]]), threshold=0.0)
    with pytest.raises(ValueError, match="at least 1 x 1"):
        _raster(np.zeros((0, 3)), threshold=0.0)
    band = np.ones((4, 4, 1))
    band[:2] = 0.0
    truth = _raster(band, threshold=0.5)
    assert truth[50:].all() and not truth[:50].any()


def test_non_square_array_warns():
    with pytest.warns(UserWarning, match=r"\(3, 6\).*stretched"):
        truth = _raster(np.repeat([[0.0], [1.0], [2.0]], 6, axis=1), threshold=1.0)
    assert truth.any() and not truth.all()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _raster(np.repeat([[0.0], [2.0]], 3, axis=0).repeat(6, axis=1), threshold=1.0)


def test_a_threshold_every_cell_reaches_is_refused():
    with pytest.raises(ValueError, match=r"every map cell reaches terrain.threshold = 1\.0"):
        _raster(np.ones((6, 6)), threshold=1.0)


def test_threshold_above_every_cell_names_it_and_the_range():
    raster = np.linspace(0.0, 5.0, 16).reshape(4, 4)
    with pytest.raises(ValueError, match=r"threshold = 7\.5.*\[0, 5\]"):
        _raster(raster, threshold=7.5)
    # Area averaging counts: one bright pixel among many cannot reach the threshold alone.
    sparse = np.zeros((10, 10))
    sparse[0, 0] = 10.0
    with pytest.raises(ValueError, match=r"threshold = 5\.0.*\[0, 10\]"):
        _raster(sparse, threshold=5.0, world=TINY)
    assert _raster(raster, threshold=5.0)[-1, -1]  # ">=": the maximum itself counts
