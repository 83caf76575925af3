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
pairs failed: exit code 2) returns, names them and issues a ``UserWarning``. Messages are one
line and name Python's types, never the library's; a bug inside the library raises a one-line
``RuntimeError`` ("internal error"), nothing is printed. Every call releases the GIL while it
computes, so threads run in parallel.

``progress`` takes a function ``progress(stage, done, total)``: ``stage`` a short string naming
what runs ("selecting pairs", "matching pair 3/12", "tiles (2 at once)", "fusing", ...),
``done`` and ``total`` one count of steps (rows, tiles, blocks) over the whole call: neither
ever goes back, ``total`` grows when a stage whose size was unknown starts (for
:func:`reconstruct_many`, the pairs × their tiles, then the fusion's blocks) and ``done``
reaches it when the call returns. It is called when the stage changes or the count gains a
whole percent, from the library's threads. ``True`` shows one tqdm bar when tqdm is installed,
else plain lines on stderr (one per stage and every 10 %); ``None`` or ``False``, nothing.
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import sys
import tempfile
import warnings
from typing import Any, Callable, Iterable, Iterator, NamedTuple, Optional, Tuple, Union

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


@contextlib.contextmanager
def _reporting(progress: Progress) -> Iterator[Optional[Callable[[str, int, int], Any]]]:
    """The callback of ``progress`` for one call: itself; with ``True`` one tqdm bar over the
    whole call, or without tqdm plain lines on stderr (one per stage and every 10 %)."""
    if progress is None or progress is False:
        yield None
        return
    if progress is not True:
        if not callable(progress):
            raise TypeError("progress is a function progress(stage, done, total), True or "
                            f"None, got {type(progress).__name__}")
        yield progress
        return
    try:
        from tqdm import tqdm
    except ImportError:
        tqdm = None
    bar: list = [None]
    last: list = [None, -1]

    def update(stage: str, done: int, total: int) -> None:
        if tqdm is not None:
            if bar[0] is None:
                bar[0] = tqdm(total=total, desc=stage, unit="step", leave=False)
            bar[0].total = total
            bar[0].set_description(stage, refresh=False)
            bar[0].update(done - bar[0].n)
            return
        tenth = 10 * done // max(total, 1)
        if stage != last[0] or tenth > last[1]:
            last[0], last[1] = stage, tenth
            print(f"seasonstereo: {stage}: {done}/{total} ({100 * done // max(total, 1)} %)",
                  file=sys.stderr, flush=True)

    try:
        yield update
    finally:
        if bar[0] is not None:
            bar[0].close()


_IMAGE_TYPES = (np.float32, np.uint8, np.uint16)


def _image(name: str, image: Any) -> np.ndarray:
    """``image`` as an array the library takes: float32, uint8 and uint16 as they are, other
    real numbers (float64, numpy's default, and integers) as float32."""
    if not isinstance(image, np.ndarray):
        raise TypeError(f"{name} is a numpy array (H×W or H×W×C), got {type(image).__name__}")
    if image.dtype in _IMAGE_TYPES:
        return image
    if image.dtype.kind not in "biuf":
        raise TypeError(f"{name} is a numpy array of real numbers (float32, uint8 or uint16; "
                        f"others are converted to float32), got {image.dtype}")
    return image.astype(np.float32)


def _text(name: str, value: Any) -> str:
    """``value``, a ``TypeError`` naming ``name`` unless it is a string."""
    if not isinstance(value, str):
        raise TypeError(f"{name} is a string, got {type(value).__name__}")
    return value


def _images(images: Any) -> list:
    """The images of :func:`reconstruct_many` as a list of paths: a list (or other iterable) of
    paths as it is, one path as a list of it, a glob pattern (``*``, ``?``, ``[``; not an
    existing file's name) as the files it matches, sorted."""
    if isinstance(images, (str, os.PathLike)):
        path = os.fspath(images)
        if not isinstance(path, str):
            raise TypeError(f"images: a path is a str or os.PathLike of str, got {path!r}")
        if os.path.exists(path) or not any(c in path for c in "*?["):
            return [path]
        found = sorted(glob.glob(path))
        if not found:
            raise ValueError(f"images: no file matches the pattern {path!r}")
        return found
    if isinstance(images, (bytes, dict)) or not hasattr(images, "__iter__"):
        raise TypeError("images is a list of paths (str or os.PathLike), one path or a glob "
                        f"pattern, got {type(images).__name__}")
    paths = []
    for i, image in enumerate(images):
        if not isinstance(image, (str, os.PathLike)):
            raise TypeError(f"images[{i}] is a path (str or os.PathLike), got "
                            f"{type(image).__name__}")
        path = os.fspath(image)
        if not isinstance(path, str):
            raise TypeError(f"images[{i}]: a path is a str or os.PathLike of str, got {path!r}")
        paths.append(path)
    return paths


def predict(left: np.ndarray, right: np.ndarray, disparity_range: Optional[Tuple[int, int]] = None,
            method: str = "mgm", *, progress: Progress = None, **options: Any) -> np.ndarray:
    """The disparity (H×W float32, NaN = invalid) of the rectified pair ``left``, ``right``
    (H×W or H×W×C numpy arrays: float32, uint8 and uint16 as they are, other real numbers,
    float64 and integers, converted to float32; NaN = no data, as :func:`rectify` writes
    outside the views, infinite values are refused with ``ValueError``), as ``seasonstereo predict``: census + MGM (``method="mgm"``) or SGM over
    ``disparity_range`` (inclusive pixels; estimated from the images when None). Options:
    ``p1``, ``p2``, ``four_paths``, ``lr_tolerance``, ``p2_adaptive``, ``census`` ("WxH"),
    ``uniqueness``, ``speckle``, ``speckle_diff``; ``threads``, this call's worker threads
    (default: every core, shared by all calls); ``max_memory`` (GiB, default 16): a pair whose
    matching would need more is refused with ``ValueError`` before anything is allocated.
    ``progress``: see the module's help."""
    left, right = _image("left", left), _image("right", right)
    _text("method", method)
    if disparity_range is not None:
        if (isinstance(disparity_range, (str, bytes)) or not hasattr(disparity_range, "__len__")
                or len(disparity_range) != 2
                or not all(isinstance(d, (int, np.integer)) for d in disparity_range)):
            raise TypeError("disparity_range is None or (min, max), two integers, got "
                            f"{disparity_range!r}")
        if not all(-2**31 <= d < 2**31 for d in disparity_range):
            raise ValueError(f"disparity_range {tuple(disparity_range)} is beyond ±2³¹ pixels")
    with _reporting(progress) as callback:
        return _native.predict(left, right, disparity_range, method, callback, **options)


def rectify(left: PathLike, right: PathLike, out: PathLike, *, rpc_left: Optional[Camera] = None,
            rpc_right: Optional[Camera] = None, progress: Progress = None,
            **options: Any) -> dict:
    """Rectifies a raw pair from its RPCs into the folder ``out`` (``L/``, ``R/``,
    ``homography/``, ``rectify/``), as ``seasonstereo rectify`` (an ``out`` that is one of the
    inputs is refused; its files are replaced). Options: ``roi`` (x, y, w, h),
    ``alt_range`` (min, max metres), ``stem``. Returns the paths written and the
    ``disparity_range`` for :func:`predict`."""
    with _cameras(rpc_left, rpc_right) as (l, r, _):
        with _reporting(progress) as callback:
            return _native.rectify(left, right, out, rpc_left=l, rpc_right=r,
                                   progress=callback, **options)


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
    ``work``, ``shard`` ("I/N"), ``merge``, ``keep_intermediates``, ``single_view``,
    ``no_pointing_correction``, ``threads`` (this call's
    worker threads; default every core), the products beside the DSM (``ortho``: a true
    orthoimage GeoTIFF on its grid; ``ortho_blend``: ``"nadir"`` or ``"median"``; ``points``: a
    ``.las``/``.laz``/``.ply`` point cloud of the measured cells; ``preview``: a PNG quicklook),
    ``heights`` (``"ellipsoid"``, the default: above the WGS84 ellipsoid; ``"egm96"``: above the
    EGM96 geoid) and the matcher's options of :func:`predict`. ``epsg`` takes any projected or
    geographic code (e.g. 4326, 3857). Without
    ``rpc_left``/``rpc_right`` each image's camera is found beside it as the command finds it (a
    vendor ``.RPB``, ``_RPC.TXT``, DIMAP ``RPC_*.XML``, else the TIFF's RPC tag), so a vendor
    delivery needs no camera argument. Returns the tiles (``failed`` ones included: the DSM holds the others),
    the DSM's grid and coverage, ``scores`` (with ``truth``), each step's ``seconds``,
    ``pointing`` (the right camera's correction and residual per image, the tie points'
    altitudes; None with ``no_pointing_correction``), ``products`` (points written, seconds;
    None without products) and the ``warnings`` the command prints (also issued as Python warnings).

    An existing ``out`` raises ``FileExistsError`` (the command line's message) unless
    ``overwrite=True`` or it is the DSM of an earlier run of the same ``work`` folder (resumed).
    When every tile failed, nothing is written and :class:`NothingProduced` is raised; when only
    some failed, the call returns with them in ``tiles["failed"]`` and a warning."""
    _text("method", method)
    with _cameras(rpc_left, rpc_right) as (l, r, _), _reporting(progress) as callback:
        summary = _native.reconstruct(left, right, out=out, method=method, overwrite=overwrite,
                                      progress=callback, rpc_left=l, rpc_right=r, **options)
    for line in summary["warnings"]:
        warnings.warn(line, stacklevel=2)
    return summary


def reconstruct_many(images: "Union[PathLike, Iterable[PathLike]]", rpc_dir: Optional[PathLike] = None, *,
                     out: PathLike, method: str = "mgm", overwrite: bool = False,
                     progress: Progress = None, **options: Any) -> dict:
    """Many dates, one DSM, as ``seasonstereo reconstruct-many``: scores every overlapping pair
    of ``images`` (two or more; a list of paths, or a glob pattern such as
    ``"images/*.tif"``, expanded and sorted; cameras ``<image stem>.json`` in ``rpc_dir``, else
    found beside each image: a vendor delivery needs no camera argument), corrects every camera's
    pointing by one bundle adjustment (``no_pointing_correction=True`` skips it), reconstructs
    the best ``pairs`` and fuses them into ``out`` (with
    ``<out>_count.tif``, ``<out>_spread.tif``, ``<out>_confidence.tif`` and
    ``<out>_report.json`` beside it). Options, with the command's defaults: ``pairs``,
    ``dry_run`` (choose the pairs, write nothing), ``cluster_tolerance``, ``min_support``,
    ``min_confidence``, ``register``, ``pair_weights``, ``fill_holes``,
    ``median_filter``, ``pair_median_filter``, ``single_view``, ``work``, ``shard`` (``"I/N"``:
    only this task's share of the pairs' tiles, no fusion; the call without it fuses), ``like``,
    ``resolution``, ``epsg``,
    ``truth``,
    ``alt_range``, ``gridding``, ``tile``, ``collar``, ``max_memory`` (GiB), ``threads`` (this
    call's worker threads; default every core), the products ``ortho`` (from every image),
    ``ortho_blend``, ``points``, ``preview``, ``heights`` (as :func:`reconstruct`) and the matcher's options
    of :func:`predict`.

    Returns the report's content: ``views``, ``pointing`` (each image's correction and
    residuals, the pairs tied, the tie points' altitudes), ``cameras`` (the corrected cameras as
    rpcm dictionaries by image stem, also written as ``cameras/<stem>.json`` in the work folder),
    ``candidates``, ``chosen`` (pairs with their score
    ``terms``), ``pairs`` (each pair's status, DSM, coverage, scores, agreement with the
    equal-weight fusion and weight in the fusion, seconds), ``fused`` (files,
    grid with ``transform`` and ``crs``, coverage; None on a dry run), ``scores``, ``seconds``
    and ``warnings`` (incomplete pairs, also issued as Python warnings). Fewer than two images
    (an empty list, a pattern matching no file) raise ``ValueError``, anything but paths
    ``TypeError``; existing outputs ``FileExistsError`` unless ``overwrite=True`` (or an
    earlier run of the same work folder is resumed); no pair producing a DSM
    :class:`NothingProduced`."""
    images = _images(images)
    _text("method", method)
    with _reporting(progress) as callback:
        summary = _native.reconstruct_many(images, rpc_dir, out=out, method=method,
                                           overwrite=overwrite, progress=callback, **options)
    for line in summary["warnings"]:
        warnings.warn(line, stacklevel=2)
    return summary
