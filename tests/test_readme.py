"""The README's Python example runs as written."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_example_runs():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)
    assert blocks, "the README has a Python example"
    for code in blocks:
        exec(compile(code, str(README), "exec"), {})


def test_readme_first_lines_are_the_two_setup_commands():
    lines = README.read_text(encoding="utf-8").splitlines()
    block = "\n".join(lines[:6])
    assert "make demo" in block and "make test" in block
