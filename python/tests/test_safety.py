"""The command line's safety rules from Python: an existing output is refused (the same message)
unless ``overwrite=True``, a run whose every tile failed raises ``NothingProduced`` and writes
nothing, one where some failed returns naming them with a warning. On the procedural world."""

import struct
import subprocess

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
