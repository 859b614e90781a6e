"""The report in a real headless Chromium: every image loads, no script or console errors.

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

from adaptenv.report import build_report

CHROMIUM = Path("/usr/bin/chromium")
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
    var out = {images: imgs.length, broken: broken, errors: window.__errors, scripts: document.scripts.length};
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
            "--disable-extensions", "--hide-scrollbars", f"--user-data-dir={user_data}", "--window-size=1280,900"]


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


def test_run_report_loads_cleanly_in_chromium(tmp_path, make_run, evil):
    run = make_run(tmp_path / "run", iterations=2, scenes=2, text=evil)
    index = build_report(run)
    found, console = probe(index, tmp_path)
    assert found["images"] == 1 + 2 * 2 * 2  # curves + before/after of 2 scenes in 2 iterations
    assert found["broken"] == []
    assert found["errors"] == []
    assert found["scripts"] == 1, "only the probe may be a script: text from files must stay escaped"
    assert console == []


def test_experiment_and_nested_run_reports_load_cleanly(tmp_path, make_experiment):
    exp = make_experiment(tmp_path / "exp", methods=("ours", "dr"), seeds=(0, 1), iterations=2)
    index = build_report(exp)
    found, console = probe(index, tmp_path)
    assert found["images"] == 2  # one curve figure per held-out set
    assert found["broken"] == [] and found["errors"] == [] and console == []
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
