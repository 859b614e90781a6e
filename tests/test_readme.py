"""The README's Python snippets run as written, each in a fresh interpreter (as a newcomer would run them)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)


def run_fresh(code: str, tmp_path: Path) -> subprocess.CompletedProcess:
    """Run ``code`` in a new Python process whose path starts with this checkout's sources."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)


def test_readme_has_the_api_and_gymnasium_examples():
    assert len(BLOCKS) >= 2
    assert any('gym.make("adaptenv/ObjectNav-v0")' in b for b in BLOCKS)


@pytest.mark.parametrize("k", range(len(BLOCKS)))
def test_readme_python_snippet_runs_in_a_fresh_interpreter(k, tmp_path):
    proc = run_fresh(BLOCKS[k], tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]


@pytest.mark.parametrize("order", ["import gymnasium as gym\nimport adaptenv", "import adaptenv\nimport gymnasium as gym",
                                   "import adaptenv.sim\nimport gymnasium as gym"])
def test_import_adaptenv_registers_the_gymnasium_id_in_either_order(order, tmp_path):
    code = f"{order}\nenv = gym.make('adaptenv/ObjectNav-v0')\nprint(type(env.unwrapped).__name__)"
    proc = run_fresh(code, tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "NavEnv"


def test_import_adaptenv_stays_light(tmp_path):
    proc = run_fresh("import sys, adaptenv\nprint(sorted(m for m in ('gymnasium', 'numpy', 'torch') if m in sys.modules))",
                     tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"


def test_readme_first_lines_are_the_two_setup_commands():
    lines = README.read_text(encoding="utf-8").splitlines()
    block = "\n".join(lines[:6])
    assert "make demo" in block and "make test" in block


# "session" as a unit of the project's work ("session 11", "sessions 14-15", "this session's host"); the
# operating system's and pytest's sessions ("per session", scope="session") are other words.
WORK_SESSION = re.compile(r"\bsessions? \d+|\bsession-\d+|\bsessions? of work\b|\b(this|last|previous|earlier|next|"
                          r"later|that|with the) session\b|\bacross sessions\b|\bsession's\b", re.IGNORECASE)


def test_docs_speak_of_dates_and_commits_not_of_work_sessions():
    files = [README, *(p for p in sorted((ROOT / "docs").rglob("*")) if p.suffix in {".md", ".txt", ".json"})]
    hits = [f"{p.relative_to(ROOT)}: {m.group(0)!r}" for p in files
            for m in WORK_SESSION.finditer(p.read_text(encoding="utf-8", errors="replace"))]
    assert not hits, hits[:20]


def heading_anchors(markdown: str) -> set[str]:
    """GitHub's anchors of a Markdown file's headings: lower case, punctuation dropped, spaces to hyphens."""
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")
            for h in re.findall(r"^#+ (.+)$", markdown, flags=re.M)}


def test_readme_links_to_files_and_headings_that_exist():
    links = re.findall(r"\]\(([^)#\s]+\.md)(?:#([^)\s]+))?\)", README.read_text(encoding="utf-8"))
    assert ("docs/RESULTS.md", "the-current-answer") in links
    for path, anchor in links:
        target = ROOT / path
        assert target.is_file(), path
        if anchor:
            assert anchor in heading_anchors(target.read_text(encoding="utf-8")), f"{path}#{anchor}"
