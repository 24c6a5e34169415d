"""Test helper: a page loaded in a real headless browser (Debian's ``chromium``, installed by .ci/setup), and the
static check that a page needs no network.

:func:`browser_probe` loads a copy of the page with a probe script added (the shipped page has none): on load it
writes into ``document.title`` how many <img> there are and how many decoded (naturalWidth > 0), where the verdict
box is, how many parameter-table rows are rendered (not folded away), the element the URL's fragment targets (its
display, position, and its first image's natural and rendered width) and any error events; the title is read back
from ``--dump-dom``.
:func:`screenshot` loads the page as shipped with console logging on and keeps the screenshot (under the test's
tmp dir and, when set, ``$VC_ARTEFACTS``). Without chromium the tests skip, except in CI (``CI=true``) where they
fail: there the browser test must run."""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ["--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars", "--no-first-run",
         "--disable-extensions", "--disable-background-networking", "--virtual-time-budget=15000"]

PROBE = """<script>
window.__errors = [];
window.addEventListener('error', function (e) {
  var t = e.target && e.target.tagName ? e.target.tagName + ' ' + String(e.target.src || '').slice(0, 40) : '';
  window.__errors.push(String(e.message || 'error event') + ' ' + t);
}, true);
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var v = document.getElementById('verdict');
  var r = v ? v.getBoundingClientRect() : null;
  var probe = {n_images: imgs.length,
               decoded: imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length,
               verdict_text: v ? v.innerText : null, verdict_top: r ? r.top : null, verdict_height: r ? r.height : null,
               param_rows_visible: Array.prototype.filter.call(document.querySelectorAll('#parameters tbody tr'),
                 function (t) { return t.getClientRects().length > 0 && t.innerText.trim().length > 0; }).length,
               target: null, errors: window.__errors};
  var t = document.querySelector(':target');
  if (t) {
    var st = getComputedStyle(t), im = t.querySelector('img');
    probe.target = {id: t.id, display: st.display, position: st.position,
                    img_natural_width: im ? im.naturalWidth : null,
                    img_width: im ? im.getBoundingClientRect().width : null};
  }
  document.title = 'PROBE' + JSON.stringify(probe);
});
</script>"""


def need_chromium() -> str:
    """The chromium executable; skip (outside CI) or fail (CI=true) without it."""
    if CHROMIUM:
        return CHROMIUM
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail("chromium is not installed but CI=true: the report.html browser test must run (.ci/setup "
                    "installs Debian's chromium)")
    pytest.skip("chromium not installed (apt-get install chromium; .ci/setup does it); outside CI the headless "
                "browser test is skipped")


def _run(args, timeout=120) -> subprocess.CompletedProcess:
    return subprocess.run([need_chromium(), *FLAGS, *args], capture_output=True, text=True, timeout=timeout)


def browser_probe(page: Path, fragment: str = "", where: Path | None = None) -> dict:
    """Load a copy of ``page`` beside it (same relative links; or in the folder ``where``, e.g. an empty one: the
    page as mailed) with :data:`PROBE` added as the first thing in <head>, at ``#fragment`` when given; returns the
    probe's dict plus ``stderr`` (chromium's log) and ``dom`` (the dumped DOM)."""
    text = Path(page).read_text()
    assert "<head>" in text, f"{page}: no <head>"
    probed = (Path(where) if where is not None else Path(page).parent) / ("probe_" + Path(page).name)
    probed.write_text(text.replace("<head>", "<head>" + PROBE, 1))
    try:
        res = _run(["--dump-dom", "--enable-logging=stderr", "--v=0",
                    probed.resolve().as_uri() + (f"#{fragment}" if fragment else "")])
    finally:
        probed.unlink()
    m = re.search(r"<title>PROBE(.*?)</title>", res.stdout, re.S)
    assert m, f"the probe did not run (no load event?); chromium rc {res.returncode}, stderr: {res.stderr[-2000:]}"
    out = json.loads(html.unescape(m.group(1)))
    out["stderr"] = res.stderr
    out["dom"] = res.stdout
    return out


def console_errors(stderr: str) -> list[str]:
    """Chromium log lines of the page's console (any message: the pages carry no script, and the probe logs
    nothing, so each one is an error, uncaught exceptions included) and of failed resource loads; not the
    browser's own noise (D-Bus, GPU, sandbox)."""
    return [ln for ln in stderr.splitlines()
            if ":CONSOLE" in ln or "Failed to load resource" in ln or "net::ERR_" in ln]


def screenshot(page: Path, dest: Path, size=(1280, 2400)) -> tuple[Path, str]:
    """Screenshot of ``page`` as shipped into ``dest`` (PNG), also copied to ``$VC_ARTEFACTS`` when set; returns
    (path, chromium's stderr with console logging on)."""
    dest = Path(dest)
    res = _run([f"--screenshot={dest}", f"--window-size={size[0]},{size[1]}", "--enable-logging=stderr", "--v=0",
                Path(page).resolve().as_uri()])
    assert dest.is_file() and dest.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", \
        f"no screenshot of {page}: rc {res.returncode}, {res.stderr[-2000:]}"
    art = os.environ.get("VC_ARTEFACTS")
    if art:
        Path(art).mkdir(parents=True, exist_ok=True)
        shutil.copyfile(dest, Path(art) / dest.name)
    return dest, res.stderr


class _Refs(HTMLParser):
    def __init__(self):
        super().__init__()
        self.refs, self.tags = [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        for k, v in attrs:
            if k in ("src", "href", "srcset", "poster", "data") and v is not None:
                self.refs.append((tag, k, v))


def network_references(text: str) -> list[str]:
    """What in a page would need the network or another file to render: <script>, <link>, <iframe>, <object>
    tags; src attributes that are not data: URIs; href / url() with a scheme (http:, https:, //)."""
    p = _Refs()
    p.feed(text)
    bad = [f"<{t}>" for t in p.tags if t in ("script", "link", "iframe", "object", "embed")]
    for tag, k, v in p.refs:
        if k == "src" and not v.startswith("data:"):
            bad.append(f"<{tag} {k}={v[:60]}>")
        if k != "src" and re.match(r"^\s*([a-z][a-z0-9+.-]*:|//)", v, re.I) and not v.startswith("data:"):
            bad.append(f"<{tag} {k}={v[:60]}>")
    bad += re.findall(r"url\(\s*['\"]?(?:https?:|//)[^)]*\)", text)
    bad += re.findall(r"@import[^;]*;", text)
    return bad
