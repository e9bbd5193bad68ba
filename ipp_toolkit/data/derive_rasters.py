"""Derive the bundled real rasters (``ipp_toolkit/data/rasters/``) from public sample data.

Run by hand, once, where the sources are at hand (the toolkit never needs them)::

    apt-get download r-cran-stars && dpkg-deb -x r-cran-stars_*.deb /tmp/debs
    pip install imagecodecs scipy      # LZW TIFFs and NetCDF-3, for this script only
    python -m ipp_toolkit.data.derive_rasters --stars /tmp/debs/usr/lib/R/site-library/stars

Each source file becomes one ``NAME.npy``: float32, ``[layer, y, x]`` with row 0 at the
south edge (the map convention), NaN where the source has no data, at most
``MAX_SIDE`` pixels a side (area-averaged down where larger; no-data pixels stay NaN), and
one entry in ``sources.json`` with its split, what it measures, the source file and licence.

The split is by source file, never by crop: a mission's crop comes from a file of its own
namespace (train / validation / test). matplotlib's Jacksboro DEM is a test raster
(``examples/04`` flies it as unseen terrain). Never add the data of the Debian package
r-cran-satellite: it is reserved for testing outside the project. Packages whose data carry a
copyleft licence (r-cran-terra, r-cran-raster: GPL-3) are left out of this MIT project.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

MAX_SIDE = 200
HERE = Path(__file__).resolve().parent / "rasters"


def _shrink(layer: np.ndarray) -> np.ndarray:
    """Area-average by an integer factor so no side exceeds MAX_SIDE; NaN stays NaN."""
    factor = int(np.ceil(max(layer.shape) / MAX_SIDE))
    if factor == 1:
        return layer
    h, w = (layer.shape[0] // factor) * factor, (layer.shape[1] // factor) * factor
    blocks = layer[:h, :w].reshape(h // factor, factor, w // factor, factor)
    with np.errstate(invalid="ignore"):
        mean = np.nanmean(blocks, axis=(1, 3)) if np.isnan(blocks).any() \
            else blocks.mean(axis=(1, 3))
    mean[np.isnan(blocks).any(axis=(1, 3))] = np.nan  # a block touching no-data is no-data
    return mean


def _north_up_to_map(layer: np.ndarray) -> np.ndarray:
    """Images and grids stored north row first -> row 0 at the south edge."""
    return np.ascontiguousarray(layer[::-1])


def _tiff(path: Path) -> np.ndarray:
    import tifffile

    return np.asarray(tifffile.imread(path), dtype=np.float64)


def _netcdf(path: Path, variable: str) -> np.ndarray:
    from scipy.io import netcdf_file

    with netcdf_file(path, mmap=False) as nc:
        var = nc.variables[variable]
        data = np.asarray(var.data, dtype=np.float64)
        for attribute in ("_FillValue", "missing_value"):
            fill = getattr(var, attribute, None)
            if fill is not None:
                data[data == float(np.asarray(fill))] = np.nan
        data[np.abs(data) > 1e19] = np.nan
        scale = float(getattr(var, "scale_factor", 1.0))
        offset = float(getattr(var, "add_offset", 0.0))
    return data * scale + offset


def derive(stars: Path, matplotlib_data: Path) -> list[dict]:
    """Write every bundled raster; returns the manifest entries."""
    licence_stars = "Apache-2.0 (R package stars, Debian r-cran-stars)"
    licence_mpl = "matplotlib licence (PSF-based), matplotlib sample data"
    entries = []

    def save(name: str, layers: list[np.ndarray], split: str, measures: str, source: str,
             licence: str, note: str) -> None:
        stack = np.stack([_shrink(layer) for layer in layers]).astype(np.float32)
        np.save(HERE / f"{name}.npy", stack)
        entries.append({"name": name, "split": split, "measures": measures, "source": source,
                        "licence": licence, "shape": list(stack.shape),
                        "nodata_fraction": round(float(np.isnan(stack).mean()), 4),
                        "note": note})

    # --- training sources
    bands = _tiff(stars / "tif" / "L7_ETMs.tif")  # (y, x, 6) Landsat 7 ETM+, north row first
    red, nir = bands[..., 2], bands[..., 3]
    ndvi = (nir - red) / np.maximum(nir + red, 1.0)
    save("landsat_ndvi", [_north_up_to_map(ndvi)], "train", "vegetation index (NDVI)",
         "stars/tif/L7_ETMs.tif (bands 3 and 4)", licence_stars,
         "NDVI = (NIR - red) / (NIR + red) of a Landsat 7 scene near Olinda, Brazil")
    dem = _tiff(stars / "tif" / "olinda_dem_utm25s.tif")
    save("olinda_dem", [_north_up_to_map(dem)], "train", "elevation (m)",
         "stars/tif/olinda_dem_utm25s.tif", licence_stars, "digital elevation model, Olinda")
    topo = np.load(matplotlib_data / "topobathy.npz")["topo"].astype(np.float64)
    save("topobathy", [topo], "train", "elevation and bathymetry (m)",
         "matplotlib sample_data/topobathy.npz", licence_mpl,
         "topography and bathymetry grid (latitude ascending: row 0 is south)")
    waves = _netcdf(stars / "nc" / "c201923412.out1_4.nc", "wvh")
    save("wave_height", [waves[0]], "train", "significant wave height (m)",
         "stars/nc/c201923412.out1_4.nc (wvh)", licence_stars,
         "ocean wave model output; land is no-data")
    # --- validation sources
    sst = _netcdf(stars / "nc" / "reduced.nc", "sst")
    save("sea_surface_temperature", [sst[0, 0]], "validation", "sea surface temperature (C)",
         "stars/nc/reduced.nc (sst)", licence_stars,
         "NOAA OI SST, one day, global 2-degree grid; land is no-data")
    rain = _netcdf(stars / "nc" / "test_stageiv_xyt.nc",
                   "Total_precipitation_surface_1_Hour_Accumulation")
    wettest = np.argsort([-np.nansum(layer) for layer in rain])[:4]
    save("stage4_precipitation", [rain[k] for k in sorted(wettest)], "validation",
         "hourly precipitation (mm)", "stars/nc/test_stageiv_xyt.nc", licence_stars,
         "NCEP Stage IV hourly precipitation, the four wettest hours")
    # --- test sources
    tas = _netcdf(stars / "nc" / "bcsd_obs_1999.nc", "tas")
    save("bcsd_air_temperature", [tas[k] for k in (0, 3, 6, 9)], "test",
         "monthly mean air temperature (C)", "stars/nc/bcsd_obs_1999.nc (tas)", licence_stars,
         "gridded observed monthly mean surface air temperature, 1999: Jan, Apr, Jul, Oct")
    jacksboro = np.load(matplotlib_data / "jacksboro_fault_dem.npz")["elevation"]
    save("jacksboro_dem", [_north_up_to_map(jacksboro.astype(np.float64))], "test",
         "elevation (m)", "matplotlib sample_data/jacksboro_fault_dem.npz", licence_mpl,
         "USGS DEM of the Jacksboro fault, Tennessee (examples/04 flies it as unseen)")
    return entries


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stars", type=Path, required=True,
                        help="the installed R package stars (its tif/ and nc/ folders)")
    parser.add_argument("--matplotlib-data", type=Path, default=None,
                        help="matplotlib's sample_data folder (default: the installed one)")
    args = parser.parse_args()
    if args.matplotlib_data is None:
        import matplotlib

        args.matplotlib_data = Path(matplotlib.get_data_path()) / "sample_data"
    HERE.mkdir(exist_ok=True)
    entries = derive(args.stars, args.matplotlib_data)
    (HERE / "sources.json").write_text(json.dumps(entries, indent=1) + "\n")
    for entry in entries:
        print(f"{entry['split']:<10} {entry['name']:<26} {entry['shape']} "
              f"no-data {entry['nodata_fraction']:.2f}")


if __name__ == "__main__":
    main()
