"""Learning curves as small PNGs (matplotlib, Agg canvas; no pyplot, so no global backend state).

Every figure has the same 2x2 layout: success (top) and SPL (bottom) against iterations (left)
and against environment steps (right), so methods are compared at equal environment steps too.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from adaptenv.files import atomic_path
from adaptenv.report.data import RunData, Stat, curve

DPI = 100
SIZE = (9.0, 5.6)
METRIC_LABELS = {"success": "success rate", "spl": "SPL"}


@dataclass
class Line:
    """One curve: points (iteration, env steps, mean, SE or None) and how to draw it."""

    label: str
    points: list[tuple[float, float, float, float | None]]
    dashed: bool = False
    colour: str | None = None


def _figure(lines_by_metric: dict[str, Sequence[Line]], title: str, path: Path) -> Path | None:
    """Draw the 2x2 grid for the given lines per metric and save it as PNG; None when nothing to draw."""
    if not any(line.points for lines in lines_by_metric.values() for line in lines):
        return None
    # matplotlib: slow to import, so only when there is something to draw
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import EngFormatter, MaxNLocator

    fig = Figure(figsize=SIZE, dpi=DPI)
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2, sharey="row")
    handles: dict[str, object] = {}
    for row, metric in enumerate(("success", "spl")):
        for col, xkey in enumerate((0, 1)):
            ax = axes[row][col]
            for k, line in enumerate(lines_by_metric.get(metric, ())):
                if not line.points:
                    continue
                pts = sorted(line.points, key=lambda p: p[xkey])
                xs = [p[xkey] for p in pts]
                ys = [p[2] for p in pts]
                colour = line.colour or f"C{k % 10}"
                (h,) = ax.plot(xs, ys, "--" if line.dashed else "-", color=colour, marker="o", markersize=3,
                               linewidth=1.6, label=line.label)
                handles.setdefault(line.label, h)
                if any(p[3] for p in pts):
                    se = [p[3] or 0.0 for p in pts]
                    ax.fill_between(xs, [y - s for y, s in zip(ys, se, strict=True)],
                                    [y + s for y, s in zip(ys, se, strict=True)], color=colour, alpha=0.18,
                                    linewidth=0)
            ax.set_ylim(-0.02, 1.02)
            ax.grid(True, color="#e5e5e5", linewidth=0.8)
            ax.spines[["top", "right"]].set_visible(False)
            ax.tick_params(labelsize=8)
            if col == 0:
                ax.set_ylabel(METRIC_LABELS[metric], fontsize=9)
                ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            else:
                ax.xaxis.set_major_formatter(EngFormatter(sep=""))
            if row == 1:
                ax.set_xlabel("iteration" if col == 0 else "environment steps", fontsize=9)
    fig.suptitle(title, fontsize=11, x=0.01, ha="left")
    fig.legend(list(handles.values()), list(handles), loc="upper right", ncols=min(len(handles), 4), fontsize=8,
               frameon=False)
    fig.subplots_adjust(left=0.075, right=0.985, bottom=0.09, top=0.9, wspace=0.06, hspace=0.16)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})
    return path


def run_curves(run: RunData, path: Path) -> Path | None:
    """Held-out success and SPL of one run, one line per set (train dashed), shaded +- SE over episodes."""
    lines: dict[str, list[Line]] = {}
    for metric in ("success", "spl"):
        per_set = []
        for name in run.sets:
            pts = [(r.iteration, r.env_steps, getattr(m, metric), getattr(m, f"{metric}_se") or None)
                   for r in run.iterations if (m := r.heldout.get(name)) is not None]
            per_set.append(Line(name, pts))
        train = [(r.iteration, r.env_steps, getattr(r.train, metric), getattr(r.train, f"{metric}_se") or None)
                 for r in run.iterations if r.train is not None]
        per_set.append(Line("train", train, dashed=True, colour="#888888"))
        lines[metric] = per_set
    return _figure(lines, f"{run.label}: learning curves", path)


def experiment_curves(runs: dict[str, list[RunData]], set_name: str, path: Path) -> Path | None:
    """One held-out set across methods: mean over seeds per iteration, shaded +- standard error."""
    lines: dict[str, list[Line]] = {}
    for metric in ("success", "spl"):
        lines[metric] = [Line(method, [_point(p) for p in curve(method_runs, set_name, metric)])
                         for method, method_runs in runs.items()]
    return _figure(lines, f"held-out set '{set_name}': mean over seeds ± standard error", path)


def _point(p: tuple[int, float, Stat]) -> tuple[float, float, float, float | None]:
    t, steps, stat = p
    return (t, steps, stat.mean, stat.se)
