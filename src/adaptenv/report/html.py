"""Write the HTML report of a run or an experiment as a self-contained folder of files.

The folder holds ``index.html`` (CSS inlined, no scripts, no external fonts or URLs), the learning
curves under ``plots/``, copies of the renders under ``img/``, copies of the raw records under
``data/`` and, for an experiment, one run report per (method, seed) under ``runs/``. Every piece
of text read from files is HTML-escaped.

Example:
    >>> from adaptenv.report.html import build_report
    >>> build_report(Path("runs/accel/seed_0"))  # doctest: +SKIP
    PosixPath('runs/accel/seed_0/report/index.html')
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
from collections.abc import Iterable
from pathlib import Path
from urllib.parse import quote

from PIL import Image, UnidentifiedImageError

from adaptenv.curriculum.records import (
    ITERATIONS,
    ITERATIONS_CSV,
    RUN_INFO,
    IterationRecord,
    SetMetrics,
)
from adaptenv.curriculum.verdict import budget_line, lever_lines, verdict_lines
from adaptenv.errors import AdaptenvError
from adaptenv.files import atomic_path, atomic_write_text
from adaptenv.render.compare import BeforeAfter, render_before_after
from adaptenv.render.topdown import render_house
from adaptenv.report.data import (
    EditRow,
    ExperimentData,
    GalleryEntry,
    RunData,
    Stat,
    detect,
    final_stat,
    heldout_files,
    house_sets,
    is_number,
    last_with,
    load_experiment,
    load_gallery,
    load_run,
)
from adaptenv.report.plots import experiment_curves, run_curves
from adaptenv.scene.house import load_house
from adaptenv.sim.trajectory import Trajectory

GENERATOR = "adaptenv report"
INDEX = "index.html"
_OWNED = ("img", "plots", "runs", "data")
OWNS = (INDEX, *_OWNED)
"""Every top-level name a report writes into its folder."""
"""Sub-folders a report owns; cleared before a report is rewritten in place."""
CSS_FILE = Path(__file__).parent / "static" / "report.css"
GALLERY_SIZE = 640
"""Longer side (px) of the before/after renders the report draws itself."""


def esc(value: object) -> str:
    """HTML-escape any value's text (quotes too, so it is safe inside attributes)."""
    return html.escape(str(value), quote=True)


def safe_name(text: str) -> str:
    """A file-name-safe version of an id from a file (letters, digits, '.', '_', '-')."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("._") or "item"


def href(path: Path, base: Path) -> str:
    """URL of ``path`` relative to folder ``base`` (both inside the report), percent-encoded."""
    return quote(Path(os.path.relpath(path, base)).as_posix())


# --------------------------------------------------------------------------- numbers

def num(x: float | int | None, digits: int = 3) -> str:
    if x is None:
        return "–"
    if isinstance(x, int):
        return f"{x:,}"
    return f"{x:.{digits}f}"


def pct(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.1f}%"


def metric_text(metric: str, value: float | None) -> str:
    return pct(value) if metric == "success" else num(value)


def stat_cell(metric: str, stat: Stat | None, best: bool = False) -> str:
    """A ``<td>`` with mean and, when known, '± SE' in a muted span."""
    if stat is None:
        return "<td>–</td>"
    se = "" if stat.se is None else f' <span class="se">± {metric_text(metric, stat.se)}</span>'
    return f'<td{" class=best" if best else ""}>{metric_text(metric, stat.mean)}{se}</td>'


def set_cell(metric: str, m: SetMetrics | None) -> str:
    if m is None:
        return "<td>–</td>"
    se_val = getattr(m, f"{metric}_se")
    se = (' <span class="se">± n/a</span>' if se_val is None
          else f' <span class="se">± {metric_text(metric, se_val)}</span>' if se_val else "")
    return f"<td>{metric_text(metric, getattr(m, metric))}{se}</td>"


def stars(p: float) -> str:
    return "***" if p < 0.001 else "**" if p < 0.01 else "*" if p < 0.05 else ""


# --------------------------------------------------------------------------- page parts

def page(title: str, subtitle: str, nav: list[tuple[str, str]], body: str) -> str:
    """A whole HTML document with the stylesheet inlined."""
    css = CSS_FILE.read_text(encoding="utf-8")
    links = "".join(f'<a href="{esc(h)}">{esc(t)}</a>' for t, h in nav)
    return ("<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<meta name=\"generator\" content=\"{GENERATOR}\"><title>{esc(title)}</title>"
            f"<style>\n{css}</style></head>\n<body>\n"
            f"<header class=\"top\"><div class=\"wrap\"><h1>{esc(title)}</h1><p>{subtitle}</p></div></header>\n"
            f"<nav class=\"toc\"><div class=\"wrap\">{links}</div></nav>\n"
            f"<main class=\"wrap\">\n{body}\n</main>\n"
            "<footer><div class=\"wrap\">Written by <code>adaptenv report</code>. "
            "Works offline: every file this page uses is inside its folder.</div></footer>\n</body></html>\n")


def block(anchor: str, title: str, content: str) -> str:
    return f'<section class="block" id="{esc(anchor)}"><h2>{esc(title)}</h2>\n{content}\n</section>'


def table(head: str, rows: Iterable[str]) -> str:
    return f'<div class="tablewrap"><table><thead>{head}</thead><tbody>{"".join(rows)}</tbody></table></div>'


def cards(items: list[tuple[str, str]]) -> str:
    return '<div class="cards">' + "".join(
        f'<div class="card"><div class="k">{esc(k)}</div><div class="v">{esc(v)}</div></div>' for k, v in items) + "</div>"


def warnings_box(warnings: list[str], title: str = "Problems met while reading the records") -> str:
    if not warnings:
        return ""
    items = "".join(f"<li>{esc(w)}</li>" for w in warnings)
    return f'<div class="callout"><strong>{esc(title)}</strong><ul>{items}</ul></div>'


def plot_img(path: Path | None, base: Path, alt: str) -> str:
    if path is None:
        return '<p class="note">No held-out evaluations yet, so there is nothing to plot.</p>'
    w, h = _image_size(path) or (0, 0)
    size = f' width="{w}" height="{h}"' if w else ""
    return f'<img class="plot" src="{href(path, base)}" alt="{esc(alt)}"{size}>'


def _image_size(path: Path) -> tuple[int, int] | None:
    """Pixel size of an image file, or None when it is not a readable image."""
    try:
        with Image.open(path) as im:
            im.verify()
            return im.size
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError):
        return None


class Assets:
    """Copies files into the report folder under unique, safe names and hands back their URLs."""

    def __init__(self, root: Path, page_dir: Path):
        self.root, self.page_dir = root, page_dir
        self.used: set[Path] = set()

    def copy(self, src: Path, folder: str, name: str) -> Path:
        dest = self.reserve(folder, name)
        with atomic_path(dest) as tmp:
            shutil.copyfile(src, tmp)
        return dest

    def reserve(self, folder: str, name: str) -> Path:
        """A new, unique, safe path for a file called ``name`` under ``folder`` (parents created)."""
        stem, dot, ext = name.rpartition(".")
        sub = Path(*[safe_name(part) for part in Path(folder).parts])
        dest = self.root / sub / (safe_name(stem)[:60] + dot + safe_name(ext) if dot else safe_name(name)[:60])
        stem, suffix, k = dest.stem, dest.suffix, 1
        while dest in self.used:
            k += 1
            dest = dest.with_name(f"{stem}-{k}{suffix}")
        self.used.add(dest)
        dest.parent.mkdir(parents=True, exist_ok=True)
        return dest

    def image(self, src: Path | None, folder: str, name: str, alt: str) -> str:
        """An ``<img>`` (lazy, with its size, linking to the full image) or a placeholder when unusable."""
        if src is None:
            return f'<div class="missing">{esc(alt)}: no render recorded</div>'
        size = _image_size(src)
        if size is None:
            return f'<div class="missing">{esc(alt)}: render unreadable</div>'
        return self.img_tag(self.copy(src, folder, name), size, alt)

    def drawn(self, image, folder: str, name: str, alt: str) -> str:
        """Save a PIL image into the report and return its ``<img>``."""
        dest = self.reserve(folder, name)
        with atomic_path(dest) as tmp:
            image.save(tmp)
        return self.img_tag(dest, image.size, alt)

    def img_tag(self, dest: Path, size: tuple[int, int], alt: str) -> str:
        url = href(dest, self.page_dir)
        return (f'<a href="{url}"><img src="{url}" alt="{esc(alt)}" loading="lazy" '
                f'width="{size[0]}" height="{size[1]}"></a>')

    def link(self, src: Path, folder: str = "data", label: str | None = None) -> str:
        dest = self.copy(src, folder, src.name)
        return f'<a href="{href(dest, self.page_dir)}">{esc(label or src.name)}</a>'


# --------------------------------------------------------------------------- gallery

def outcome_html(analysis) -> str:
    o = analysis.outcome
    badge = '<span class="badge ok">success</span>' if o.success else (
        f'<span class="badge bad">failure{": " + esc(o.failure_mode) if o.failure_mode else ""}</span>')
    spl = f", SPL {num(o.spl, 2)}" if o.spl is not None else ""
    figures = "" if f"{o.steps} steps" in o.summary else f' <span class="muted">({o.steps} steps{spl})</span>'
    source = f' <span class="muted">(analysis by {esc(analysis.source)})</span>' if analysis.source else ""
    return (f"<p>{badge} {esc(o.summary)}{figures}{source}</p>"
            f'<p class="note">{esc(analysis.task)}</p>')


def analysis_html(analysis) -> str:
    """Outcome, concerns and suggestions as readable lists."""
    if analysis is None:
        return '<h5>Analysis</h5><p class="note">No analysis recorded for this scene.</p>'
    concerns = []
    for c in analysis.concerns:
        where = f", near grid ({c.where.x:.0f}, {c.where.y:.0f})" if c.where else ""
        steps = (f", steps {c.steps[0]}–{c.steps[-1]}" if len(c.steps) > 1 and c.steps[0] != c.steps[-1]
                 else f", step {c.steps[0]}" if c.steps else "")
        steps += f", {c.count} times" if c.count > 1 else ""
        objs = f" <span class=\"muted\">objects: {esc(', '.join(c.objects))}</span>" if c.objects else ""
        concerns.append(f'<li><span class="kind">{esc(c.kind)}</span> {esc(c.description)} '
                        f'<span class="muted">[{esc(c.id)}, severity {c.severity:.2f}{esc(where)}{esc(steps)}]</span>{objs}</li>')
    suggestions = []
    for s in analysis.suggestions:
        addr = f"addresses {', '.join(s.addresses)}" if s.addresses else "general difficulty"
        suggestions.append(f'<li><span class="kind">{esc(s.kind)}</span> {esc(s.description)} '
                           f'<span class="muted">[{esc(s.id)}, priority {s.priority:.2f}, {esc(addr)}]</span></li>')
    return ("<h5>Analysis</h5>" + outcome_html(analysis) + '<div class="cols"><div>'
            + "<h5>Concerns</h5>" + (f"<ul>{''.join(concerns)}</ul>" if concerns else '<p class="note">none</p>')
            + "</div><div><h5>Suggestions</h5>"
            + (f"<ol>{''.join(suggestions)}</ol>" if suggestions else '<p class="note">none</p>') + "</div></div>")


def _move(d: tuple[float, float]) -> str:
    return f"({d[0]:+.1f}, {d[1]:+.1f})"


def _verdict(e: EditRow) -> str:
    if not e.accepted:
        return '<span class="badge bad">rejected</span>' if e.object_id != "-" else f'<span class="badge na">{esc(e.stop_reason)}</span>'
    if e.outcome:  # no-op or undone: not in the scene, never "accepted" or "verified"
        return f'<span class="badge na">{esc(e.outcome)}</span>'
    if e.verified is True:
        how = f" ({esc(e.verification)})" if e.verification and e.verification != "none" else ""
        return f'<span class="badge ok">verified{how}</span>'
    if e.verified is False:
        return '<span class="badge bad">failed check</span>'
    if not e.verification:  # an EditLog: validation kept the edit, verification not recorded
        return '<span class="badge ok">accepted</span>'
    return '<span class="badge na">accepted, not verified</span>'


def edits_html(entry: GalleryEntry) -> str:
    """The edit table: object, requested vs achieved move (grid units), rotation, stop reason, verification."""
    gen = f' <span class="muted">(generator: {esc(entry.generator)})</span>' if entry.generator else ""
    if not entry.edits:
        return f'<h5>Edits</h5><p class="note">No edits recorded for this scene.{gen}</p>'
    head = ("<tr><th>#</th><th class=l>object</th><th>requested (dx, dy)</th><th>achieved (dx, dy)</th>"
            "<th>rotation</th><th class=l>stop reason</th><th class=l>result</th><th class=l>note</th></tr>")
    rows = []
    for k, e in enumerate(entry.edits, 1):
        if e.object_id == "-":
            rows.append(f"<tr><td>{k}</td><td class=l>–</td><td>–</td><td>–</td><td>–</td><td class=l>–</td>"
                        f"<td class=l>{_verdict(e)}</td><td class=wrap-text>{esc(e.note)}</td></tr>")
            continue
        rot = "–" if e.rotation is None else f"{e.rotation:.0f}° ({e.yaw_before:.0f}°→{e.yaw_after:.0f}°)"
        stop = esc(e.stop_reason) + (f'<br><span class="muted">by {esc(e.blocked_by)}</span>' if e.blocked_by else "")
        note = " ".join(x for x in (e.note, f"intent: {e.intent}" if e.intent else "") if x)
        rows.append(f"<tr><td>{k}</td><td class=l><code>{esc(e.object_id)}</code></td><td>{_move(e.requested)}</td>"
                    f"<td>{_move(e.achieved)}</td><td>{esc(rot)}</td><td class=l>{stop}</td>"
                    f"<td class=l>{_verdict(e)}</td><td class=wrap-text>{esc(note)}</td></tr>")
    return (f"<h5>Edits{gen}</h5>" + table(head, rows)
            + '<p class="note">Moves in grid units of the normalized 0..100 map (+dx right, +dy up); '
              "rotation is the requested absolute yaw (yaw before → after).</p>")


def draw_pair(entry: GalleryEntry) -> BeforeAfter | None:
    """Draw the scene's two episodes with :func:`render_before_after` (None, with a warning, when it cannot)."""
    files = entry.episodes
    if files is None:
        return None
    try:
        houses = [load_house(p) for p in (files.before_house, files.after_house)]
        trajs = [Trajectory.load(p) for p in (files.before_trajectory, files.after_trajectory)]
        return render_before_after(*houses, *trajs, size=GALLERY_SIZE)
    except (AdaptenvError, ValueError, OSError) as exc:
        entry.warnings.append(f"cannot draw the two episodes ({str(exc).splitlines()[0]}); showing the recorded renders")
        return None


def changes_html(pair: BeforeAfter) -> str:
    """The figures of both episodes side by side, coloured by whether the agent did better or worse."""
    rows = []
    for c in pair.changes:
        cls = " class=better" if c.trend > 0 else " class=worse" if c.trend < 0 else ""
        rows.append(f"<tr><td class=l>{esc(c.name)}</td><td>{esc(c.before)}</td><td{cls}>{esc(c.after)}</td></tr>")
    moved = ", ".join(f"<code>{esc(m)}</code>" for m in pair.moved) or "none"
    return ("<h5>What changed for pi_t</h5>" + table("<tr><th class=l>figure</th><th>before (e_t)</th>"
                                                     "<th>after (e_t+1)</th></tr>", rows)
            + f'<p class="note">Same start and target on both sides. Moved objects (cyan in the after render): '
              f"{moved}. Green: better for the agent; red: worse (the edit made the task harder).</p>")


def scene_html(entry: GalleryEntry, assets: Assets, t: int, k: int) -> str:
    folder = f"img/iter_{t:04d}/{k:02d}_{safe_name(entry.scene)[:40]}"
    pair = draw_pair(entry)
    if pair is not None:
        before = assets.drawn(pair.before, folder, "before.png", f"{entry.scene}, before")
        after = assets.drawn(pair.after, folder, "after.png", f"{entry.scene}, after")
        after_caption = "after: pi_t's own episode in the edited scene e_t+1 (moved objects in cyan)"
        changes = changes_html(pair)
    else:
        before = assets.image(entry.before, folder, "before.png", f"{entry.scene}, before")
        after = assets.image(entry.after, folder, "after.png", f"{entry.scene}, after")
        after_caption = ("after: the edited scene as the run rendered it (this run did not record pi_t's "
                         "episode there, so any path drawn may be the before episode's)")
        changes = ""
    summary = f' <span class="muted">— {esc(entry.summary)}</span>' if entry.summary else ""
    return (f'<article class="scene" id="iter-{t}-scene-{k}"><h4><code>{esc(entry.scene)}</code>{summary}</h4>'
            f'<div class="pair"><figure>{before}<figcaption>before: pi_t in e_t</figcaption></figure>'
            f"<figure>{after}<figcaption>{esc(after_caption)}</figcaption></figure></div>{changes}"
            f'<div class="analysis">{analysis_html(entry.analysis)}</div><div class="edits">{edits_html(entry)}</div>'
            f"{warnings_box(entry.warnings, 'Missing or unreadable files')}</article>")


def gallery_html(run: RunData, assets: Assets) -> str:
    parts = []
    for r in reversed(run.iterations):
        if not r.gallery:
            continue
        scenes = "".join(scene_html(load_gallery(run.path, item), assets, r.iteration, k)
                         for k, item in enumerate(r.gallery, 1))
        n = len(r.gallery)
        parts.append(f'<details class="iter" id="iter-{r.iteration}" open><summary>Iteration {r.iteration} '
                     f'<span class="muted">— {n} adapted scene{"s" if n != 1 else ""}</span></summary>'
                     f'<div class="body">{scenes}</div></details>')
    if not parts:
        return '<p class="note">No adapted scenes were recorded in the finished iterations.</p>'
    return '<p class="note">Latest iteration first. Click a render to open it at full size.</p>' + "".join(parts)


# --------------------------------------------------------------------------- reading aids

GLOSSARY = [
    ("pi_t", "the agent's policy after t closed-loop iterations; pi_0 is the starting (pretrained) policy."),
    ("e_t", "a training scene (house) at iteration t; e_t+1 is the scene after G edited it."),
    ("tau", "a trajectory: one recorded episode of pi_t in e_t (the path drawn on the renders)."),
    ("F", "the analysis step: reads tau and returns outcome, concerns and abstract suggestions."),
    ("G", "the generator: turns F's suggestions into single-object moves on the 0..100 grid, each validated "
          "(and verified when the generator checks its edits)."),
    ("Delta R", "the improvement on held-out houses: held-out success of pi_t minus that of pi_0 on the same "
                "episodes. The paper's G is good when Delta R is positive."),
    ("ours", "the paper's method: F then G on pi_t's own failures (ours-llm: F and G are language models)."),
    ("dr, plr, accel, random", "baselines: domain randomisation (fresh houses), prioritized level replay, "
                               "ACCEL (replay plus random edits), and random edits without F."),
    ("house_00~t02a00", "a scene id: base house house_00, made at iteration t=02 by adaptation (a; r: random "
                        "edit, c: ACCEL child), 00th of that iteration."),
    ("grid units", "positions and moves on the paper's normalized map: 0..100 across the house, x right, y up "
                   "(metres are world units)."),
]

KIND_TEXT = {"narrow_passage": "narrow a passage", "occlude_target": "hide the target",
             "lengthen_route": "lengthen the route", "add_clutter": "add clutter"}
THUMBS = 8
"""Thumbnails shown per house set."""


def glossary_html() -> str:
    """The paper's symbols and the report's names, in plain words."""
    rows = "".join(f"<dt><code>{esc(k)}</code></dt><dd>{esc(v)}</dd>" for k, v in GLOSSARY)
    return f'<dl class="glossary">{rows}</dl>'


CURVES_NOTE = ("How to read the curves: each point is held-out success (or SPL) of the policy after that "
               "iteration, on the same episodes every time; iteration 0 is pi_0. Delta R is a point's height above "
               "iteration 0. A fall smaller than about two standard errors (the ± in the results table) is noise. "
               "A steady fall means fine-tuning on the adapted scenes made the agent worse on houses it never "
               "trains on (forgetting or overfitting to edits), not that those houses got harder: held-out "
               "houses never change.")


def houses_html(run: RunData, assets: Assets) -> str:
    """Thumbnails of the training and held-out houses named in the run's config."""
    sets = house_sets(run)
    if not sets:
        return '<p class="note">The run records no house sets (run.json has no config).</p>'
    parts = []
    for hs in sets:
        head = f"<h3>{esc(hs.name)} <span class=\"muted\">({esc(hs.spec)}, {len(hs.files)} houses)</span></h3>"
        if not hs.files:
            parts.append(head + f'<p class="note">No thumbnails: {esc(hs.note)}.</p>')
            continue
        figs = []
        for f in hs.files[:THUMBS]:
            try:
                image = render_house(load_house(f), size=256, labels=False, legend=False, title=f.stem)
            except (AdaptenvError, ValueError, OSError) as exc:
                figs.append(f'<div class="missing">{esc(f.name)}: {esc(str(exc).splitlines()[0])}</div>')
                continue
            figs.append(f"<figure>{assets.drawn(image, f'img/houses/{hs.name}', f.stem + '.png', f.stem)}</figure>")
        more = f'<p class="note">and {len(hs.files) - THUMBS} more.</p>' if len(hs.files) > THUMBS else ""
        parts.append(head + f'<div class="thumbs">{"".join(figs)}</div>{more}')
    return "".join(parts)


def heldout_html(run: RunData, assets: Assets) -> str:
    """Per held-out set: a table per house and the failed episodes' renders (when the run wrote them)."""
    found = heldout_files(run)
    if not found:
        return ('<p class="note">This run wrote no per-house held-out results (iter_XXXX/heldout/&lt;set&gt;/'
                "houses.csv); run <code>adaptenv evaluate</code> on a checkpoint for them.</p>")
    parts = []
    cols = ("episodes", "success", "spl", "collisions", "steps")
    for h in found:
        rows = []
        for row in h.rows:
            cells = "".join(f"<td>{esc(_cell(row.get(c, '')))}</td>" for c in cols)
            rows.append(f"<tr><td class=l><code>{esc(row.get('house', ''))}</code></td>{cells}</tr>")
        head = "<tr><th class=l>house</th>" + "".join(f"<th>{c}</th>" for c in cols) + "</tr>"
        failed = any(float(row.get("success") or 1.0) < 1.0 for row in h.rows)
        fail = (assets.image(h.failures, f"img/heldout/{h.name}", "failures.png", f"{h.name}: failed episodes")
                if h.failures else '<p class="note">' + ("No renders of the failed episodes were recorded for this "
                                                         "evaluation; <code>adaptenv evaluate</code> on this "
                                                         "iteration's policy.pt draws them." if failed else
                                                         "No failed episodes.") + "</p>")
        parts.append(f"<h3>{esc(h.name)} <span class=\"muted\">(iteration {h.iteration})</span></h3>"
                     + table(head, rows) + "<h5>Failed episodes</h5>" + fail)
    return "".join(parts)


def _cell(text: str) -> str:
    try:
        x = float(text)
    except ValueError:
        return text
    return f"{x:.0f}" if x == round(x) and abs(x) >= 1 else f"{x:.3f}"


def intents_html(run: RunData) -> str:
    """How many gallery edits pursued each intent (narrow a passage, hide the target, ...), and how they ended."""
    counts: dict[str, list[int]] = {}
    for r in run.iterations:
        for item in r.gallery:
            for e in load_gallery(run.path, item).edits:
                if e.object_id == "-":
                    continue
                kind = e.kind or next((k for k in KIND_TEXT if k in e.intent), "")  # "s1 narrow_passage: ..."
                label = KIND_TEXT.get(kind, kind) or (e.intent[:60] if e.intent else "(intent not recorded)")
                c = counts.setdefault(label, [0, 0, 0])
                c[0] += 1
                c[1] += int(e.accepted)
                c[2] += int(bool(e.verified))
    if not counts:
        return '<p class="note">No edits recorded in the gallery.</p>'
    rows = [f"<tr><td class=l>{esc(k)}</td><td>{n}</td><td>{a}</td><td>{v}</td></tr>"
            for k, (n, a, v) in sorted(counts.items(), key=lambda kv: -kv[1][0])]
    return (table("<tr><th class=l>intent</th><th>edits</th><th>accepted</th><th>verified</th></tr>", rows)
            + '<p class="note">Over the adapted scenes of the gallery (not every scene of the run).</p>')


# --------------------------------------------------------------------------- run page

def results_table(run: RunData) -> str:
    sets = run.sets
    head = ('<tr><th rowspan=2>iteration</th><th rowspan=2>env steps</th><th rowspan=2>grad updates</th>'
            '<th rowspan=2>edits</th>' + "".join(f"<th colspan=2 class=group>{esc(s)}</th>" for s in ["train", *sets])
            + "<th rowspan=2>wall time</th></tr><tr>" + "<th>success</th><th>SPL</th>" * (1 + len(sets)) + "</tr>")
    rows = []
    for r in run.iterations:
        anchor = f'<a href="#iter-{r.iteration}">{r.iteration}</a>' if r.gallery else str(r.iteration)
        rows.append(f"<tr><td>{anchor}</td><td>{num(r.env_steps)}</td><td>{num(r.grad_updates)}</td>"
                    f"<td>{num(r.edits)}</td>{set_cell('success', r.train)}{set_cell('spl', r.train)}"
                    + "".join(set_cell("success", r.heldout.get(s)) + set_cell("spl", r.heldout.get(s)) for s in sets)
                    + f"<td>{_duration(r.wall_time_s)}</td></tr>")
    return table(head, rows) + ('<p class="note">Env steps, gradient updates and edits are cumulative. Train figures '
                                "are pi_t on its training scenes; held-out figures are pi_{t+1}; ± is the "
                                "standard error over episodes when recorded.</p>")


def llm_usage_table(run: RunData) -> str:
    """LLM tokens, calls, retries, cache hits and cost per iteration and role (ours-llm runs); empty otherwise."""
    rows = []
    for r in run.iterations:
        u = r.llm_usage
        if not u:
            continue
        for role, v in [("all", u), *sorted((u.get("by_role") or {}).items())]:
            cost = f"${v['cost_usd']:.4f}" if "cost_usd" in v else "–"
            rows.append(f"<tr><td>{r.iteration}</td><td>{esc(role)}</td><td>{num(v['input_tokens'])}</td>"
                        f"<td>{num(v.get('cached_tokens', 0))}</td><td>{num(v['output_tokens'])}</td>"
                        f"<td>{num(v['calls'])}</td><td>{num(v.get('retries', 0))}</td>"
                        f"<td>{num(v.get('cache_hits', 0))}</td><td>{cost}</td></tr>")
    if not rows:
        return ""
    head = ("<tr><th>iteration</th><th>role</th><th>input tokens</th><th>cached</th><th>output tokens</th>"
            "<th>calls</th><th>retries</th><th>cache hits</th><th>cost</th></tr>")
    return table(head, rows) + ('<p class="note">Roles: F analysis, G move proposals, verify verification. Cost '
                                "is estimated from the prices in the run's LLM config (– without prices); the run "
                                "total is in llm_usage.json.</p>")


def _duration(s: float) -> str:
    if s <= 0:
        return "–"
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} min" if s < 7200 else f"{s / 3600:.1f} h"


def key_figures(run: RunData) -> str:
    last = run.last
    if last is None:
        return ""
    items = [("iteration", str(last.iteration)), ("env steps", num(last.env_steps)),
             ("gradient updates", num(last.grad_updates)), ("edits", num(last.edits))]
    for s in run.sets:
        if (r := last_with(run, s)) is not None:
            items.append((f"{s}: success / SPL", f"{pct(r.heldout[s].success)} / {num(r.heldout[s].spl, 2)}"))
    return cards(items)


def run_meta(run: RunData) -> str:
    parts = []
    if run.info is not None:
        if run.info.command:
            parts.append(f"<p><strong>Command:</strong> <code>{esc(run.info.command)}</code></p>")
        if run.info.config:
            cfg = json.dumps(run.info.config, indent=2, sort_keys=True, default=str)
            parts.append(f"<details><summary>Config ({len(run.info.config)} fields)</summary><pre>{esc(cfg)}</pre></details>")
    return "".join(parts)


def write_run_report(run: RunData, out: Path, *, back: tuple[str, str] | None = None) -> Path:
    """Write one run's report into ``out`` (index.html plus its files); returns index.html's path."""
    out.mkdir(parents=True, exist_ok=True)
    assets = Assets(out, out)
    subtitle = f"Run folder: {esc(run.path)}"
    if back is not None:
        subtitle = f'<a href="{esc(back[1])}">← {esc(back[0])}</a> · ' + subtitle
    files = [p for p in (run.path / RUN_INFO, run.path / ITERATIONS, run.path / ITERATIONS_CSV) if p.is_file()]
    data_links = " · ".join(assets.link(p) for p in files)
    overview = key_figures(run) + run_meta(run) + (f'<p class="note">Raw records: {data_links}</p>' if files else "")
    body = [warnings_box(run.warnings)]
    if not run.iterations:
        body.append(block("overview", "Overview", overview + (
            '<div class="callout empty"><strong>No iterations have finished yet.</strong> '
            f"This run has no records in {ITERATIONS}; the report fills in once the loop finishes its first "
            "iteration (run <code>adaptenv report</code> again).</div>")))
        nav = [("Overview", "#overview")]
    else:
        plot = run_curves(run, out / "plots" / "curves.png")
        body += [block("overview", "Overview", overview),
                 block("curves", "Learning curves", plot_img(plot, out, "held-out success and SPL against iterations "
                                                                        "and environment steps")
                       + f'<p class="note">{esc(CURVES_NOTE)}</p>'),
                 block("results", "Results per iteration", results_table(run)),
                 block("houses", "Houses", houses_html(run, assets)),
                 block("heldout", "Held-out houses, one by one", heldout_html(run, assets)),
                 block("intents", "What the edits tried", intents_html(run)),
                 block("gallery", "Gallery: before and after each adaptation", gallery_html(run, assets)),
                 block("glossary", "Glossary", glossary_html())]
        nav = [("Overview", "#overview"), ("Learning curves", "#curves"), ("Results", "#results"),
               ("Houses", "#houses"), ("Held-out", "#heldout"), ("Edits", "#intents"), ("Gallery", "#gallery"),
               ("Glossary", "#glossary")]
        if usage := llm_usage_table(run):  # before the gallery
            body.insert(-2, block("llm", "LLM usage per iteration", usage))
            nav.insert(-2, ("LLM usage", "#llm"))
    if back is not None:
        nav.insert(0, (f"← {back[0]}", back[1]))
    index = out / INDEX
    atomic_write_text(index, page(f"Run report: {run.label}", subtitle, nav, "\n".join(b for b in body if b)))
    return index


# --------------------------------------------------------------------------- experiment page

def summary_table(exp: ExperimentData) -> str:
    """Per method: seeds, final iteration, env steps, gradient updates, then per set success and SPL (mean ± SE)."""
    sets, show_p = exp.sets, bool(exp.pvalues)
    stats = {(m, s, k): final_stat(runs, s, k) for m, runs in exp.runs.items() for s in sets for k in ("success", "spl")}
    best = {}
    for s in sets:
        for k in ("success", "spl"):
            means = [st.mean for m in exp.methods if (st := stats[(m, s, k)]) is not None]
            best[(s, k)] = max(means) if len(means) > 1 else None
    per_set = 3 if show_p else 2
    head = ('<tr><th class=l rowspan=2>method</th><th rowspan=2>seeds</th><th rowspan=2>iterations</th>'
            '<th rowspan=2>env steps</th><th rowspan=2>grad updates</th>'
            + "".join(f"<th colspan={per_set} class=group>held-out: {esc(s)}</th>" for s in sets) + "</tr><tr>"
            + "".join("<th>success</th><th>SPL</th>" + ("<th class=l>significance</th>" if show_p else "") for _ in sets)
            + "</tr>")
    rows = []
    for m, runs in exp.runs.items():
        lasts = [r.last for r in runs if r.last is not None]
        iters = mean_text([x.iteration for x in lasts], 1)
        steps = mean_text([x.env_steps for x in lasts], 0)
        grads = mean_text([x.grad_updates for x in lasts], 0)
        cells = [f"<td class=l><strong>{esc(m)}</strong></td><td>{len(runs)}</td><td>{iters}</td><td>{steps}</td>"
                 f"<td>{grads}</td>"]
        for s in sets:
            for k in ("success", "spl"):
                st = stats[(m, s, k)]
                cells.append(stat_cell(k, st, best=st is not None and best[(s, k)] is not None and st.mean == best[(s, k)]))
            if show_p:
                cells.append(f"<td class=l>{esc(pvalue_text(exp, m, s))}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    notes = ["Each run's latest evaluation of a set, averaged over seeds; ± is the standard error over seeds "
             "(shown with two or more seeds); the best mean per column is bold."]
    if show_p:
        test = f" ({esc(exp.test)})" if exp.test else ""
        what = (f"compares {esc(exp.reference)} with the method of each row" if exp.reference
                else f"compares each method with {esc(exp.baseline)}" if exp.baseline else "")
        notes.append(f"Significance{test} is taken from summary.json{': ' + what if what else ''}; "
                     "* p &lt; 0.05, ** p &lt; 0.01, *** p &lt; 0.001.")
    return table(head, rows) + "".join(f'<p class="note">{n}</p>' for n in notes)


def final_tables(exp: ExperimentData) -> str:
    """The final evaluation (summary_final.json): success and SPL per method and set, then the reference minus each
    method on success with its 95% interval, p and Holm's p (what docs/RESULTS.md quotes)."""
    final = exp.final or {}
    methods: dict[str, dict] = final.get("methods", {})
    sets = sorted({k.split(":", 1)[1] for figs in methods.values() for k in figs if k.startswith("success:")})
    if not methods or not sets:
        return '<p class="note">summary_final.json holds no held-out figures.</p>'

    def cell(metric: str, fig: dict | None) -> str:
        if not isinstance(fig, dict) or not is_number(fig.get("mean")):
            return "<td>–</td>"
        return stat_cell(metric, Stat(fig["mean"], fig["se"] if is_number(fig.get("se")) else None, fig.get("n", 0)))

    head = ('<tr><th class=l rowspan=2>method</th><th rowspan=2>seeds</th>'
            + "".join(f"<th colspan=2 class=group>{esc(s)}</th>" for s in sets) + "</tr><tr>"
            + "<th>success</th><th>SPL</th>" * len(sets) + "</tr>")
    rows = [f"<tr><td class=l><strong>{esc(m)}</strong></td><td>{esc(_seeds(figs))}</td>"
            + "".join(cell("success", figs.get(f"success:{s}")) + cell("spl", figs.get(f"spl:{s}")) for s in sets)
            + "</tr>" for m, figs in methods.items()]
    ref = final.get("reference")
    effects, tests, holm = final.get("effects", {}), final.get("tests", {}), final.get("holm", {})
    diff_rows = []
    for m in effects:
        for s in sets:
            e, key = effects[m].get(f"success:{s}"), f"success:{s}"
            if not isinstance(e, dict) or not is_number(e.get("diff")):
                continue
            p, ph = tests.get(m, {}).get(key), holm.get(m, {}).get(key)
            interval = (f"[{100 * e['low']:+.1f}, {100 * e['high']:+.1f}]"
                        if is_number(e.get("low")) and is_number(e.get("high")) else "–")
            diff_rows.append(f"<tr><td class=l>{esc(m)}</td><td class=l>{esc(s)}</td><td>{100 * e['diff']:+.1f}</td>"
                             f"<td>{interval}</td><td>{_p(p)}</td><td>{_p(ph)}</td></tr>")
    episodes = final.get("episodes")
    what = f"on {episodes:,} episodes per held-out set" if isinstance(episodes, int) else "on its held-out sets"
    out = table(head, rows) + (
        f'<p class="note">Each run\'s last policy evaluated {what} (the same episodes for every method of a seed), '
        "averaged over seeds; ± is the standard error over seeds.</p>")
    if diff_rows:
        out += (f"<h3>{esc(ref)} minus each method: held-out success (points)</h3>"
                + table("<tr><th class=l>method</th><th class=l>set</th><th>difference</th><th>95% interval</th>"
                        "<th>p (paired t)</th><th>p (Holm)</th></tr>", diff_rows)
                + f'<p class="note">Paired by seed. Holm\'s correction runs over all {len(diff_rows)} comparisons '
                  "of this table. * p &lt; 0.05, ** p &lt; 0.01, *** p &lt; 0.001.</p>")
    return out


def _p(p: object) -> str:
    return f"{p:.3g}{stars(p)}" if is_number(p) else "–"


def _seeds(figs: dict) -> str:
    ns = [f["n"] for f in figs.values() if isinstance(f, dict) and isinstance(f.get("n"), int)]
    return str(max(ns)) if ns else "–"


def mean_text(values: list[float], digits: int) -> str:
    if not values:
        return "–"
    mean = sum(values) / len(values)
    return f"{mean:,.{digits}f}" if digits and mean != round(mean) else f"{round(mean):,}"


def pvalue_text(exp: ExperimentData, method: str, set_name: str) -> str:
    parts = []
    for metric, label in (("success", "success"), ("spl", "SPL"), ("", "")):
        p = exp.pvalues.get((method, set_name, metric))
        if p is not None:
            parts.append(f"{label + ' ' if label else ''}p={p:.3g}{stars(p)}")
    return ", ".join(parts) or "–"


def runs_table(exp: ExperimentData, links: dict[Path, str]) -> str:
    sets = exp.sets
    head = ("<tr><th class=l rowspan=2>method</th><th rowspan=2>seed</th><th rowspan=2>iterations</th>"
            "<th rowspan=2>env steps</th><th rowspan=2>grad updates</th>"
            + "".join(f"<th colspan=2 class=group>{esc(s)}</th>" for s in sets)
            + "<th class=l rowspan=2>report</th></tr><tr>" + "<th>success</th><th>SPL</th>" * len(sets) + "</tr>")
    rows = []
    for m, runs in exp.runs.items():
        for run in runs:
            last: IterationRecord | None = run.last
            seed = run.info.seed if run.info else run.path.name
            cells = (f"<td class=l>{esc(m)}</td><td>{esc(seed)}</td><td>{len(run.iterations)}</td>"
                     f"<td>{num(last.env_steps) if last else '–'}</td><td>{num(last.grad_updates) if last else '–'}</td>")
            for s in sets:
                r = last_with(run, s)
                cells += set_cell("success", r.heldout[s] if r else None) + set_cell("spl", r.heldout[s] if r else None)
            warn = f' <span class="muted">({len(run.warnings)} warning{"s" if len(run.warnings) != 1 else ""})</span>' \
                if run.warnings else ""
            cells += f'<td class=l><a href="{esc(links[run.path])}">run report</a>{warn}</td>'
            rows.append(f"<tr>{cells}</tr>")
    return table(head, rows)


def verdict_html(exp: ExperimentData) -> str:
    """The page's opening lines: summary.json's lever line and verdict of the reference against each method."""
    summary = exp.summary if isinstance(exp.summary, dict) else {}
    try:
        lines = lever_lines(summary) + verdict_lines(summary) if summary.get("reference") else []
        lines += [b] if lines and (b := budget_line(summary)) else []
    except (KeyError, TypeError):  # a summary.json written by something else
        lines = []
    return "".join(f'<p class="verdict"><strong>{esc(line)}</strong></p>' for line in lines)


def write_experiment_report(exp: ExperimentData, out: Path) -> Path:
    """Write the experiment report (summary, curves per set, per-run reports) into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    assets = Assets(out, out)
    links: dict[Path, str] = {}
    for m, runs in exp.runs.items():
        for run in runs:
            run_out = out / "runs" / safe_name(m) / safe_name(run.path.name)
            index = write_run_report(run, run_out, back=("experiment", href(out / INDEX, run_out)))
            links[run.path] = href(index, out)
    n_runs = sum(len(r) for r in exp.runs.values())
    seeds = sorted({r.info.seed for runs in exp.runs.values() for r in runs if r.info is not None})
    overview = cards([("methods", str(len(exp.runs))), ("runs", str(n_runs)), ("seeds", str(len(seeds))),
                      ("held-out sets", str(len(exp.sets)))])
    if exp.files:
        links_ = [assets.link(p, str(Path("data") / p.parent.relative_to(exp.path)), p.relative_to(exp.path).as_posix())
                  for p in exp.files]
        overview += '<p class="note">Data: ' + " · ".join(links_) + "</p>"
    body = [verdict_html(exp), warnings_box(exp.warnings), block("overview", "Overview", overview)]
    nav = [("Overview", "#overview")]
    if not any(run.iterations for runs in exp.runs.values() for run in runs):
        body.append('<div class="callout empty"><strong>No run has finished an iteration yet.</strong> '
                    "The summary and curves appear once runs write iterations.jsonl.</div>")
    else:
        curves = []
        for s in exp.sets:
            plot = experiment_curves(exp.runs, s, out / "plots" / f"curves_{safe_name(s)}.png")
            curves.append(f"<h3>{esc(s)}</h3>" + plot_img(plot, out, f"{s}: success and SPL per method"))
        if exp.final is not None:
            body.append(block("final", "Final evaluation", final_tables(exp)))
            nav.append(("Final evaluation", "#final"))
        body += [block("summary", "Summary", summary_table(exp)),
                 block("curves", "Learning curves", ("".join(curves) or '<p class="note">No held-out evaluations yet.</p>')
                       + f'<p class="note">{esc(CURVES_NOTE)}</p>')]
        nav += [("Summary", "#summary"), ("Learning curves", "#curves")]
    body.append(block("runs", "Runs", runs_table(exp, links)))
    body.append(block("glossary", "Glossary", glossary_html()))
    nav += [("Runs", "#runs"), ("Glossary", "#glossary")]
    title = f"Experiment report: {exp.path.resolve().name}"
    subtitle = f"Experiment folder: {esc(exp.path)} · methods: {esc(', '.join(exp.methods))}"
    index = out / INDEX
    atomic_write_text(index, page(title, subtitle, nav, "\n".join(b for b in body if b)))
    return index


# --------------------------------------------------------------------------- entry point

def _prepare_out(out: Path, source: Path) -> None:
    """Create the output folder (``adaptenv report`` removes its own earlier report first, and nothing else)."""
    if out.resolve() == source.resolve():
        raise AdaptenvError(f"{out}: the report cannot be written into the folder it reads; "
                            "pass another -o folder (default: <folder>/report)")
    if out.exists() and not out.is_dir():
        raise AdaptenvError(f"{out}: exists and is not a folder; pass a folder to -o")
    out.mkdir(parents=True, exist_ok=True)


def build_report(path: Path, out: Path | None = None) -> Path:
    """Write the report of a run or experiment folder (default into ``<path>/report``); returns index.html."""
    path = Path(path)
    kind = detect(path)
    out = Path(out) if out is not None else path / "report"
    run = load_run(path) if kind == "run" else None
    if run is not None and run.info is None and not run.iterations:
        raise AdaptenvError(f"{path}: nothing of the run is readable ({'; '.join(run.warnings)}); pass the folder a "
                            "closed-loop run wrote")
    _prepare_out(out, path)
    if run is not None:
        return write_run_report(run, out)
    return write_experiment_report(load_experiment(path), out)
