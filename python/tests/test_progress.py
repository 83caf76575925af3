"""``progress``: one count over the whole call, ``(stage, done, total)``, neither going back;
``True`` shows something without tqdm too."""

import sys

import numpy as np

import seasonstereo

TEXTURE = np.random.default_rng(7).random((60, 80)).astype(np.float32)


def check_one_count(calls):
    """The calls of one run: strings and counts, neither going back, complete at the end."""
    assert calls, "the callback was never called"
    for stage, done, total in calls:
        assert isinstance(stage, str) and stage and 0 <= done <= total
    for (_, d0, t0), (_, d1, t1) in zip(calls, calls[1:]):
        assert d1 >= d0 and t1 >= t0, (d0, t0, d1, t1)
    assert calls[-1][1] == calls[-1][2]


def test_predict_reports_one_count():
    calls = []
    seasonstereo.predict(TEXTURE, np.roll(TEXTURE, -2, axis=1), (0, 4),
                         progress=lambda *a: calls.append(a))
    check_one_count(calls)
    assert calls[0][0].startswith("matching")


def test_progress_true_without_tqdm_prints_lines(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "tqdm", None)
    seasonstereo.predict(TEXTURE, TEXTURE, (0, 4), progress=True)
    lines = capsys.readouterr().err.splitlines()
    assert lines and all(line.startswith("seasonstereo: matching") for line in lines)
    assert lines[-1].endswith("(100 %)") and len(lines) <= 12


def test_reconstruct_many_reports_pairs_times_tiles_then_the_fusion(dev, tmp_path):
    calls = []
    s = seasonstereo.reconstruct_many(str(dev / "images" / "JAX_068_01[345]_RGB.tif"),
                                      dev / "rpcs" / "ba", out=tmp_path / "dsm.tif", pairs=2,
                                      tile=384, progress=lambda *a: calls.append(a))
    assert len(s["chosen"]) == 2 and s["fused"] is not None
    check_one_count(calls)
    stages = list(dict.fromkeys(stage for stage, _, _ in calls))
    assert stages[0] == "selecting pairs" and stages[-1] == "fusing"
    assert stages[1:3] == ["matching pair 1/2", "matching pair 2/2"]
    # While the pairs run, the total is the pairs × their tiles: several tiles each.
    tiles = [total for stage, _, total in calls if stage.startswith("matching")]
    assert tiles[0] >= 1 + 2 * 2
