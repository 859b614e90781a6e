"""The README's main job, `adaptenv demo`: the closed loop against DR end to end, a report with a verdict."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

DEV_EXTRAS = ("ray", "tensorboard", "minigrid", "pytest", "hypothesis", "ruff", "xdist")

DEMO_AND_LIST_IMPORTS = """
import json, sys

from adaptenv.cli import main

sys.argv = ["adaptenv", "demo", "-o", {out!r}, "--houses", "1", "--iterations", "1"]
try:
    main()
except SystemExit as exc:
    assert not exc.code, exc.code
print(json.dumps(sorted({{m.split(".")[0] for m in sys.modules}} & {extras!r})))
"""


@pytest.mark.slow
def test_demo_compares_the_loop_with_dr_and_imports_none_of_the_dev_extras(tmp_path):
    """One fresh process, as `make demo` runs it: ours and dr on the same houses, seed and budget, a report that
    opens with the verdict, and no dev extra imported (what `make demo` installs is enough)."""
    src = Path(__file__).resolve().parents[1] / "src"
    out = tmp_path / "demo"
    code = DEMO_AND_LIST_IMPORTS.format(extras=set(DEV_EXTRAS), out=str(out))
    env = dict(os.environ, PYTHONPATH=str(src), COLUMNS="400")  # no wrapped console lines
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-3000:]
    *printed, extras = proc.stdout.strip().splitlines()
    assert json.loads(extras) == []

    runs = {m: [json.loads(line) for line in (out / "run" / m / "seed_0" / "iterations.jsonl").read_text().splitlines()]
            for m in ("dr", "ours")}
    for records in runs.values():
        assert [r["iteration"] for r in records] == [0, 1]
        assert set(records[1]["heldout"]) == {"rearranged", "unseen"}
    assert runs["dr"][1]["grad_updates"] == runs["ours"][1]["grad_updates"] > 0  # the same fine-tuning budget
    assert runs["dr"][0]["heldout"] == runs["ours"][0]["heldout"]  # the same pi_0 on the same episodes
    assert runs["ours"][1]["edits"] > 0
    assert (out / "run" / "ours" / "seed_0" / runs["ours"][1]["gallery"][0]["after_png"]).is_file()

    verdict = next(line for line in printed if line.startswith("Verdict: ours - dr held-out success = "))
    assert "paired over the 50 held-out episodes" in verdict  # 25 per house, 1 house, 2 sets
    against = [line for line in printed if line.startswith("Against t=0: ")]  # each method against pi_0
    assert [line.split(" - pi_0")[0] for line in against] == ["Against t=0: dr", "Against t=0: ours"]
    assert all("over the same 50 episodes" in line and ("within noise of pi_0" in line or "beyond noise" in line)
               for line in against)
    steps = {m: records[-1]["env_steps"] for m, records in runs.items()}
    budget = next(line for line in printed if line.startswith("Environment steps: "))
    assert f"ours {steps['ours']:,}" in budget and f"dr {steps['dr']:,}" in budget
    assert f"ours used {steps['ours'] / steps['dr']:.1f}x dr's" in budget and "unequal budgets" in budget
    index = out / "run" / "report" / "index.html"
    assert index.is_file() and f"report: {index}" in [line.strip() for line in printed]
    page = index.read_text()
    assert page.index('<p class="verdict">') < page.index('id="overview"')
