"""``reconstruct_many`` from Python: the command line's fused DSM byte for byte, a dry run that
only chooses, and its refusals."""

import filecmp
import json

import pytest

import seasonstereo
from conftest import run_cli

# Four dev dates, two pairs: a fused DSM in well under a minute.
DATES = ("013", "014", "015", "020")


def test_reconstruct_many_writes_the_command_line_s_dsm(dev, cli, tmp_path):
    images = [dev / "images" / f"JAX_068_{d}_RGB.tif" for d in DATES]
    rpcs, truth = dev / "rpcs" / "ba", dev / "truth" / "JAX_068_DSM.tif"
    run_cli(cli, "reconstruct-many", *images, "--rpc-dir", rpcs, "--pairs", 2, "--like", truth,
            "-o", tmp_path / "cli" / "dsm.tif")
    s = seasonstereo.reconstruct_many(images, rpcs, out=tmp_path / "py" / "dsm.tif", pairs=2,
                                      like=truth)
    for name in ("dsm.tif", "dsm_confidence.tif"):
        assert filecmp.cmp(tmp_path / "cli" / name, tmp_path / "py" / name, shallow=False)
    assert len(s["chosen"]) == 2 and all("score" in c["terms"] for c in s["chosen"])
    assert [p["status"] for p in s["pairs"]] == ["done", "done"] and s["warnings"] == []
    assert s["fused"]["crs"] == "EPSG:32617" and s["fused"]["measured_cells"] > 0
    with pytest.raises(FileExistsError, match="already exists"):
        seasonstereo.reconstruct_many(images, rpcs, out=tmp_path / "cli" / "dsm.tif", pairs=2,
                                      like=truth, work=tmp_path / "elsewhere")


def test_a_dry_run_chooses_and_writes_nothing(dev, tmp_path):
    images = [dev / "images" / f"JAX_068_{d}_RGB.tif" for d in DATES]
    s = seasonstereo.reconstruct_many(images, dev / "rpcs" / "ba", out=tmp_path / "dsm.tif",
                                      pairs=2, dry_run=True)
    assert len(s["chosen"]) == 2 and s["pairs"] == [] and s["fused"] is None
    assert list(tmp_path.iterdir()) == []


def test_one_image_is_refused(dev, tmp_path):
    with pytest.raises(ValueError):
        seasonstereo.reconstruct_many([dev / "images" / "JAX_068_013_RGB.tif"],
                                      dev / "rpcs" / "ba", out=tmp_path / "dsm.tif")


def test_shards_then_the_unsharded_call_give_one_call_s_dsm(dev, tmp_path):
    images = [dev / "images" / f"JAX_068_{d}_RGB.tif" for d in DATES]
    rpcs = dev / "rpcs" / "ba"
    seasonstereo.reconstruct_many(images, rpcs, out=tmp_path / "one" / "dsm.tif", pairs=2)
    work = tmp_path / "shared_work"
    for i in range(2):
        s = seasonstereo.reconstruct_many(images, rpcs, out=tmp_path / "sharded" / "dsm.tif",
                                          pairs=2, work=work, shard=f"{i}/2")
        assert s["shard"] == f"{i}/2" and s["fused"] is None
        assert all(p["status"] == "tiles" for p in s["pairs"])
    assert not (tmp_path / "sharded" / "dsm.tif").exists()
    s = seasonstereo.reconstruct_many(images, rpcs, out=tmp_path / "sharded" / "dsm.tif",
                                      pairs=2, work=work)
    assert s["shard"] is None and s["fused"] is not None
    assert filecmp.cmp(tmp_path / "one" / "dsm.tif", tmp_path / "sharded" / "dsm.tif",
                       shallow=False)


def test_a_vendor_delivery_needs_no_camera_and_gives_its_corrected_cameras(dev, tmp_path):
    # Plain TIFFs with .RPB cameras and .IMD metadata beside them, nothing else.
    images = [dev / "vendor" / f"JAX_068_{d}_RGB.TIF" for d in DATES]
    truth = dev / "truth" / "JAX_068_DSM.tif"
    s = seasonstereo.reconstruct_many(images, out=tmp_path / "dsm.tif", pairs=2, like=truth,
                                      truth=truth, ortho=tmp_path / "ortho.tif",
                                      points=tmp_path / "points.las")
    assert [p["status"] for p in s["pairs"]] == ["done", "done"]
    assert all(v["date"] for v in s["views"]), "dates from the .IMD files"
    assert sorted(s["cameras"]) == [f"JAX_068_{d}_RGB" for d in DATES]
    for stem, rpc in s["cameras"].items():
        assert len(rpc["row_num"]) == 20 and rpc["alt_scale"] > 0
        # The same camera as the file the run wrote, which `reconstruct` takes as it is.
        written = json.loads((tmp_path / "dsm_work" / "cameras" / f"{stem}.json").read_text())
        assert written["rpc"] == rpc and written["min_alt"] < written["max_alt"]
    fits = s["pointing"]["images"]
    assert all(f["rms_px"] < 1.2 for f in fits)
    lo, hi = s["pointing"]["alt_range"]
    assert -60 < lo < -20 and 25 < hi < 70
    assert s["scores"]["mae_filtered"] < 1.2
    # The products, as GDAL (rasterio) and laspy read them: the orthoimage on the DSM's grid,
    # the DSM saying what its heights are, the point cloud with its count, CRS and colours.
    rasterio = pytest.importorskip("rasterio")
    laspy = pytest.importorskip("laspy")
    with rasterio.open(tmp_path / "dsm.tif") as dsm, rasterio.open(tmp_path / "ortho.tif") as o:
        assert (o.crs, o.transform, o.shape) == (dsm.crs, dsm.transform, dsm.shape)
        assert o.count == 3 and o.dtypes == ("uint8",) * 3 and o.nodata == 0
        assert dsm.descriptions == ("height above the WGS84 ellipsoid",)
        assert dsm.units == ("metre",)
        assert "EPSG:4979" in dsm.tags()["VERTICAL_REFERENCE"]
        heights, counts = dsm.read(1), rasterio.open(tmp_path / "dsm_count.tif").read(1)
        rgb = o.read()
    measured = int(((heights == heights) & (counts > 0)).sum())
    assert s["products"]["points"] == measured
    cloud = laspy.read(tmp_path / "points.las")
    assert len(cloud.points) == measured
    keys = next(v for v in cloud.header.vlrs if v.record_id == 34735).geo_keys
    assert any(k.id == 3072 and k.value_offset == 32617 for k in keys)
    coloured = (cloud.red > 0) | (cloud.green > 0) | (cloud.blue > 0)
    assert coloured.mean() > 0.99 and (rgb.sum(axis=0) > 0).mean() > 0.5
