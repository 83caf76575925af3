"""Shared fixtures: the data root found as the Rust tests find it (``crates/testdata``), the
command-line binary the Python results are compared with, and a rectified dev pair.

The data root is ``SEASONSTEREO_DATA`` (relative to the repository root) when set and not empty,
else ``../shared`` beside the repository. An absent set skips the test with one line, or fails
it under ``SEASONSTEREO_REQUIRE_DATA=1`` (as CI sets it), so a run with the data never skips
silently. The binary is ``SEASONSTEREO_CLI``, else the newest of ``target/release`` and
``target/debug`` (``cargo build``; CI's ``cargo test`` builds the debug one).
"""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parents[2]
DEV = "data/dfc2019-jax068-dev"
DEV_WHAT = ("ten DFC2019 WorldView-3 crops of JAX_068 with RPCs, LiDAR truth and s2p DSMs, from "
            "DFC2019 Track 3 on IEEE DataPort, SatNeRF's layout; README inside")
# The synchronic dev pair of the tests (12 days apart) and its bundle-adjusted cameras.
PAIR = ("014", "015")


def _required() -> bool:
    value = os.environ.get("SEASONSTEREO_REQUIRE_DATA", "")
    return value not in ("", "0")


def _absent(what: str) -> None:
    """Skips (or fails under SEASONSTEREO_REQUIRE_DATA) for want of ``what``."""
    if _required():
        pytest.fail(f"missing {what}: SEASONSTEREO_REQUIRE_DATA is set, so an absent input fails")
    pytest.skip(what)


def data_root() -> Path:
    var = os.environ.get("SEASONSTEREO_DATA", "")
    return REPOSITORY / var if var else REPOSITORY / "../shared"


@pytest.fixture(scope="session")
def dev() -> Path:
    """The DFC2019 JAX_068 development set."""
    folder = data_root() / DEV
    if not folder.is_dir():
        _absent(f"skipped: needs {DEV} ({DEV_WHAT}; set SEASONSTEREO_DATA)")
    return folder


@pytest.fixture(scope="session")
def cli() -> Path:
    """The ``seasonstereo`` binary built from this checkout."""
    given = os.environ.get("SEASONSTEREO_CLI")
    candidates = [Path(given)] if given else [
        REPOSITORY / "target" / profile / "seasonstereo" for profile in ("release", "debug")]
    found = [c for c in candidates if c.is_file()]
    if not found:
        _absent("skipped: needs the seasonstereo binary (cargo build; or set SEASONSTEREO_CLI)")
    return max(found, key=lambda c: c.stat().st_mtime)


def run_cli(cli: Path, *args: object) -> str:
    """Runs the binary; its stdout, or a failure with its stderr."""
    done = subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True)
    assert done.returncode == 0, f"seasonstereo {' '.join(map(str, args))}: {done.stderr}"
    return done.stdout


def images(dev: Path, pair=PAIR) -> list:
    """The raw images and bundle-adjusted cameras of ``pair``: left, right, rpc_left, rpc_right."""
    names = [f"JAX_068_{i}_RGB" for i in pair]
    return ([dev / "images" / f"{n}.tif" for n in names]
            + [dev / "rpcs" / "ba" / f"{n}.json" for n in names])


@pytest.fixture(scope="session")
def rectified(dev: Path, cli: Path, tmp_path_factory) -> dict:
    """The dev pair rectified by the command line: its record (paths, disparity range)."""
    out = tmp_path_factory.mktemp("rectified")
    left, right, rpc_left, rpc_right = images(dev)
    said = run_cli(cli, "rectify", left, right, "-o", out, "--rpc-left", rpc_left,
                   "--rpc-right", rpc_right, "--stem", "pair")
    lo, hi = re.search(r"disparity range (-?\d+):(-?\d+) px", said).groups()
    return {"folder": out, "range": (int(lo), int(hi)), "left": out / "L" / "pair.iio",
            "right": out / "R" / "pair.iio", "homography": out / "homography" / "pair.npz"}
