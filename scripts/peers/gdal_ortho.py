"""GDAL's RPC orthorectification over our DSM, the peer of `--ortho` in BENCHMARKS.md: one image
onto the DSM's grid, bilinear, no occlusion handling, its RPC as delivered (GDAL reads the .RPB).
Needs rasterio (`pip install rasterio`, GDAL inside). Usage: gdal_ortho.py IMAGE DSM OUT"""
import sys, time
import numpy as np, rasterio
from rasterio.warp import reproject, Resampling
img, dsm, out = sys.argv[1:4]
t = time.time()
with rasterio.open(img) as src, rasterio.open(dsm) as d:
    dst = np.zeros((src.count, d.height, d.width), np.uint8)
    reproject(rasterio.band(src, list(range(1, src.count + 1))), dst, rpcs=src.rpcs,
              dst_transform=d.transform, dst_crs=d.crs, resampling=Resampling.bilinear,
              RPC_DEM=dsm, num_threads=2)
    prof = d.profile | {"count": src.count, "dtype": "uint8", "nodata": 0}
with rasterio.open(out, "w", **prof) as o:
    o.write(dst)
print(f"{time.time() - t:.2f} s")
