"""The report in a real headless Chromium: every image loads, no script or console errors, true "after" pictures.

The report page is copied next to itself with a small probe script injected at the top of
``<head>``; the probe opens every ``<details>``, makes lazy images eager, waits for them, and writes
what it found (broken images, caught errors, script count) into a hidden element, which is read
back from ``--dump-dom``. Console messages are read from Chromium's log on stderr.
CI installs the browser with ``apt-get install -y chromium`` (Debian).
"""

from __future__ import annotations

import html
import json
import re
import subprocess
from pathlib import Path

import pytest
from PIL import Image

from adaptenv.report import build_report

CHROMIUM = Path("/usr/bin/chromium")
WINDOW = (1400, 900)
"""The probe's window: a report must fit its width (no sideways scrolling)."""
pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason="needs /usr/bin/chromium (apt-get install -y chromium)")

PROBE = """<script>
window.__errors = [];
window.addEventListener('error', function (e) {
  var t = e.target;
  if (t && t !== window && (t.src || t.href)) { window.__errors.push('resource failed: ' + (t.src || t.href)); }
  else { window.__errors.push('script error: ' + e.message); }
}, true);
window.addEventListener('unhandledrejection', function (e) { window.__errors.push('unhandled rejection: ' + e.reason); });
(function () {
  var orig = console.error;
  console.error = function () { window.__errors.push('console.error: ' + Array.prototype.join.call(arguments, ' ')); orig.apply(console, arguments); };
})();
window.addEventListener('load', function () {
  document.querySelectorAll('details').forEach(function (d) { d.open = true; });
  var imgs = Array.prototype.slice.call(document.images);
  imgs.forEach(function (img) { img.loading = 'eager'; });
  Promise.all(imgs.map(function (img) {
    return img.complete ? Promise.resolve() : new Promise(function (done) {
      img.addEventListener('load', done); img.addEventListener('error', done); });
  })).then(function () {
    var broken = imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0); })
                     .map(function (i) { return i.getAttribute('src'); });
    var wide = Array.prototype.slice.call(document.querySelectorAll('body *'))
                    .filter(function (e) { return e.getBoundingClientRect().right > window.innerWidth; })
                    .slice(0, 5).map(function (e) { return e.tagName + '.' + e.className; });
    var out = {images: imgs.length, broken: broken, errors: window.__errors, scripts: document.scripts.length,
               scroll_width: document.documentElement.scrollWidth, window_width: window.innerWidth, wide: wide};
    var el = document.createElement('pre');
    el.id = '__report_check'; el.hidden = true; el.textContent = JSON.stringify(out);
    document.body.appendChild(el);
  });
});
</script>"""


def chromium_args(user_data: Path) -> list[str]:
    """Headless, offline-friendly flags (no sync, updates or background networking)."""
    return [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            "--disable-extensions", "--hide-scrollbars", f"--user-data-dir={user_data}", f"--window-size={WINDOW[0]},{WINDOW[1]}"]


def probe(index: Path, tmp_path: Path) -> tuple[dict, list[str]]:
    """Load ``index`` with the probe in headless Chromium; the probe's findings and the console lines."""
    page = index.with_name("_browser_check.html")
    text = index.read_text(encoding="utf-8")
    page.write_text(text.replace("<head>", "<head>" + PROBE, 1), encoding="utf-8")
    try:
        proc = subprocess.run(chromium_args(tmp_path / "chromium-profile")
                              + ["--enable-logging=stderr", "--v=0", "--virtual-time-budget=15000", "--dump-dom",
                                 page.as_uri()], capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{index}: the page did not finish loading in 60 s (a script dialog, e.g. unescaped markup?)")
    finally:
        page.unlink()
    m = re.search(r'<pre id="__report_check"[^>]*>(.*?)</pre>', proc.stdout, re.S)
    assert m, f"the probe did not report (exit {proc.returncode}); stderr tail: {proc.stderr[-800:]}"
    console = [line for line in proc.stderr.splitlines() if ":CONSOLE" in line]
    return json.loads(html.unescape(m.group(1))), console


def assert_fits_window(found: dict) -> None:
    """The page does not scroll sideways in the probe's window."""
    assert found["window_width"] == WINDOW[0]
    assert found["scroll_width"] <= WINDOW[0], f"the page scrolls sideways; too wide: {found['wide']}"


def test_run_report_loads_cleanly_in_chromium(tmp_path, make_run, evil):
    run = make_run(tmp_path / "run", iterations=2, scenes=2, text=evil)
    heldout = run / "iter_0002" / "heldout" / "unseen"  # a failure grid twice as wide as the window
    heldout.mkdir(parents=True)
    (heldout / "houses.csv").write_text("house,episodes,success,spl,collisions,steps\nh0,4,0.5,0.3,2,120\n")
    Image.new("RGB", (2 * WINDOW[0], 300), "white").save(heldout / "failures.png")
    index = build_report(run)
    found, console = probe(index, tmp_path)
    assert found["images"] == 1 + 2 * 2 * 2 + 1  # curves + before/after of 2 scenes in 2 iterations + failures
    assert found["broken"] == []
    assert found["errors"] == []
    assert found["scripts"] == 1, "only the probe may be a script: text from files must stay escaped"
    assert console == []
    assert_fits_window(found)


def test_experiment_and_nested_run_reports_load_cleanly(tmp_path, make_experiment):
    exp = make_experiment(tmp_path / "exp", methods=("ours", "dr"), seeds=(0, 1), iterations=2)
    index = build_report(exp)
    found, console = probe(index, tmp_path)
    assert found["images"] == 2  # one curve figure per held-out set
    assert found["broken"] == [] and found["errors"] == [] and console == []
    assert_fits_window(found)
    nested, console = probe(index.parent / "runs" / "ours" / "seed_1" / "index.html", tmp_path)
    assert nested["images"] == 1 + 2 * 1 * 2
    assert nested["broken"] == [] and nested["errors"] == [] and console == []


def test_probe_detects_a_broken_image(tmp_path, make_run):
    """The check can fail: a render corrupted after the report was written shows up as broken."""
    run = make_run(tmp_path / "run", iterations=1, scenes=1)
    index = build_report(run)
    victim = next((index.parent / "img").rglob("after.png"))
    victim.write_bytes(b"not a png")
    found, _ = probe(index, tmp_path)
    assert len(found["broken"]) == 1 and found["broken"][0].endswith("after.png")


def screenshot(image_src: str, folder: Path, size: tuple[int, int], tmp_path: Path) -> Image.Image:
    """Chromium's screenshot of a page in ``folder`` showing one image at 1:1 (``image_src`` relative to it)."""
    page = folder / "_screenshot.html"
    page.write_text(f'<!doctype html><html><body style="margin:0;background:#fff">'
                     f'<img src="{html.escape(image_src)}" style="display:block"></body></html>', encoding="utf-8")
    shot = tmp_path / "shot.png"
    try:
        subprocess.run(chromium_args(tmp_path / "chromium-profile")[:-1]
                       + [f"--window-size={size[0]},{size[1]}", "--force-device-scale-factor=1",
                          f"--screenshot={shot}", page.as_uri()], capture_output=True, text=True, timeout=60)
    finally:
        page.unlink()
    assert shot.is_file(), "Chromium wrote no screenshot"
    return Image.open(shot).convert("RGB").crop((0, 0, *size))


def test_gallery_after_render_in_chromium_draws_no_path_through_moved_objects(tmp_path, adapted):
    """Screenshot each "after" image of the gallery as Chromium shows it; no path pixel may fall in a moved object.

    The same screenshot of the old, wrong picture (the before path over the edited scene) must fail the check.
    """
    from adaptenv.render.compare import MOVED_COLOUR, render_before_after
    from adaptenv.render.topdown import render_map
    from adaptenv.report.html import GALLERY_SIZE
    from tests.report.gallery_check import path_pixels_in
    from tests.report.run_folders import write_adapted_run

    index = build_report(write_adapted_run(tmp_path / "run", adapted))
    text = index.read_text(encoding="utf-8")
    afters = [src for src, alt in re.findall(r'<img src="([^"]+)" alt="([^"]+)"', text) if alt.endswith(", after")]
    assert len(afters) == 1
    pair = render_before_after(adapted.original, adapted.edited, adapted.before, adapted.after, size=GALLERY_SIZE)
    shown = screenshot(afters[0], index.parent, pair.after.size, tmp_path)
    assert path_pixels_in(shown, pair.after_layout, adapted.edited, [adapted.moved], adapted.after) == 0

    wrong = render_map(adapted.edited, trajectory=adapted.before, grid=True, size=GALLERY_SIZE,
                       highlight={adapted.moved: MOVED_COLOUR})
    wrong.image.save(index.parent / "img" / "wrong.png")
    shown = screenshot("img/wrong.png", index.parent, wrong.image.size, tmp_path)
    assert path_pixels_in(shown, wrong.layout, adapted.edited, [adapted.moved], adapted.before) > 50
