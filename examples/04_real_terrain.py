"""Fly the planners over a real terrain: a digital elevation model that matplotlib carries.

The paper maps a thermal image thresholded at 25 C; any single-band raster works the same
way. Here the "interesting" class is high ground: the Jacksboro fault DEM from matplotlib's
sample data (elevation in metres, 344 x 403 cells) thresholded at ``--threshold`` metres. The
file is not copied into this project: the script reads it from your matplotlib installation
(it is distributed with matplotlib under matplotlib's licence), saves it as ``.npy`` in the
map convention (row 0 = south) and runs ``ipp-compare``'s Python API on it. The learned
policies were trained on synthetic split terrains only.

    python examples/04_real_terrain.py                   # 20 missions, r_M = 0.1 m
    python examples/04_real_terrain.py --quick --planners ig,coverage

It writes into ``--out`` (default ``examples-output/04_real_terrain``): the .npy, and the
tables and figures in ``OUT/compare``, whose path is printed last. The same from the command
line, once the .npy exists:

    ipp-compare --terrain examples-output/04_real_terrain/jacksboro_dem.npy --threshold 550

The raster is not square, so it is stretched onto the 50 m x 50 m area (a warning says so).
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np
from matplotlib import cbook

from reports import compare_planners


def jacksboro_dem(folder: Path) -> Path:
    """Save matplotlib's Jacksboro DEM as ``folder/jacksboro_dem.npy`` (row 0 = south)."""
    with cbook.get_sample_data("jacksboro_fault_dem.npz") as data:
        elevation = np.asarray(data["elevation"], dtype=np.float32)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "jacksboro_dem.npy"
    # Image rows run north to south; the toolkit's arrays have row 0 at y = 0 (south).
    np.save(path, np.flipud(elevation))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threshold", type=float, default=550.0,
                        help="metres above which ground counts as interesting (default 550)")
    parser.add_argument("--planners", default="coma,ppo,ig,coverage")
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--out", default="examples-output/04_real_terrain",
                        help="folder of the raster and, in OUT/compare, the tables and figures "
                             "(default: examples-output/04_real_terrain)")
    parser.add_argument("--quick", action="store_true", help="2 missions at r_M = 1 m")
    args = parser.parse_args()
    out = Path(args.out)
    dem = jacksboro_dem(out)
    share = float((np.load(dem) > args.threshold).mean())
    print(f"{dem}: {share:.0%} of the area lies above {args.threshold:g} m")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*not square.*")
        comparison = compare_planners(agents=4, comm=25.0, planners=args.planners,
                                      trials=2 if args.quick else args.trials, terrain=dem,
                                      threshold=args.threshold, out=out / "compare",
                                      resolution=1.0 if args.quick else None,
                                      progress=False)
    print(comparison.table)
    print(f"tables and figures: {out / 'compare'}")


if __name__ == "__main__":
    main()
