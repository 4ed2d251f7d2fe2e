"""The README's Python API example runs as written."""
from __future__ import annotations

import os
import re
import shutil

from conftest import ROOT


def test_readme_python_example_runs(tmp_path, capsys):
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Python API"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    shutil.copytree(ROOT / "scenes", tmp_path / "scenes",
                    ignore=shutil.ignore_patterns("out*", "*.exr", "*.png"))
    old = os.getcwd()
    os.chdir(tmp_path)
    try:
        exec(compile(code, "README.md", "exec"), {})
    finally:
        os.chdir(old)
    printed = capsys.readouterr().out.split()
    assert (tmp_path / "out" / "api-mesh" / "image.exr").exists()
    assert float(printed[-1]) > 0                      # the two renders differ
