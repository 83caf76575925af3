#!/usr/bin/env python3
"""Run s2p, the classical peer, on one pair of the JAX_068 development images with the settings
of the set's `s2p/README.md`, so that any pair can be compared with `seasonstereo reconstruct`.

    python scripts/s2p_pair.py --s2p S2P_BIN --data DEV_DIR --out OUT 014-020 [006-022 ...]

Writes OUT/<pair>.tif (s2p's DSM on its own 0.5 m grid; `seasonstereo score` cuts it onto the
truth's grid) and OUT/<pair>.seconds (wall clock of the s2p command). The first image of a pair
is the reference. Settings: MGM, `full_img`, 0.5 m cells, s2p's defaults otherwise, and, standing
in for the SRTM tile s2p would download, a flat DEM at -25 m above the WGS84 ellipsoid (read as
ellipsoidal, `exogenous_dem_geoid_mode` false); with s2p's -10/+100 m margins it gives the
disparity range, together with s2p's SIFT range. These settings reproduce the set's
`s2p/003-004.tif` cell for cell with s2p at commit 4a0b2d8.

Run it with the Python that s2p is installed in (it needs numpy and rasterio, as s2p does).
Install notes (s2p at 4a0b2d8 with its submodules; Debian): apt `libfftw3-dev libtiff-dev
libgeotiff-dev libgdal-dev cmake`; `pip install --no-build-isolation` for its dependencies that
still build with `pkg_resources` (ransac, srtm4, plyflatten); `make` in the source tree; then
`pip install --no-build-isolation --no-deps -e .`.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import time

FLAT_DEM_ALTITUDE = -25.0


def write_flat_dem(path, lon, lat):
    """A 1°×1° EPSG:4326 DEM around (lon, lat) at the flat altitude."""
    import numpy as np
    import rasterio
    from rasterio.transform import from_origin

    res, size = 0.001, 1000
    west, north = round(lon) - 0.5, round(lat) + 0.5
    data = np.full((size, size), FLAT_DEM_ALTITUDE, np.float32)
    with rasterio.open(path + ".tmp", "w", driver="GTiff", width=size, height=size, count=1,
                       dtype="float32", crs="EPSG:4326",
                       transform=from_origin(west, north, res, res)) as dst:
        dst.write(data, 1)
    os.replace(path + ".tmp", path)


def image_paths(data, image_id):
    stem = f"JAX_068_{image_id}_RGB"
    return f"{data}/images/{stem}.tif", f"{data}/rpcs/ba/{stem}.json"


def run_pair(args, pair, dem):
    out_tif = os.path.join(args.out, f"{pair}.tif")
    if os.path.exists(out_tif):
        print(f"{pair}: {out_tif} exists, skipped")
        return
    images = []
    for image_id in pair.split("-"):
        image, rpc = image_paths(args.data, image_id)
        with open(rpc) as f:
            images.append({"img": image, "rpc": json.load(f)["rpc"]})
    work = os.path.join(args.out, f"{pair}_work")
    shutil.rmtree(work, ignore_errors=True)
    config = {
        "out_dir": work,
        "images": images,
        "full_img": True,
        "dsm_resolution": 0.5,
        "matching_algorithm": "mgm",
        "exogenous_dem": dem,
        "exogenous_dem_geoid_mode": False,
    }
    config_path = os.path.join(args.out, f"{pair}.json")
    with open(config_path, "w") as f:
        json.dump(config, f, indent=2)
    start = time.monotonic()
    with open(os.path.join(args.out, f"{pair}.log"), "w") as log:
        rc = subprocess.call([args.s2p, config_path], stdout=log, stderr=subprocess.STDOUT)
    seconds = time.monotonic() - start
    dsm = os.path.join(work, "dsm.tif")
    if rc != 0 or not os.path.exists(dsm):
        sys.exit(f"{pair}: s2p failed (exit {rc}); see {args.out}/{pair}.log")
    # The DSM lands last: a pair whose DSM exists is complete, its time included.
    with open(os.path.join(args.out, f"{pair}.seconds"), "w") as f:
        f.write(f"{seconds:.1f}\n")
    shutil.copyfile(dsm, out_tif + ".tmp")
    os.replace(out_tif + ".tmp", out_tif)
    print(f"{pair}: {out_tif} in {seconds:.1f} s")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--s2p", default="s2p", help="the s2p command")
    p.add_argument("--data", required=True, help="the dfc2019-jax068-dev folder")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("pairs", nargs="+", help="pairs as REF-SEC image ids, e.g. 014-020")
    args = p.parse_args()
    os.makedirs(args.out, exist_ok=True)
    with open(image_paths(args.data, args.pairs[0].split("-")[0])[1]) as f:
        rpc = json.load(f)["rpc"]
    dem = os.path.join(args.out, "flat_dem.tif")
    if not os.path.exists(dem):
        write_flat_dem(dem, rpc["lon_offset"], rpc["lat_offset"])
    for pair in args.pairs:
        run_pair(args, pair, dem)


if __name__ == "__main__":
    main()
