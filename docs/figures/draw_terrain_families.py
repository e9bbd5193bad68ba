"""Redraw docs/figures/terrain-families.png: six ground truths of each terrain family.

Rows: ``split``, ``blobs`` and ``fractal`` (as training missions draw them), then ``real``
crops of the bundled rasters of each split (train, validation, test), each titled with its
source. Black cells are interesting. Every map comes from the terrain registry
(:func:`ipp_toolkit.world.terrain.generate_terrain`, and
:func:`ipp_toolkit.world.families.real_crop` for the ``real`` rows so that a panel can name
its source) with the default area (50 m) and terrain settings.

    python docs/figures/draw_terrain_families.py
    python docs/figures/draw_terrain_families.py --seed 3 --resolution 0.1 --out families.png

The draws depend on ``--seed``: a different seed shows other members of the same families.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ipp_toolkit.config.schema import TerrainConfig, WorldConfig  # noqa: E402
from ipp_toolkit.world.families import real_crop  # noqa: E402
from ipp_toolkit.world.terrain import generate_terrain  # noqa: E402

ROWS = (("split", "train"), ("blobs", "train"), ("fractal", "train"),
        ("real", "train"), ("real", "validation"), ("real", "test"))
"""(terrain kind, mission namespace) per row of the figure."""


def draw(out: Path, seed: int = 0, columns: int = 6, resolution: float = 0.25) -> Path:
    """Draw the figure to ``out`` and return its path."""
    world = WorldConfig(resolution=resolution)
    rng = np.random.default_rng(seed)
    figure, axes = plt.subplots(len(ROWS), columns, figsize=(1.35 * columns, 1.45 * len(ROWS)),
                                squeeze=False, constrained_layout=True)
    for row, (kind, namespace) in enumerate(ROWS):
        config = TerrainConfig(kind=kind)
        for column in range(columns):
            if kind == "real":
                truth, drawn = real_crop(config, world, rng, namespace)
                title = str(drawn["source"]).replace("_", " ")[:20]
            else:
                truth = generate_terrain(config, world, rng, namespace=namespace)
                title = kind
            ax = axes[row, column]
            ax.imshow(truth, origin="lower", cmap="gray_r", vmin=0, vmax=1,
                      interpolation="nearest")
            ax.set_title(title, fontsize=6)
            ax.set_xticks([])
            ax.set_yticks([])
        axes[row, 0].set_ylabel(f"{kind}\n({namespace})", fontsize=8)
    figure.suptitle("Terrain families (black = interesting); real: crops of bundled rasters "
                    "by split", fontsize=9)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=100)
    plt.close(figure)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).with_name("terrain-families.png"),
                        help="figure to write (default: docs/figures/terrain-families.png)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the draws (default 0)")
    parser.add_argument("--columns", type=int, default=6, help="maps per row (default 6)")
    parser.add_argument("--resolution", type=float, default=0.25,
                        help="map cell side in metres (default 0.25; missions fly at 0.1)")
    args = parser.parse_args()
    print(f"wrote {draw(args.out, args.seed, args.columns, args.resolution)}")


if __name__ == "__main__":
    main()
