"""The command line's safety rules from Python: an existing output is refused (the same message)
unless ``overwrite=True``, a run whose every tile failed raises ``NothingProduced`` and writes
nothing, one where some failed returns naming them with a warning. On the procedural world.

And no panic reachable from input: every entry point with bad values raises the fitting
exception with one clear line, and a panic that happens anyway is a one-line ``RuntimeError``
with nothing printed."""

import os
import struct
import subprocess
import sys

import numpy as np
import pytest

import seasonstereo
from conftest import run_cli


def world(cli, folder, size):
    """A procedural raw pair with its cameras (``seasonstereo world --raw``)."""
    run_cli(cli, "world", "--size", size, "--seed", 3, "--raw", "-o", folder)
    return {"left": folder / "raw/WORLD_3_A.tif", "right": folder / "raw/WORLD_3_B.tif",
            "rpc_left": folder / "rpc/WORLD_3_A.json", "rpc_right": folder / "rpc/WORLD_3_B.json"}


def damage_tiles(path, hit):
    """Overwrites the compressed bytes of the TIFF tiles at (row, column) where ``hit``, as the
    command line's safety test does: the file opens, those tiles fail to decode."""
    data = bytearray(path.read_bytes())
    assert data[:2] == b"II", "little-endian TIFF"
    big = struct.unpack_from("<H", data, 2)[0] == 43
    offset = struct.unpack_from("<Q" if big else "<I", data, 8 if big else 4)[0]
    count_format, entry, head = ("<Q", 20, 8) if big else ("<H", 12, 2)
    count = struct.unpack_from(count_format, data, offset)[0]
    sizes = {3: ("H", 2), 4: ("I", 4), 16: ("Q", 8)}
    tags = {}
    for i in range(count):
        at = offset + head + i * entry
        tag, kind = struct.unpack_from("<HH", data, at)
        n = struct.unpack_from("<Q" if big else "<I", data, at + 4)[0]
        code, size = sizes.get(kind, ("B", 1))
        inline = n * size <= (8 if big else 4)
        where = at + (12 if big else 8) if inline else struct.unpack_from(
            "<Q" if big else "<I", data, at + (12 if big else 8))[0]
        tags[tag] = struct.unpack_from(f"<{n}{code}", data, where)
    across = -(-tags[256][0] // tags[322][0])
    for i, (start, length) in enumerate(zip(tags[324], tags[325])):
        if hit(i // across, i % across):
            data[start:start + length] = b"\xa5" * length
    path.write_bytes(bytes(data))


def test_an_existing_output_is_refused_as_on_the_command_line(cli, tmp_path):
    scene = world(cli, tmp_path / "world", 256)
    out = tmp_path / "dsm.tif"
    out.write_bytes(b"yesterday's DSM")
    with pytest.raises(FileExistsError) as refused:
        seasonstereo.reconstruct(out=out, **scene)
    assert str(out) in str(refused.value) and "already exists" in str(refused.value)
    assert out.read_bytes() == b"yesterday's DSM"
    said = subprocess.run([str(cli), "reconstruct", scene["left"], scene["right"], "--rpc-left",
                           scene["rpc_left"], "--rpc-right", scene["rpc_right"], "-o", out],
                          capture_output=True, text=True)
    assert said.returncode == 1 and said.stderr.strip() == f"error: {refused.value}"
    s = seasonstereo.reconstruct(out=out, overwrite=True, **scene)
    assert s["tiles"]["failed"] == [] and seasonstereo.read_dsm(out).array.shape[0] > 0
    # The work folder of that run is resumed: its DSM is rewritten without overwrite.
    seasonstereo.reconstruct(out=out, **scene)


def test_dsm_refuses_an_existing_output(tmp_path):
    out = tmp_path / "dsm.tif"
    out.write_bytes(b"kept")
    with pytest.raises(FileExistsError, match="already exists"):
        seasonstereo.dsm(np.zeros((4, 4), np.float32), tmp_path / "h.npz", tmp_path / "l.json",
                         tmp_path / "r.json", out)
    assert out.read_bytes() == b"kept"


def test_failed_tiles_warn_when_some_and_raise_when_all(cli, tmp_path):
    scene = world(cli, tmp_path / "world", 768)
    # 768² views in 256² TIFF tiles: the bottom-right one damaged.
    damage_tiles(scene["left"], lambda r, c: r == 2 and c == 2)
    with pytest.warns(UserWarning, match="r002_c002"):
        s = seasonstereo.reconstruct(out=tmp_path / "partial.tif", tile=256, **scene)
    assert "r002_c002" in s["tiles"]["failed"] and (tmp_path / "partial.tif").is_file()
    damage_tiles(scene["left"], lambda r, c: True)
    nothing = tmp_path / "nothing.tif"
    with pytest.raises(seasonstereo.NothingProduced, match="no DSM written"):
        seasonstereo.reconstruct(out=nothing, tile=256, **scene)
    assert not nothing.exists() and issubclass(seasonstereo.NothingProduced, RuntimeError)


# Issue 51: no panic reachable from input. Every entry point with bad values: each raises the
# fitting exception with one clear line (never a PanicException, a backtrace or a Rust type
# name), before any work. Table-driven; the files are made once.

RUST_WORDS = ("ImageArray", "F32", "U16", "PathBuf", "PyString", "PyAny", "Vec<", "usize", "u64",
              "f64", "i32", "panicked", "backtrace", "Rust", "index out of bounds",
              "integral type conversion")
TEXTURE = np.random.default_rng(5).random((40, 50)).astype(np.float32)
HUGE = np.broadcast_to(np.zeros((1, 1), np.float32), (200_000, 200_000))


@pytest.fixture(scope="module")
def bad(tmp_path_factory):
    """Bad files, by name: missing, a folder, empty, garbage TIFF, malformed cameras."""
    d = tmp_path_factory.mktemp("bad")
    files = {"missing": d / "missing.tif", "folder": d / "folder", "empty": d / "empty.tif",
             "garbage": d / "garbage.tif", "json": d / "cam.json", "rpc_wrong": d / "wrong.json",
             "rpb": d / "cam.RPB", "imd": d / "cam.IMD", "out": d / "out" / "dsm.tif"}
    files["folder"].mkdir()
    files["empty"].write_bytes(b"")
    files["garbage"].write_bytes(b"II*\x00" + b"\xa5" * 300)
    files["json"].write_text('{"rpc": {"LINE_OFF": ')
    files["rpc_wrong"].write_text('{"rpc": {"LINE_OFF": "north", "SAMP_OFF": []}}')
    files["rpb"].write_text("satId = \"WV03\";\nBEGIN_GROUP = IMAGE\n\tlineOffset = ;\n")
    files["imd"].write_text("version = \"AA\";\nBEGIN_GROUP = IMAGE_1\nEND_GROUP\n")
    return files


P = seasonstereo
CASES = {
    # predict: arrays and values
    "predict None": (lambda b: P.predict(None, TEXTURE), TypeError),
    "predict int": (lambda b: P.predict(3, TEXTURE), TypeError),
    "predict dict": (lambda b: P.predict({}, TEXTURE), TypeError),
    "predict bytes": (lambda b: P.predict(b"\x00" * 8, TEXTURE), TypeError),
    "predict object array": (lambda b: P.predict(np.full((4, 4), None), TEXTURE), TypeError),
    "predict inf": (lambda b: P.predict(TEXTURE, TEXTURE * np.inf, (0, 4)), ValueError),
    "predict -inf": (lambda b: P.predict(np.where(TEXTURE > 0.5, -np.inf, TEXTURE), TEXTURE),
                     ValueError),
    "predict 0x0": (lambda b: P.predict(np.zeros((0, 0)), np.zeros((0, 0)), (0, 4)), ValueError),
    "predict 0xN": (lambda b: P.predict(np.zeros((0, 50)), np.zeros((0, 50))), ValueError),
    "predict 1-d": (lambda b: P.predict(TEXTURE.ravel(), TEXTURE.ravel(), (0, 4)), ValueError),
    "predict 4-d": (lambda b: P.predict(TEXTURE[None, :, :, None], TEXTURE, (0, 4)), ValueError),
    "predict sizes differ": (lambda b: P.predict(TEXTURE, TEXTURE[:, :40], (0, 4)), ValueError),
    "predict huge image": (lambda b: P.predict(HUGE, HUGE, (0, 4)), ValueError),
    "predict huge range": (lambda b: P.predict(TEXTURE, TEXTURE, (-2**31, 2**31 - 1)),
                           ValueError),
    "predict range too big for int": (lambda b: P.predict(TEXTURE, TEXTURE, (0, 2**40)),
                                      ValueError),
    "predict range reversed": (lambda b: P.predict(TEXTURE, TEXTURE, (4, 0)), ValueError),
    "predict range str": (lambda b: P.predict(TEXTURE, TEXTURE, "0:4"), TypeError),
    "predict range None in it": (lambda b: P.predict(TEXTURE, TEXTURE, (0, None)), TypeError),
    "predict threads 0": (lambda b: P.predict(TEXTURE, TEXTURE, (0, 4), threads=0), ValueError),
    "predict threads huge": (lambda b: P.predict(TEXTURE, TEXTURE, (0, 4), threads=10**6),
                             ValueError),
    "predict threads negative": (lambda b: P.predict(TEXTURE, TEXTURE, (0, 4), threads=-1),
                                 ValueError),
    "predict census huge": (lambda b: P.predict(TEXTURE, TEXTURE, (0, 4), census="999x999"),
                            ValueError),
    "predict census garbage": (lambda b: P.predict(TEXTURE, TEXTURE, (0, 4), census="x"),
                               ValueError),
    "predict max_memory NaN": (lambda b: P.predict(TEXTURE, TEXTURE, (0, 4),
                                                   max_memory=float("nan")), ValueError),
    "predict progress int": (lambda b: P.predict(TEXTURE, TEXTURE, (0, 4), progress=3),
                             TypeError),
    "predict method None": (lambda b: P.predict(TEXTURE, TEXTURE, (0, 4), method=None),
                            TypeError),
    "predict range 3": (lambda b: P.predict(TEXTURE, TEXTURE, (0, 4, 8)), TypeError),
    "predict range float": (lambda b: P.predict(TEXTURE, TEXTURE, (0.5, 4)), TypeError),
    # read_dsm, score: files
    "read_dsm None": (lambda b: P.read_dsm(None), TypeError),
    "read_dsm int": (lambda b: P.read_dsm(3), TypeError),
    "read_dsm missing": (lambda b: P.read_dsm(b["missing"]), FileNotFoundError),
    "read_dsm folder": (lambda b: P.read_dsm(b["folder"]), (OSError, ValueError)),
    "read_dsm empty": (lambda b: P.read_dsm(b["empty"]), (OSError, ValueError)),
    "read_dsm garbage": (lambda b: P.read_dsm(b["garbage"]), (OSError, ValueError)),
    "read_dsm zone": (lambda b: P.read_dsm(b["garbage"], "99Q"), ValueError),
    "score garbage": (lambda b: P.score(b["garbage"], b["garbage"]), (OSError, ValueError)),
    "score dict": (lambda b: P.score({}, b["garbage"]), TypeError),
    # dsm, rectify: files and cameras
    "dsm missing": (lambda b: P.dsm(b["missing"], b["missing"], b["json"], b["json"], b["out"]),
                    FileNotFoundError),
    "dsm malformed json": (lambda b: P.dsm(TEXTURE, b["garbage"], b["json"], b["json"],
                                           b["out"]), (OSError, ValueError)),
    "dsm bad camera dict": (lambda b: P.dsm(TEXTURE, b["garbage"], {"rpc": 3}, {}, b["out"]),
                            (OSError, ValueError)),
    "dsm resolution 0": (lambda b: P.dsm(TEXTURE, b["garbage"], b["json"], b["json"], b["out"],
                                         resolution=0.0), (OSError, ValueError)),
    "rectify missing": (lambda b: P.rectify(b["missing"], b["missing"], b["out"]),
                        FileNotFoundError),
    "rectify garbage": (lambda b: P.rectify(b["garbage"], b["garbage"], b["out"]),
                        (OSError, ValueError)),
    "rectify rpb": (lambda b: P.rectify(b["garbage"], b["garbage"], b["out"], rpc_left=b["rpb"],
                                        rpc_right=b["imd"]), (OSError, ValueError)),
    "rectify roi negative": (lambda b: P.rectify(b["garbage"], b["garbage"], b["out"],
                                                 roi=(-1, 0, 5, 5)), (TypeError, OverflowError)),
    # reconstruct: files, types and values
    "reconstruct None": (lambda b: P.reconstruct(None, None, out=b["out"]), TypeError),
    "reconstruct out None": (lambda b: P.reconstruct(b["garbage"], b["garbage"], out=None),
                             TypeError),
    "reconstruct missing": (lambda b: P.reconstruct(b["missing"], b["missing"], out=b["out"]),
                            FileNotFoundError),
    "reconstruct folder": (lambda b: P.reconstruct(b["folder"], b["folder"], out=b["out"]),
                           (OSError, ValueError)),
    "reconstruct empty": (lambda b: P.reconstruct(b["empty"], b["empty"], out=b["out"]),
                          (OSError, ValueError)),
    "reconstruct malformed json": (lambda b: P.reconstruct(
        b["garbage"], b["garbage"], out=b["out"], rpc_left=b["json"], rpc_right=b["rpc_wrong"]),
        (OSError, ValueError)),
    "reconstruct rpb": (lambda b: P.reconstruct(b["garbage"], b["garbage"], out=b["out"],
                                                rpc_left=b["rpb"], rpc_right=b["imd"]),
                        (OSError, ValueError)),
    "reconstruct tile str": (lambda b: P.reconstruct(b["garbage"], b["garbage"], out=b["out"],
                                                     tile="big"), TypeError),
    "reconstruct max_memory": (lambda b: P.reconstruct(b["garbage"], b["garbage"], out=b["out"],
                                                       max_memory=-1.0), ValueError),
    "reconstruct shard": (lambda b: P.reconstruct(b["garbage"], b["garbage"], out=b["out"],
                                                  shard="3/2"), ValueError),
    "reconstruct method int": (lambda b: P.reconstruct(b["garbage"], b["garbage"], out=b["out"],
                                                       method=3), TypeError),
    "reconstruct tile negative": (lambda b: P.reconstruct(b["garbage"], b["garbage"],
                                                          out=b["out"], tile=-1), ValueError),
    "reconstruct unknown": (lambda b: P.reconstruct(b["garbage"], b["garbage"], out=b["out"],
                                                    tyle=256), TypeError),
    # reconstruct_many: lists, types, values
    "many empty": (lambda b: P.reconstruct_many([], out=b["out"]), ValueError),
    "many empty native": (lambda b: P._native.reconstruct_many([], out=b["out"]), ValueError),
    "many one": (lambda b: P.reconstruct_many([b["garbage"]], out=b["out"]), ValueError),
    "many garbage": (lambda b: P.reconstruct_many([b["garbage"]] * 3, out=b["out"]),
                     (OSError, ValueError)),
    "many missing": (lambda b: P.reconstruct_many([b["missing"]] * 2, out=b["out"]),
                     FileNotFoundError),
    "many empty files": (lambda b: P.reconstruct_many([b["empty"], b["garbage"]], out=b["out"]),
                         (OSError, ValueError)),
    "many None": (lambda b: P.reconstruct_many(None, out=b["out"]), TypeError),
    "many int": (lambda b: P.reconstruct_many(3, out=b["out"]), TypeError),
    "many dict": (lambda b: P.reconstruct_many({}, out=b["out"]), TypeError),
    "many bytes": (lambda b: P.reconstruct_many(b"a.tif", out=b["out"]), TypeError),
    "many pattern": (lambda b: P.reconstruct_many(str(b["folder"] / "*.tif"), out=b["out"]),
                     ValueError),
    "many rpc_dir json": (lambda b: P.reconstruct_many([b["garbage"], b["empty"]], b["json"],
                                                       out=b["out"]), (OSError, ValueError)),
    "many pairs str": (lambda b: P.reconstruct_many([b["garbage"]] * 2, out=b["out"],
                                                    pairs="all"), TypeError),
    "many shard": (lambda b: P.reconstruct_many([b["garbage"]] * 2, out=b["out"], shard="0/0"),
                   ValueError),
    "many alt_range": (lambda b: P.reconstruct_many([b["garbage"]] * 2, out=b["out"],
                                                    alt_range=(1.0,)), TypeError),
    "many progress": (lambda b: P.reconstruct_many([b["garbage"]] * 2, out=b["out"],
                                                   progress="yes"), TypeError),
}


@pytest.mark.parametrize("name", CASES)
def test_bad_input_raises_one_clear_line_never_a_panic(name, bad, capfd):
    call, expected = CASES[name]
    with pytest.raises(Exception) as raised:
        call(bad)
    error = raised.value
    assert isinstance(error, expected), f"{type(error).__name__}: {error}"
    message = str(error)
    assert "\n" not in message and message.strip(), repr(message)
    assert not any(word in message for word in RUST_WORDS), message
    said = capfd.readouterr().err
    assert "panicked" not in said and "backtrace" not in said, said


def nan_where(image, where):
    return np.where(where, np.nan, image).astype(np.float32)


@pytest.mark.parametrize("shape,nan,disparity_range", [
    ((1, 50), False, (0, 4)), ((40, 1), False, (0, 4)), ((1, 1), False, (0, 4)),
    ((2, 2), False, None), ((1, 50), False, None), ((40, 50), True, (0, 4)),
    ((40, 50), True, None), ((40, 50), "half", None), ((40, 50), False, (-1000, 1000)),
])
def test_odd_images_give_a_disparity_or_a_value_error(shape, nan, disparity_range):
    """Tiny and all-NaN (no data) images, a range far wider than the image: a disparity of
    the image's size or a one-line ``ValueError``, never a panic."""
    image = np.random.default_rng(2).random(shape).astype(np.float32)
    if nan:
        image = nan_where(image, True if nan is True else image > 0.5)
    try:
        d = seasonstereo.predict(image, image, disparity_range)
    except ValueError as e:
        assert "\n" not in str(e) and not any(w in str(e) for w in RUST_WORDS), str(e)
    else:
        assert d.shape == shape and d.dtype == np.float32


def dev_scene(dev):
    names = [f"JAX_068_{d}_RGB" for d in ("014", "015")]
    return ([dev / "images" / f"{n}.tif" for n in names]
            + [dev / "rpcs" / "ba" / f"{n}.json" for n in names])


# Values that only real images reach: each refused before any work.
DEV_CASES = {
    "roi huge": (lambda l, r, c, o: P.reconstruct(l, r, out=o, roi=(0, 0, 10**9, 10**9), **c),
                 "does not fit"),
    "roi empty": (lambda l, r, c, o: P.reconstruct(l, r, out=o, roi=(0, 0, 0, 0), **c), "empty"),
    "resolution tiny": (lambda l, r, c, o: P.reconstruct(l, r, out=o, resolution=1e-6, **c),
                        "too large"),
    "resolution 0": (lambda l, r, c, o: P.reconstruct(l, r, out=o, resolution=0.0, **c), "DSM"),
    "resolution NaN": (lambda l, r, c, o: P.reconstruct(l, r, out=o, resolution=float("nan"),
                                                        **c), "DSM"),
    "tile 0": (lambda l, r, c, o: P.reconstruct(l, r, out=o, tile=0, **c), "too small"),
    "epsg": (lambda l, r, c, o: P.reconstruct(l, r, out=o, epsg=99999, **c), "UTM"),
    "alt_range inverted": (lambda l, r, c, o: P.reconstruct(l, r, out=o, alt_range=(100, -100),
                                                            **c), "MIN < MAX"),
    "rectify roi huge": (lambda l, r, c, o: P.rectify(l, r, o.parent / "rect", roi=(0, 0, 10**9,
                                                                                   10**9), **c),
                         "does not fit"),
    "many duplicates": (lambda l, r, c, o: P.reconstruct_many([l, l, r], l.parent.parent / "rpcs"
                                                              / "ba", out=o),
                        "the same acquisition"),
    "many pairs 0": (lambda l, r, c, o: P.reconstruct_many([l, r], l.parent.parent / "rpcs" / "ba",
                                                           out=o, pairs=0), "pairs"),
    "many resolution tiny": (lambda l, r, c, o: P.reconstruct_many(
        [l, r], l.parent.parent / "rpcs" / "ba", out=o, resolution=1e-6), "too large"),
}


@pytest.mark.parametrize("name", DEV_CASES)
def test_bad_values_on_real_images_are_refused_before_any_work(name, dev, tmp_path, capfd):
    left, right, rpc_left, rpc_right = dev_scene(dev)
    call, words = DEV_CASES[name]
    with pytest.raises(ValueError) as raised:
        call(left, right, {"rpc_left": rpc_left, "rpc_right": rpc_right}, tmp_path / "dsm.tif")
    message = str(raised.value)
    assert "\n" not in message and words in message, message
    assert not any(word in message for word in RUST_WORDS), message
    assert "panicked" not in capfd.readouterr().err
    assert not (tmp_path / "dsm.tif").exists()


def test_a_panic_in_the_library_is_one_runtime_error_and_prints_nothing():
    """Run without RUST_BACKTRACE (set, a developer keeps the default hook and its trace)."""
    code = ("import seasonstereo\n"
            "try:\n"
            "    seasonstereo._native._panic_for_tests('index out of bounds: the len is 0')\n"
            "except RuntimeError as e:\n"
            "    print(type(e).__name__, e)\n")
    env = {k: v for k, v in os.environ.items() if k != "RUST_BACKTRACE"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    said = done.stdout.strip()
    assert said.startswith("RuntimeError internal error in seasonstereo (please report it): "
                           "index out of bounds: the len is 0 (at ") and "\n" not in said, said
