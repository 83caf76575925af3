"""Type stubs of the native module (Rust, PyO3); the documented API is the package's
``__init__``, which wraps these."""

import os
from typing import Any, Callable, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

_Path = Union[str, os.PathLike[str]]
# progress(stage, done, total): `stage` a short string ("matching pair 3/12", "fusing"), `done`
# and `total` one count over the whole call, neither going back (`total` grows when a stage of
# unknown size starts).
_Progress = Optional[Callable[[str, int, int], Any]]
_Transform = Tuple[float, float, float, float, float, float]
_Dsm = Tuple[npt.NDArray[np.float32], _Transform, str]

__version__: str

class NothingProduced(RuntimeError):
    """A run that produced nothing (every tile or pair failed): the command line's exit code 3."""

def predict(
    left: npt.NDArray[Union[np.float32, np.uint8, np.uint16]],
    right: npt.NDArray[Union[np.float32, np.uint8, np.uint16]],
    disparity_range: Optional[Tuple[int, int]] = None,
    method: str = "mgm",
    progress: _Progress = None,
    *,
    p1: Optional[int] = None,
    p2: Optional[int] = None,
    four_paths: Optional[bool] = None,
    lr_tolerance: Optional[float] = None,
    p2_adaptive: Optional[float] = None,
    census: Optional[str] = None,
    uniqueness: Optional[float] = None,
    speckle: Optional[int] = None,
    speckle_diff: Optional[float] = None,
    threads: Optional[int] = None,
    max_memory: Optional[float] = None,
) -> npt.NDArray[np.float32]: ...
def rectify(
    left: _Path,
    right: _Path,
    out: _Path,
    *,
    rpc_left: Optional[_Path] = None,
    rpc_right: Optional[_Path] = None,
    roi: Optional[Tuple[int, int, int, int]] = None,
    alt_range: Optional[Tuple[float, float]] = None,
    stem: Optional[str] = None,
    progress: _Progress = None,
) -> dict[str, Any]: ...
def dsm(
    disparity: _Path,
    homography: _Path,
    rpc_left: _Path,
    rpc_right: _Path,
    out: _Path,
    *,
    like: Optional[_Path] = None,
    resolution: float = 0.5,
    bounds: Optional[Tuple[float, float, float, float]] = None,
    epsg: Optional[int] = None,
    gridding: str = "max",
    fill_holes: int = 0,
    median_filter: int = 0,
    border: int = 0,
    overwrite: bool = False,
) -> _Dsm: ...
def read_dsm(path: _Path, utm_zone: Optional[str] = None) -> _Dsm: ...
def score(dsm: _Path, truth: _Path, utm_zone: Optional[str] = None) -> dict[str, Any]: ...
def reconstruct(
    left: _Path,
    right: _Path,
    *,
    out: _Path,
    method: str = "mgm",
    overwrite: bool = False,
    progress: _Progress = None,
    rpc_left: Optional[_Path] = None,
    rpc_right: Optional[_Path] = None,
    like: Optional[_Path] = None,
    truth: Optional[_Path] = None,
    resolution: Optional[float] = None,
    epsg: Optional[int] = None,
    gridding: Optional[str] = None,
    fill_holes: Optional[int] = None,
    fill_reach: Optional[int] = None,
    median_filter: Optional[int] = None,
    roi: Optional[Tuple[int, int, int, int]] = None,
    roi_lonlat: Optional[Tuple[float, float, float, float]] = None,
    alt_range: Optional[Tuple[float, float]] = None,
    tile: Optional[int] = None,
    collar: Optional[int] = None,
    max_memory: Optional[float] = None,
    work: Optional[_Path] = None,
    shard: Optional[str] = None,
    merge: Optional[bool] = None,
    keep_intermediates: Optional[bool] = None,
    single_view: Optional[bool] = None,
    threads: Optional[int] = None,
    **matcher: Any,
) -> dict[str, Any]: ...
def reconstruct_many(
    images: list[_Path],
    rpc_dir: Optional[_Path] = None,
    *,
    out: _Path,
    method: str = "mgm",
    overwrite: bool = False,
    progress: _Progress = None,
    pairs: Optional[int] = None,
    dry_run: Optional[bool] = None,
    cluster_tolerance: Optional[float] = None,
    min_support: Optional[int] = None,
    register: Optional[bool] = None,
    pair_weights: Optional[bool] = None,
    fill_holes: Optional[int] = None,
    median_filter: Optional[int] = None,
    pair_median_filter: Optional[int] = None,
    single_view: Optional[bool] = None,
    work: Optional[_Path] = None,
    like: Optional[_Path] = None,
    resolution: Optional[float] = None,
    epsg: Optional[int] = None,
    truth: Optional[_Path] = None,
    alt_range: Optional[Tuple[float, float]] = None,
    gridding: Optional[str] = None,
    tile: Optional[int] = None,
    collar: Optional[int] = None,
    max_memory: Optional[float] = None,
    threads: Optional[int] = None,
    **matcher: Any,
) -> dict[str, Any]: ...
