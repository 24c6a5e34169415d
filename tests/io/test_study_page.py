"""The study page (study/page.py): index.html in the study's output folder with the per-cell summary table, the
parameter spread and every plot inlined; self-contained, and loaded in a headless browser every image decodes."""

import re

import yaml

from vision_calib.rig import SCENES_DIR
from vision_calib.study import run_study

from headless import browser_probe, console_errors, need_chromium, network_references, screenshot  # noqa: E402


def test_study_page_has_the_table_and_the_plots(tmp_path):
    spec = tmp_path / "tiny.yaml"
    spec.write_text(yaml.safe_dump({"name": "tiny", "scene": str(SCENES_DIR / "h4_vision.yaml"), "repetitions": 3,
                                    "seed": 5, "sweep": {"sigma_mm": [0.1, 0.3]}, "settings": {"n_poses": 20}}))
    res = run_study(spec, tmp_path / "out", workers=1)
    page = tmp_path / "out" / "index.html"
    assert res["files"]["index_html"] == str(page)
    text = page.read_text()
    assert network_references(text) == []
    assert str(tmp_path) not in text  # no absolute path: the folder can move
    table = re.search(r'<section id="summary">.*?</section>', text, re.S).group(0)
    rows = [re.findall(r"<td[^>]*>(.*?)</td>", r) for r in re.findall(r"<tr>(.*?)</tr>", table, re.S)]
    body = [r for r in rows if r]
    assert [r[0] for r in body] == ["0.1", "0.3"]  # one row per cell, its axis value first
    for r, s in zip(body, res["summary"]):
        assert int(r[1]) == s["n_runs"] - s["n_failed"]
        pos = s["figures"]["after_position_rms_mm"]
        assert float(r[3].split(" ± ")[0]) == float(f"{pos['mean']:.3g}")
    plots = res["files"]["plots"]
    assert len(plots) >= 6
    inlined = re.findall(r'<figure><img src="data:image/png;base64,[^"]+" alt="([^"]+)"', text)
    assert sorted(inlined) == sorted(p.rsplit("/", 1)[-1] for p in plots)
    need_chromium()
    probe = browser_probe(page)
    assert probe["errors"] == [] and console_errors(probe["stderr"]) == []
    assert probe["n_images"] == probe["decoded"] == len(plots)
    screenshot(page, tmp_path / "study_index.png")


def test_probe_catches_a_broken_image_and_a_script_error(tmp_path):
    """The browser check can fail: a page with one good and one corrupt image and a failing script."""
    need_chromium()
    import base64
    import zlib
    import struct

    def png(w, h):
        def chunk(t, d):
            return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
        raw = b"".join(b"\x00" + b"\x80" * w for _ in range(h))
        return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))

    good = base64.b64encode(png(4, 3)).decode()
    bad = base64.b64encode(png(4, 3)[:30]).decode()
    page = tmp_path / "bad.html"
    page.write_text(f'<!DOCTYPE html><html><head><title>t</title></head><body><section id="verdict">x</section>'
                    f'<img src="data:image/png;base64,{good}"><img src="data:image/png;base64,{bad}">'
                    "<script>undefinedFunction();</script></body></html>")
    probe = browser_probe(page)
    assert probe["n_images"] == 2 and probe["decoded"] == 1
    assert any("undefinedFunction" in e for e in probe["errors"])
    assert any("Uncaught ReferenceError" in ln for ln in console_errors(probe["stderr"]))
    assert network_references(page.read_text()) == ["<script>"]
