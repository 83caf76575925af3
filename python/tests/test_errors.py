"""Bad input raises the right exception type, with the command line's message: a missing file
is a ``FileNotFoundError`` naming it, a bad value a ``ValueError``, an unknown option a
``TypeError``; nothing panics across the boundary."""

import numpy as np
import pytest

import seasonstereo
from conftest import images

PAIR = np.zeros((40, 50), np.float32)


def test_a_missing_file_raises_file_not_found_naming_it(tmp_path):
    missing = tmp_path / "nowhere" / "JAX_068_999_RGB.tif"
    with pytest.raises(FileNotFoundError, match="JAX_068_999_RGB.tif"):
        seasonstereo.read_dsm(missing)
    with pytest.raises(FileNotFoundError, match="JAX_068_999_RGB.tif"):
        seasonstereo.rectify(missing, missing.with_name("b.tif"), tmp_path / "out")
    with pytest.raises(FileNotFoundError, match="JAX_068_999_RGB.tif"):
        seasonstereo.score(missing, tmp_path / "truth.tif")


def test_a_missing_image_of_reconstruct_raises_file_not_found(dev, tmp_path):
    _, right, rpc_left, rpc_right = images(dev)
    missing = tmp_path / "JAX_068_999_RGB.tif"
    with pytest.raises(FileNotFoundError, match="JAX_068_999_RGB.tif"):
        seasonstereo.reconstruct(missing, right, out=tmp_path / "dsm.tif", rpc_left=rpc_left,
                                 rpc_right=rpc_right)


@pytest.mark.parametrize("options,message", [
    ({"census": "4x4"}, "census window"),
    ({"method": "bm"}, "unknown method"),
    ({"p1": 40, "p2": 10}, "p1"),
])
def test_bad_matcher_options_raise_value_error(options, message):
    with pytest.raises(ValueError, match=message):
        seasonstereo.predict(PAIR, PAIR, (0, 4), **options)


def test_bad_arrays_raise_value_error():
    with pytest.raises(ValueError, match="H×W"):
        seasonstereo.predict(PAIR.ravel(), PAIR.ravel(), (0, 4))
    with pytest.raises(ValueError, match="size"):
        seasonstereo.predict(PAIR, PAIR[:, :40], (0, 4))
    with pytest.raises(ValueError):
        seasonstereo.predict(PAIR, PAIR, (4, 0))


def test_unknown_options_and_types_raise_type_error():
    with pytest.raises(TypeError, match="censsus"):
        seasonstereo.predict(PAIR, PAIR, (0, 4), censsus="5x5")
    with pytest.raises(TypeError):
        seasonstereo.predict(PAIR.astype(np.complex64), PAIR, (0, 4))


def test_bad_reconstruct_options_raise_value_error(dev, tmp_path):
    left, right, rpc_left, rpc_right = images(dev)
    truth = dev / "truth" / "JAX_068_DSM.tif"
    common = dict(out=tmp_path / "dsm.tif", rpc_left=rpc_left, rpc_right=rpc_right)
    with pytest.raises(ValueError, match="max-memory"):
        seasonstereo.reconstruct(left, right, max_memory=-1.0, **common)
    with pytest.raises(ValueError, match="--truth"):
        seasonstereo.reconstruct(left, right, truth=truth, **common)
    with pytest.raises(ValueError, match="gridding"):
        seasonstereo.reconstruct(left, right, gridding="mean", **common)
