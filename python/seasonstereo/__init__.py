"""Dense stereo of multi-date satellite images: disparity maps and DSMs from numpy arrays and
GeoTIFFs, by the same Rust library as the ``seasonstereo`` command line (same values, same
messages).

Conventions: rectified pairs have epipolar lines as rows; a disparity lives on the left view,
``x_R = x_L - d``, NaN where invalid. DSMs are float32 GeoTIFFs on a UTM grid, NaN where no
point fell; in Python a :class:`Dsm` ``(array, transform, crs)`` with ``transform`` in rasterio's
order (``rasterio.Affine(*dsm.transform)``) and ``crs`` like ``"EPSG:32617"``.

Cameras (``rpc_left``, ``rpc_right``) are a path to the product's SatNeRF/rpcm JSON, a GeoTIFF
carrying its RPC tag, or an rpcm-format dict (the bare ``rpc`` dictionary or a whole SatNeRF
JSON). Errors are ``FileNotFoundError`` (naming the file), ``FileExistsError`` (an existing
output without ``overwrite=True``, as the command line's ``--overwrite``), ``OSError``,
``ValueError`` (bad values), ``TypeError`` (unknown options) or :class:`NothingProduced` (a run
whose every tile or pair failed: the command line's exit code 3). A partial run (some tiles or
pairs failed: exit code 2) returns, names them and issues a ``UserWarning``. Every call releases the GIL while it computes, so
threads run in parallel; ``progress`` takes a callable ``progress(label, done, total)``, or
``True`` for tqdm bars when tqdm is installed.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import warnings
from typing import Any, Callable, Iterator, NamedTuple, Optional, Tuple, Union

import numpy as np

from . import _seasonstereo as _native

__version__: str = _native.__version__
NothingProduced = _native.NothingProduced
NothingProduced.__module__ = __name__
__all__ = ["Dsm", "NothingProduced", "predict", "rectify", "dsm", "read_dsm", "score",
           "reconstruct", "reconstruct_many", "__version__"]

PathLike = Union[str, "os.PathLike[str]"]
Camera = Union[PathLike, dict]
Progress = Union[None, bool, Callable[[str, int, int], Any]]


class Dsm(NamedTuple):
    """A DSM: heights in metres (H×W float32, NaN = no data), the affine transform in rasterio's
    order ``(a, b, c, d, e, f)`` (x = a·col + b·row + c, y = d·col + e·row + f, at the cells'
    outer corners) and the CRS as an EPSG string."""

    array: np.ndarray
    transform: Tuple[float, float, float, float, float, float]
    crs: str

    @property
    def gdal_transform(self) -> Tuple[float, float, float, float, float, float]:
        """The transform in GDAL's order ``(c, a, b, f, d, e)`` (``GetGeoTransform``)."""
        a, b, c, d, e, f = self.transform
        return (c, a, b, f, d, e)


@contextlib.contextmanager
def _cameras(*cameras: Optional[Camera]) -> Iterator[list]:
    """The cameras as paths, then a scratch folder: dicts are written as JSON files for the
    call's duration (the library reads every camera from a file, as the command line does)."""
    with tempfile.TemporaryDirectory(prefix="seasonstereo-") as folder:
        paths: list = []
        for i, camera in enumerate(cameras):
            if isinstance(camera, dict):
                path = os.path.join(folder, f"camera{i}.json")
                with open(path, "w") as f:
                    json.dump(camera, f)
                camera = path
            paths.append(camera)
        yield paths + [folder]


def _progress(progress: Progress) -> Optional[Callable[[str, int, int], Any]]:
    """The callback of ``progress``: itself, or with ``True`` one tqdm bar per loop (none
    without tqdm: progress is a nicety, never a dependency)."""
    if progress is not True:
        return progress or None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    bar: list = [None]

    def update(label: str, done: int, total: int) -> None:
        if done == 0 or bar[0] is None:
            bar[0] = tqdm(total=total, desc=label, leave=False)
        bar[0].update(done - bar[0].n)
        if done >= total:
            bar[0].close()

    return update


def predict(left: np.ndarray, right: np.ndarray, disparity_range: Optional[Tuple[int, int]] = None,
            method: str = "mgm", *, progress: Progress = None, **options: Any) -> np.ndarray:
    """The disparity (H×W float32, NaN = invalid) of the rectified pair ``left``, ``right``
    (H×W or H×W×C arrays of float32, uint8 or uint16), as ``seasonstereo predict``: census +
    MGM (``method="mgm"``) or SGM over ``disparity_range`` (inclusive pixels; estimated from the
    images when None). Options: ``p1``, ``p2``, ``four_paths``, ``lr_tolerance``,
    ``p2_adaptive``, ``census`` ("WxH"), ``uniqueness``, ``speckle``, ``speckle_diff``; and
    ``threads``, this call's worker threads (default: every core, shared by all calls)."""
    return _native.predict(left, right, disparity_range, method, _progress(progress), **options)


def rectify(left: PathLike, right: PathLike, out: PathLike, *, rpc_left: Optional[Camera] = None,
            rpc_right: Optional[Camera] = None, progress: Progress = None,
            **options: Any) -> dict:
    """Rectifies a raw pair from its RPCs into the folder ``out`` (``L/``, ``R/``,
    ``homography/``, ``rectify/``), as ``seasonstereo rectify`` (an ``out`` that is one of the
    inputs is refused; its files are replaced). Options: ``roi`` (x, y, w, h),
    ``alt_range`` (min, max metres), ``stem``. Returns the paths written and the
    ``disparity_range`` for :func:`predict`."""
    with _cameras(rpc_left, rpc_right) as (l, r, _):
        return _native.rectify(left, right, out, rpc_left=l, rpc_right=r,
                               progress=_progress(progress), **options)


def dsm(disparity: Union[PathLike, np.ndarray], homography: PathLike, rpc_left: Camera,
        rpc_right: Camera, out: PathLike, *, overwrite: bool = False, **options: Any) -> Dsm:
    """Triangulates the disparity of a rectified pair (a file, or the array :func:`predict`
    gave) into the DSM GeoTIFF ``out`` and returns it, as ``seasonstereo dsm``; an existing
    ``out`` raises ``FileExistsError`` unless ``overwrite=True`` (then replaced atomically). Options:
    ``like`` (a DSM whose grid to use, e.g. the truth), ``resolution``, ``bounds``, ``epsg``,
    ``gridding`` ("max" or "median"), ``fill_holes``, ``median_filter``, ``border``."""
    with _cameras(rpc_left, rpc_right) as (l, r, scratch):
        if isinstance(disparity, np.ndarray):
            path = os.path.join(scratch, "disparity.npy")
            np.save(path, np.ascontiguousarray(disparity, dtype=np.float32))
            disparity = path
        return Dsm(*_native.dsm(disparity, homography, l, r, out, overwrite=overwrite,
                                **options))


def read_dsm(path: PathLike, utm_zone: Optional[str] = None) -> Dsm:
    """Reads a DSM GeoTIFF (or a DFC2019 plain TIFF with its ``.txt``; ``utm_zone`` like "17N"
    then names its zone)."""
    return Dsm(*_native.read_dsm(path, utm_zone))


def score(dsm: PathLike, truth: PathLike, utm_zone: Optional[str] = None) -> dict:
    """The benchmark's scores of a DSM file against ``truth`` (``<AOI>_DSM.tif``, its
    ``_CLS.tif`` beside it), as ``seasonstereo score``; a DSM on its own grid (s2p's, say) is
    cut onto the truth's as the benchmark crops it (nearest cell, NaN outside): ``mae_filtered``
    (the benchmark's number), ``mae_raw``, ``mae_no_water``, ``coverage``, ``dx``, ``dy``,
    ``offset``, ..."""
    return _native.score(dsm, truth, utm_zone)


def reconstruct(left: PathLike, right: PathLike, *, out: PathLike,
                rpc_left: Optional[Camera] = None, rpc_right: Optional[Camera] = None,
                method: str = "mgm", overwrite: bool = False, progress: Progress = None,
                **options: Any) -> dict:
    """From a raw pair to the DSM GeoTIFF ``out``, tile by tile, as ``seasonstereo
    reconstruct`` with the same options and defaults (underscores for dashes): ``like``,
    ``truth``, ``resolution``, ``epsg``, ``gridding``, ``fill_holes``, ``fill_reach``,
    ``median_filter``, ``roi``, ``roi_lonlat``, ``alt_range``, ``tile``, ``collar``, ``max_memory`` (GiB),
    ``work``, ``shard`` ("I/N"), ``merge``, ``keep_intermediates``, ``single_view``, ``threads`` (this call's
    worker threads; default every core) and the matcher's options of :func:`predict`. Returns the tiles (``failed`` ones included: the DSM holds the others),
    the DSM's grid and coverage, ``scores`` (with ``truth``), each step's ``seconds`` and the
    ``warnings`` the command prints (also issued as Python warnings).

    An existing ``out`` raises ``FileExistsError`` (the command line's message) unless
    ``overwrite=True`` or it is the DSM of an earlier run of the same ``work`` folder (resumed).
    When every tile failed, nothing is written and :class:`NothingProduced` is raised; when only
    some failed, the call returns with them in ``tiles["failed"]`` and a warning."""
    with _cameras(rpc_left, rpc_right) as (l, r, _):
        summary = _native.reconstruct(left, right, out=out, method=method, overwrite=overwrite,
                                      progress=_progress(progress),
                                      rpc_left=l, rpc_right=r, **options)
    for line in summary["warnings"]:
        warnings.warn(line, stacklevel=2)
    return summary


def reconstruct_many(images: "list[PathLike]", rpc_dir: Optional[PathLike] = None, *,
                     out: PathLike, method: str = "mgm", overwrite: bool = False,
                     progress: Progress = None, **options: Any) -> dict:
    """Many dates, one DSM, as ``seasonstereo reconstruct-many``: scores every overlapping pair
    of ``images`` (two or more; cameras ``<image stem>.json`` in ``rpc_dir``, else the images'
    RPC tags), reconstructs the best ``pairs`` and fuses them into ``out`` (with
    ``<out>_count.tif``, ``<out>_spread.tif``, ``<out>_confidence.tif`` and
    ``<out>_report.json`` beside it). Options, with the command's defaults: ``pairs``,
    ``dry_run`` (choose the pairs, write nothing), ``cluster_tolerance``, ``min_support``,
    ``min_confidence``, ``register``, ``pair_weights``, ``fill_holes``,
    ``median_filter``, ``pair_median_filter``, ``single_view``, ``work``, ``shard`` (``"I/N"``:
    only this task's share of the pairs' tiles, no fusion; the call without it fuses), ``like``,
    ``resolution``, ``epsg``,
    ``truth``,
    ``alt_range``, ``gridding``, ``tile``, ``collar``, ``max_memory`` (GiB), ``threads`` (this
    call's worker threads; default every core) and the matcher's options of :func:`predict`.

    Returns the report's content: ``views``, ``candidates``, ``chosen`` (pairs with their score
    ``terms``), ``pairs`` (each pair's status, DSM, coverage, scores, agreement with the
    equal-weight fusion and weight in the fusion, seconds), ``fused`` (files,
    grid with ``transform`` and ``crs``, coverage; None on a dry run), ``scores``, ``seconds``
    and ``warnings`` (incomplete pairs, also issued as Python warnings). Fewer than two images
    raise ``ValueError``; existing outputs ``FileExistsError`` unless ``overwrite=True`` (or an
    earlier run of the same work folder is resumed); no pair producing a DSM
    :class:`NothingProduced`."""
    summary = _native.reconstruct_many([os.fspath(i) for i in images], rpc_dir, out=out,
                                       method=method, overwrite=overwrite,
                                       progress=_progress(progress), **options)
    for line in summary["warnings"]:
        warnings.warn(line, stacklevel=2)
    return summary
