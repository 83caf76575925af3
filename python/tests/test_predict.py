"""``predict`` on numpy arrays: the command line's values bit for bit, every pixel type, progress,
and the GIL released while it computes."""

import hashlib
import threading
import time

import numpy as np
import pytest

import seasonstereo
from conftest import run_cli


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal shapes and float32 bit patterns (NaN included)."""
    return a.shape == b.shape and np.array_equal(
        np.ascontiguousarray(a, np.float32).view(np.uint32),
        np.ascontiguousarray(b, np.float32).view(np.uint32))


def texture(height=300, width=400, shift=7, seed=1):
    """A random texture and its copy shifted by ``shift`` pixels: disparity ``shift``."""
    wide = np.random.default_rng(seed).uniform(0, 255, (height, width + shift)).astype(np.float32)
    return wide[:, :width].copy(), wide[:, shift:].copy()


def test_version():
    assert seasonstereo.__version__ == "0.1.0"


@pytest.mark.parametrize("method,options,flags", [
    ("mgm", {}, []),
    ("sgm", {"census": "7x7", "p2": 40}, ["--census", "7x7", "--p2", "40"]),
])
def test_predict_equals_the_command_line(rectified, cli, tmp_path, method, options, flags):
    lo, hi = rectified["range"]
    out = tmp_path / "d.npy"
    run_cli(cli, "predict", rectified["left"], rectified["right"], "-o", out,
            "--range", f"{lo}:{hi}", "--method", method, *flags)
    left, right = np.load(rectified["left"]), np.load(rectified["right"])
    disparity = seasonstereo.predict(left, right, (lo, hi), method, **options)
    assert disparity.dtype == np.float32 and disparity.shape == left.shape[:2]
    # The command writes NPY disparities H×W×1; Python gives them H×W.
    assert same_bits(disparity, np.load(out)[:, :, 0])
    assert np.isfinite(disparity).mean() > 0.2  # the rectified images' corners are NaN


def test_every_pixel_type_gives_the_same_disparity():
    left, right = texture()
    as_float = seasonstereo.predict(left.round(), right.round(), (0, 15))
    for dtype in (np.uint8, np.uint16):
        got = seasonstereo.predict(left.round().astype(dtype), right.round().astype(dtype), (0, 15))
        assert same_bits(got, as_float), dtype
    assert np.nanmedian(as_float) == pytest.approx(7, abs=0.01)
    # Channels last, any memory layout: three equal bands, Fortran order.
    rgb = [np.asfortranarray(np.repeat(a.round()[:, :, None], 3, axis=2)) for a in (left, right)]
    assert np.nanmedian(seasonstereo.predict(*rgb, (0, 15))) == pytest.approx(7, abs=0.01)


def test_progress_reaches_the_end_and_its_exceptions_propagate():
    left, right = texture(100, 120)
    calls = []
    seasonstereo.predict(left, right, (0, 15), progress=lambda *c: calls.append(c))
    label, done, total = calls[-1]
    assert calls[0][1] == 0 and done == total > 0 and isinstance(label, str)

    # Bars when tqdm is installed, silence otherwise: the same disparity either way.
    assert same_bits(seasonstereo.predict(left, right, (0, 15), progress=True),
                     seasonstereo.predict(left, right, (0, 15)))

    def fail(*_):
        raise KeyError("stop")

    with pytest.raises(KeyError):
        seasonstereo.predict(left, right, (0, 15), progress=fail)


def test_the_gil_is_released_while_predict_computes():
    """Python code keeps running in another thread while ``predict`` computes."""
    left, right = texture(600, 800)
    counter, running = [0], [True]

    def count():
        while running[0]:
            counter[0] += 1

    thread = threading.Thread(target=count)
    thread.start()
    time.sleep(0.05)
    before = counter[0]
    seasonstereo.predict(left, right, (0, 31))
    during = counter[0] - before
    running[0] = False
    thread.join()
    assert during > 10_000, f"the counting thread advanced {during} times during predict"


def timed(f) -> float:
    start = time.perf_counter()
    f()
    return time.perf_counter() - start


def one_and_two(work):
    """Seconds of one call of ``work`` and of two threads calling it at once (best of three: the
    other processes of a shared machine only slow runs down), and the two calls' intervals."""
    spans = []

    def traced():
        start = time.perf_counter()
        work()
        spans.append((start, time.perf_counter()))

    def both():
        threads = [threading.Thread(target=traced) for _ in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()

    work()
    one = min(timed(work) for _ in range(3))
    two = min(timed(both) for _ in range(3))
    return one, two, spans[-2:]


def test_two_threads_take_about_as_long_as_one():
    """Two threads calling ``predict`` with one worker thread each run at once: their calls
    overlap, and on two free cores take about as long as one (twice as long were the GIL held).
    Whether two cores are free now is measured with a GIL-free reference, hashlib's sha256."""
    left, right = texture(500, 700)
    block = bytes(96 << 20)
    ref_one, ref_two, _ = one_and_two(lambda: hashlib.sha256(block).digest())
    one, two, spans = one_and_two(lambda: seasonstereo.predict(left, right, (0, 31), threads=1))
    print(f"predict: one call {one:.3f} s, two threads {two:.3f} s ({two / one:.2f}x); "
          f"sha256: {ref_two / ref_one:.2f}x")
    (a_start, a_end), (b_start, b_end) = spans
    assert max(a_start, b_start) < min(a_end, b_end), "the two calls ran one after the other"
    # The timing tells something only while two cores are free (the reference scales): on a
    # machine shared with other jobs, the overlap above is the proof. Two matchers also share the
    # memory bandwidth, which sha256 does not: a clean-clone CI measured 1.62x with the
    # reference at 0.99x, so the bound sits between that and the 2x of a held GIL.
    if ref_two / ref_one < 1.3:
        assert two / one < 1.8
