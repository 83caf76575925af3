"""The user guide's Python page runs as written: every ```python block of
``docs/guide/src/python.md``, in order, in one namespace (later blocks use what earlier ones
made), in a temporary folder, with the development set's path replaced by where the tests find
it (``conftest``'s data root). A block whose fence follows a ``<!-- not run: why -->`` line is
left out, as the shell blocks' test does."""

import re

import pytest

from conftest import REPOSITORY

PAGE = REPOSITORY / "docs" / "guide" / "src" / "python.md"
# The data set as the page names it: a path relative to the repository, as every page does.
DATA = '"../shared/data/dfc2019-jax068-dev"'


def blocks() -> list:
    """The page's ```python blocks to run, in order."""
    found, lines = [], PAGE.read_text().splitlines()
    i = 0
    while i < len(lines):
        if lines[i].rstrip() == "```python":
            end = lines.index("```", i + 1)
            skipped = i > 0 and lines[i - 1].strip().startswith("<!-- not run:")
            if not skipped:
                found.append("\n".join(lines[i + 1:end]) + "\n")
            i = end
        i += 1
    return found


def test_the_page_has_examples_and_names_the_data_set_once():
    code = blocks()
    assert len(code) >= 3, "python.md has its examples"
    assert sum(block.count(DATA) for block in code) == 1, f"one {DATA} for the tests to replace"


def test_every_python_block_of_the_guide_runs(dev, tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    pytest.importorskip("rasterio")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.chdir(tmp_path)
    scope: dict = {"__name__": "guide"}
    for number, code in enumerate(blocks(), start=1):
        code = code.replace(DATA, repr(str(dev)))
        try:
            exec(compile(code, f"python.md, block {number}", "exec"), scope)
        except Exception as e:
            raise AssertionError(f"python.md, block {number} failed: {e!r}\n{code}") from e
    # The outputs the page says it writes.
    for name in ("dsm.tif", "ortho.tif", "points.las", "preview.png", "014-015.tif",
                 "014-015.png", "many.tif"):
        assert (tmp_path / "out" / name).is_file(), name
