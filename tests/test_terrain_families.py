"""The realistic terrain families: fractal, real (bundled rasters by split) and mixture."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest

from ipp_toolkit.config.schema import EnvConfig, TerrainConfig, WorldConfig
from ipp_toolkit.config.settings import build_env_config
from ipp_toolkit.sim.mission import reset_mission
from ipp_toolkit.world.families import RASTER_FOLDER, real_crop, real_rasters
from ipp_toolkit.world.terrain import generate_terrain

COARSE = WorldConfig(resolution=0.5)


def _draw(kind: str, seed: int, namespace: str = "train", **fields) -> np.ndarray:
    return generate_terrain(TerrainConfig(kind=kind, **fields), COARSE,
                            np.random.default_rng(seed), namespace=namespace)


@pytest.mark.parametrize("kind", ["fractal", "real", "mixture"])
def test_families_are_seeded_and_deterministic(kind):
    first = [_draw(kind, seed) for seed in range(4)]
    again = [_draw(kind, seed) for seed in range(4)]
    assert all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    assert not np.array_equal(first[0], first[1])


@pytest.mark.parametrize("kind, namespace", [("fractal", "train"), ("real", "train"),
                                             ("real", "validation"), ("real", "test")])
def test_interesting_share_follows_the_threshold_quantile(kind, namespace):
    shares = np.array([_draw(kind, seed, namespace).mean() for seed in range(25)])
    # Default quantiles 0.4-0.9: 10-60 % interesting, up to ties at the quantile (flat
    # stretches of a raster) and no-data cells.
    assert shares.min() > 0.03 and shares.max() < 0.7, shares
    assert shares.max() - shares.min() > 0.2  # the quantile is drawn per mission
    narrow = np.array([_draw(kind, seed, namespace, threshold_quantile=0.75).mean()
                       for seed in range(10)])
    assert np.all(narrow < 0.3) and np.all(narrow > 0.05), narrow


def test_fractal_exponent_sets_the_texture():
    def boundary_cells(truth: np.ndarray) -> int:
        return int((truth[1:] != truth[:-1]).sum() + (truth[:, 1:] != truth[:, :-1]).sum())

    rough = np.mean([boundary_cells(_draw("fractal", s, spectral_exponent=(1.5, 1.5),
                                          threshold_quantile=0.7)) for s in range(6)])
    smooth = np.mean([boundary_cells(_draw("fractal", s, spectral_exponent=(4.5, 4.5),
                                           threshold_quantile=0.7)) for s in range(6)])
    assert rough > 2 * smooth


def test_fractal_ignores_the_map_resolution():
    config = TerrainConfig(kind="fractal", threshold_quantile=0.6)
    coarse = generate_terrain(config, COARSE, np.random.default_rng(3))
    fine = generate_terrain(config, WorldConfig(resolution=0.1), np.random.default_rng(3))
    agree = fine.reshape(100, 5, 100, 5).mean(axis=(1, 3)).round() == coarse
    assert agree.mean() > 0.97


def test_real_sources_are_split_by_file():
    rasters = real_rasters()
    splits = Counter(r.split for r in rasters)
    assert set(splits) == {"train", "validation", "test"} and min(splits.values()) >= 2
    assert len({r.name for r in rasters}) == len(rasters)  # one entry per file
    by_name = {r.name: r for r in rasters}
    assert by_name["jacksboro_dem"].split == "test"  # examples/04 presents it as unseen
    manifest = json.loads((RASTER_FOLDER / "sources.json").read_text())
    assert all(entry["licence"] and entry["source"] for entry in manifest)
    assert not any("satellite" in entry["source"].lower() for entry in manifest)
    for namespace in ("train", "validation", "test"):
        drawn = {real_crop(TerrainConfig(kind="real"), COARSE, np.random.default_rng(s),
                           namespace)[1]["source"] for s in range(30)}
        assert drawn <= {r.name for r in rasters if r.split == namespace}
        assert len(drawn) >= 2


def test_real_no_data_is_never_interesting():
    raster = next(r for r in real_rasters() if np.isnan(r.layers).any())
    config = TerrainConfig(kind="real", real_sources="all", threshold_quantile=0.05,
                           crop_fraction=(1.0, 1.0))
    for seed in range(40):
        truth, drawn = real_crop(config, COARSE, np.random.default_rng(seed), "train")
        if drawn["source"] == raster.name:
            # At q = 0.05 every data cell but the lowest 5 % is interesting: the rest of the
            # map is the no-data share.
            assert truth.mean() < 0.97
            return
    pytest.fail(f"no crop of {raster.name} in 40 draws")


def test_mixture_respects_its_weights():
    config = TerrainConfig(kind="mixture", mixture={"split": 3.0, "fractal": 1.0, "blobs": 0})
    kinds = []
    for seed in range(200):
        rng = np.random.default_rng(seed)
        probabilities = np.array([3.0, 1.0, 0.0]) / 4.0
        kinds.append(("split", "fractal", "blobs")[int(rng.choice(3, p=probabilities))])
        truth = generate_terrain(config, COARSE, np.random.default_rng(seed))
        if kinds[-1] == "split":  # a straight boundary: every row is a prefix or suffix run
            assert ((truth[:, 1:] != truth[:, :-1]).sum(axis=1) <= 1).all()
    counts = Counter(kinds)
    assert counts["blobs"] == 0 and 120 < counts["split"] < 180


def test_mission_namespace_picks_the_real_split():
    config = EnvConfig().replace(world={"resolution": 1.0}, terrain={"kind": "real"})
    names = {r.name: r.split for r in real_rasters()}
    for namespace in ("train", "validation", "test"):
        state = reset_mission(config, seed=0, mission=1, namespace=namespace)
        assert state.ground_truth.any()
    # The same mission index in two namespaces draws from disjoint files.
    assert {names[r] for r in ("jacksboro_dem", "bcsd_air_temperature")} == {"test"}


@pytest.mark.parametrize("fields, message", [
    ({"kind": "mixture", "mixture": {"nope": 1}}, "unknown terrain kind 'nope'"),
    ({"kind": "mixture", "mixture": {"split": -1}}, "weight of 'split'"),
    ({"kind": "mixture", "mixture": {"split": 0}}, "needs a positive weight"),
    ({"kind": "mixture", "mixture": {"mixture": 1}}, "not mixture"),
    ({"kind": "fractal", "threshold_quantile": 1.5}, "threshold_quantile"),
    ({"kind": "fractal", "threshold_quantile": [0.8, 0.2]}, "threshold_quantile"),
    ({"kind": "real", "real_sources": "holdout"}, "real_sources"),
    ({"kind": "real", "crop_fraction": [0.0, 1.0]}, "crop_fraction"),
    ({"kind": "raster", "raster": "x.npy", "threshold": 1.0, "threshold_quantile": 0.5},
     "not both"),
])
def test_bad_terrain_settings_name_the_field(fields, message):
    with pytest.raises(ValueError, match=message):
        TerrainConfig(**fields)


def test_raster_threshold_quantile_and_yaml_mixture(tmp_path):
    values = np.arange(100.0).reshape(10, 10)
    config = TerrainConfig(kind="raster", raster="unused.npy", threshold_quantile=0.75)
    truth = generate_terrain(config, COARSE, np.random.default_rng(0), raster=values)
    assert 0.2 < truth.mean() < 0.3
    path = tmp_path / "mix.yaml"
    path.write_text("terrain:\n  kind: mixture\n  mixture: {split: 1, real: 2}\n")
    built = build_env_config(path)
    assert built.terrain.mixture == (("split", 1.0), ("real", 2.0))
