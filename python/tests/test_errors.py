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


# Issue 51: what a user met first.

RUST_WORDS = ("ImageArray", "F32", "U16", "PathBuf", "Vec<", "usize", "panicked", "backtrace",
              "index out of bounds")


def one_clear_line(error):
    """The exception's message: one line, no Rust."""
    message = str(error)
    assert "\n" not in message and message.strip(), repr(message)
    assert not any(word in message for word in RUST_WORDS), message
    return message


def texture(seed, shape=(40, 50)):
    return np.random.default_rng(seed).random(shape)


def test_an_empty_list_of_images_raises_value_error(tmp_path):
    with pytest.raises(ValueError) as refused:
        seasonstereo.reconstruct_many([], out=tmp_path / "dsm.tif")
    assert "two or more images" in one_clear_line(refused.value)


def test_float64_and_integer_arrays_are_converted_to_float32():
    left, right = texture(1), np.roll(texture(1), -2, axis=1)
    expected = seasonstereo.predict(left.astype(np.float32), right.astype(np.float32), (0, 4))
    np.testing.assert_array_equal(seasonstereo.predict(left, right, (0, 4)), expected)
    ints = (left * 1000).astype(np.int64), (right * 1000).astype(np.int64)
    as_float = [a.astype(np.float32) for a in ints]
    np.testing.assert_array_equal(seasonstereo.predict(*ints, (0, 4)),
                                  seasonstereo.predict(*as_float, (0, 4)))


@pytest.mark.parametrize("image", [PAIR.astype(np.complex64), None, "left.tif", [[1, 2]],
                                   np.array([["a", "b"]])])
def test_other_images_raise_type_error_naming_python_types(image):
    with pytest.raises(TypeError) as refused:
        seasonstereo.predict(image, PAIR, (0, 4))
    assert "numpy array" in one_clear_line(refused.value)


def test_the_native_module_names_numpy_types_too():
    with pytest.raises(TypeError) as refused:
        seasonstereo._native.predict(PAIR.astype(np.float64), PAIR, (0, 4))
    assert "float32, uint8 or uint16, got a numpy array of float64" in one_clear_line(refused.value)


def test_one_path_is_one_image_not_its_characters(tmp_path):
    image = tmp_path / "img.tif"
    image.write_bytes(b"")
    for given in (str(image), image):
        with pytest.raises(ValueError) as refused:
            seasonstereo.reconstruct_many(given, out=tmp_path / "dsm.tif")
        assert f"got 1 ({image})" in one_clear_line(refused.value)


def test_a_pattern_matching_nothing_raises_value_error_naming_it(tmp_path):
    pattern = str(tmp_path / "*.tif")
    with pytest.raises(ValueError) as refused:
        seasonstereo.reconstruct_many(pattern, out=tmp_path / "dsm.tif")
    assert pattern in one_clear_line(refused.value)


def test_a_pattern_is_expanded_and_sorted(dev, tmp_path):
    pattern = str(dev / "images" / "JAX_068_01[345]_RGB.tif")
    s = seasonstereo.reconstruct_many(pattern, dev / "rpcs" / "ba", out=tmp_path / "dsm.tif",
                                      pairs=1, dry_run=True)
    assert [v["image"] for v in s["views"]] == sorted(
        str(dev / "images" / f"JAX_068_{d}_RGB.tif") for d in ("013", "014", "015"))


@pytest.mark.parametrize("images", [None, 3, {"a": 1}, b"img.tif", [None], ["a.tif", 3]])
def test_images_of_other_types_raise_type_error(images, tmp_path):
    with pytest.raises(TypeError) as refused:
        seasonstereo.reconstruct_many(images, out=tmp_path / "dsm.tif")
    assert "images" in one_clear_line(refused.value)
