"""The README's Python example runs as written (the data root and the output folder replaced by
the tests' own)."""

import os
import re

from conftest import REPOSITORY


def example() -> str:
    readme = (REPOSITORY / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", readme, re.S)
    assert len(blocks) == 1, "the README has one Python example"
    return blocks[0]


def test_the_readme_example_writes_a_dsm(dev, tmp_path, monkeypatch):
    code = example()
    assert len(code.strip().splitlines()) <= 12
    code = code.replace('"../shared/data/dfc2019-jax068-dev"', repr(str(dev)))
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)
    assert os.path.isfile(tmp_path / "out/py/006-020.tif")
    dsm = scope["summary"]["dsm"]
    # Measured cells, and cells with a height once the holes are filled, over the grid of the
    # left image's footprint (its corners lie outside the pair's overlap).
    assert dsm["coverage"] > 0.35 and dsm["filled"] > 0.6, dsm
