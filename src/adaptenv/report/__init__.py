"""Reports of closed-loop runs and experiments: a self-contained folder of HTML, PNGs and data.

``adaptenv report RUN_OR_EXPERIMENT_DIR`` (or :func:`build_report`) reads what the loop wrote
(:mod:`adaptenv.curriculum.records`) and writes ``index.html`` that works offline:

- a run: key figures, learning curves (held-out success and SPL against iterations and environment
  steps), the per-iteration results table, and a gallery of before/after renders with the
  analysis (outcome, concerns, suggestions) and the edits of every adapted scene;
- an experiment (``<method>/seed_<s>/`` run folders): a summary table (mean ± standard error over
  seeds, p-values from the runner's summary.json when given), curves with one line per method,
  and a report per run, linked.

Modules: :mod:`~adaptenv.report.data` reads folders into dataclasses, :mod:`~adaptenv.report.plots`
draws the curves (matplotlib, Agg), :mod:`~adaptenv.report.html` writes the pages. Nothing heavy is
imported here.
"""

from __future__ import annotations

from pathlib import Path


def build_report(path: Path, out: Path | None = None) -> Path:
    """Write the report of a run or experiment folder (default ``<path>/report``); returns index.html."""
    from adaptenv.report.html import build_report as build

    return build(path, out)


__all__ = ["build_report"]
