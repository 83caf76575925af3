"""The steps on files: ``rectify``, ``dsm``, ``read_dsm`` and ``score`` write and read what the
command line does, and score the dev truth as known."""

import filecmp
import json

import numpy as np
import pytest

import seasonstereo
from conftest import PAIR, images, run_cli

# The s2p DSM of the dev pair on the truth's grid, scored by the benchmark's metric.
S2P_SCORES = {"mae_filtered": 1.32371, "mae_raw": 1.32761, "coverage": 0.71023}


def truth_of(dev):
    return dev / "truth" / "JAX_068_DSM.tif"


def test_rectify_writes_what_the_command_line_writes(dev, rectified, tmp_path):
    left, right, rpc_left, rpc_right = images(dev)
    # One camera as a path, the other as an rpcm dict: the same rectification.
    rpc_right = json.loads(rpc_right.read_text())
    s = seasonstereo.rectify(left, right, tmp_path, rpc_left=rpc_left, rpc_right=rpc_right,
                             stem="pair")
    assert tuple(s["disparity_range"]) == rectified["range"]
    for key in ("left", "right", "homography"):
        assert filecmp.cmp(s[key], rectified[key], shallow=False), key


def test_a_camera_can_be_a_geotiff_carrying_the_rpc_tag(dev, cli, tmp_path):
    """The dev images carry their original RPCs in tag 50844: given as the camera files, they
    rectify exactly as the command line does reading each image's own tag."""
    left, right, _, _ = images(dev)
    said = run_cli(cli, "rectify", left, right, "-o", tmp_path / "cli", "--stem", "pair",
                   "--alt-range=-27:30")
    s = seasonstereo.rectify(left, right, tmp_path / "py", rpc_left=left, rpc_right=right,
                             stem="pair", alt_range=(-27, 30))
    assert f"disparity range {s['disparity_range'][0]}:{s['disparity_range'][1]} px" in said
    for folder, suffix in (("L", "iio"), ("R", "iio"), ("homography", "npz")):
        assert filecmp.cmp(tmp_path / "cli" / folder / f"pair.{suffix}",
                           tmp_path / "py" / folder / f"pair.{suffix}", shallow=False), folder


def test_dsm_writes_what_the_command_line_writes(dev, cli, rectified, tmp_path):
    _, _, rpc_left, rpc_right = images(dev)
    lo, hi = rectified["range"]
    disparity = tmp_path / "d.npy"
    run_cli(cli, "predict", rectified["left"], rectified["right"], "-o", disparity,
            "--range", f"{lo}:{hi}")
    grid = ["--like", truth_of(dev)]
    run_cli(cli, "dsm", disparity, "--homography", rectified["homography"], "--rpc-left",
            rpc_left, "--rpc-right", rpc_right, "-o", tmp_path / "cli.tif", *grid)
    dsm = seasonstereo.dsm(disparity, rectified["homography"], rpc_left, rpc_right,
                           tmp_path / "py.tif", like=truth_of(dev))
    assert filecmp.cmp(tmp_path / "cli.tif", tmp_path / "py.tif", shallow=False)
    # From the array predict gives, the same DSM.
    array = seasonstereo.predict(np.load(rectified["left"]), np.load(rectified["right"]), (lo, hi))
    again = seasonstereo.dsm(array, rectified["homography"], rpc_left, rpc_right,
                             tmp_path / "again.tif", like=truth_of(dev))
    assert np.array_equal(again.array, dsm.array, equal_nan=True)
    check_truth_grid(dev, dsm)


def check_truth_grid(dev, dsm):
    """The DSM lies on the truth's grid: 512×512 cells of 0.5 m, UTM 17N, upper-left corner
    from the DFC2019 georeference (lower-left E N, size, resolution)."""
    e, n, size, res = map(float, (dev / "truth" / "JAX_068_DSM.txt").read_text().split())
    assert dsm.array.shape == (512, 512) and dsm.array.dtype == np.float32
    assert dsm.crs == "EPSG:32617"
    assert dsm.transform == pytest.approx((res, 0, e, 0, -res, n + size * res))
    assert dsm.gdal_transform == pytest.approx((e, res, 0, n + size * res, 0, -res))
    assert 0.5 < np.isfinite(dsm.array).mean() <= 1


def test_read_dsm_reads_the_dfc_truth_with_its_zone(dev):
    truth = seasonstereo.read_dsm(truth_of(dev), utm_zone="17N")
    assert truth.array.shape == (512, 512) and truth.crs == "EPSG:32617"
    with pytest.raises(ValueError, match="UTM zone"):
        seasonstereo.read_dsm(truth_of(dev))


def test_score_on_the_dev_truth_is_the_command_line_s(dev, cli, tmp_path):
    s2p = dev / "s2p" / "truth-grid" / f"{PAIR[0]}-{PAIR[1]}.tif"
    scores = seasonstereo.score(s2p, truth_of(dev))
    run_cli(cli, "score", s2p, "--truth", truth_of(dev), "--json", tmp_path / "s.json")
    expected = json.loads((tmp_path / "s.json").read_text())
    expected.pop("dsm")
    assert scores == expected
    print({k: scores[k] for k in S2P_SCORES})
    for key, value in S2P_SCORES.items():
        assert scores[key] == pytest.approx(value, abs=1e-5), key
    # s2p's DSM as s2p wrote it, on its own grid, is cut onto the truth's: the same scores.
    assert seasonstereo.score(dev / "s2p" / f"{PAIR[0]}-{PAIR[1]}.tif", truth_of(dev)) == scores
