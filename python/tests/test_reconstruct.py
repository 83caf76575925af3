"""``reconstruct`` from Python writes the command line's DSM byte for byte (on one thread of its
own as on every core), with its scores."""

import filecmp

import pytest

import seasonstereo
from conftest import images, run_cli

# Scores of the dev pair's DSM (defaults: right image sheared, MGM, median gridding, holes filled
# up to 16 cells from a measurement, median filter) against the LiDAR truth (filled without that
# limit: 1.41136 m, 0.91959; before the shear: 1.42155 m, 0.91180).
SCORES = {"mae_filtered": 1.34551, "coverage": 0.91523}


def test_reconstruct_writes_the_command_line_s_dsm(dev, cli, tmp_path):
    left, right, rpc_left, rpc_right = images(dev)
    truth = dev / "truth" / "JAX_068_DSM.tif"
    said = run_cli(cli, "reconstruct", left, right, "--rpc-left", rpc_left, "--rpc-right", rpc_right,
            "--like", truth, "--truth", truth, "-o", tmp_path / "cli.tif")
    calls = []
    s = seasonstereo.reconstruct(left, right, rpc_left=rpc_left, rpc_right=rpc_right,
                                 like=truth, truth=truth, out=tmp_path / "py.tif", threads=1,
                                 progress=lambda *c: calls.append(c))
    assert filecmp.cmp(tmp_path / "cli.tif", tmp_path / "py.tif", shallow=False)
    assert s["output"] == str(tmp_path / "py.tif") and s["tiles"]["failed"] == []
    assert s["warnings"] == []
    assert s["dsm"]["crs"] == "EPSG:32617" and s["dsm"]["width"] == 512
    assert set(s["seconds"]) == {"tiles", "merge"} and calls
    assert f"MAE filtered {s['scores']['mae_filtered']:.3f} m" in said
    for key, value in SCORES.items():
        assert s["scores"][key] == pytest.approx(value, abs=1e-5), key



def test_single_view_is_the_command_line_s_and_changes_a_very_narrow_pair(dev, cli, tmp_path):
    # 014-020 (0.20 px of disparity per metre of altitude) is measured from both views by
    # default; single_view=True is the command line's --single-view.
    left, right, rpc_left, rpc_right = images(dev, ("014", "020"))
    truth = dev / "truth" / "JAX_068_DSM.tif"
    run_cli(cli, "reconstruct", left, right, "--rpc-left", rpc_left, "--rpc-right", rpc_right,
            "--like", truth, "--single-view", "-o", tmp_path / "cli.tif")
    common = dict(rpc_left=rpc_left, rpc_right=rpc_right, like=truth, truth=truth)
    one = seasonstereo.reconstruct(left, right, out=tmp_path / "one.tif", single_view=True,
                                   **common)
    both = seasonstereo.reconstruct(left, right, out=tmp_path / "both.tif", **common)
    assert filecmp.cmp(tmp_path / "cli.tif", tmp_path / "one.tif", shallow=False)
    assert not filecmp.cmp(tmp_path / "one.tif", tmp_path / "both.tif", shallow=False)
    assert both["scores"]["mae_filtered"] < one["scores"]["mae_filtered"] - 0.04
