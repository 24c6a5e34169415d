"""report.html of real runs of every command that writes a report: self-contained (no network), the verdict first,
the parameter table, the per-pose residuals worst first, the overlays of the rejected and worst poses; loaded in
a real headless browser (chromium): no errors, the verdict box at the top, every image decodes; a screenshot is
kept (tmp dir and $VC_ARTEFACTS)."""

import base64
import json
import re
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from vision_calib.cli import main
from vision_calib.io.overlay import MAX_WIDTH_PX
from vision_calib.rig import SCENES_DIR

from headless import browser_probe, console_errors, need_chromium, network_references, screenshot  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiment"))
from flange_folder import flange_pose_folder, measured_pose_file  # noqa: E402

RX90 = str(SCENES_DIR / "rx90_eye_in_hand.yaml")
#: verdict box background of each status (io/report_html.py CSS), RGB
STATUS_RGB = {"ok": (0xE8, 0xF6, 0xEA), "warning": (0xFF, 0xF5, 0xDE), "failed": (0xFD, 0xE8, 0xE8)}


def damage(src: Path, dst: Path) -> None:
    """Copy the recording src to dst with pose 003's frames blank (the target not found: a measurement
    rejection) and the frames of poses 005 and 009 swapped (images of another pose: outliers of the fit)."""
    import shutil

    shutil.copytree(src, dst)
    for k in ("00", "01"):
        a, b, c = (dst / "images" / p / f"{k}.png" for p in ("003", "005", "009"))
        im = cv2.imread(str(a), cv2.IMREAD_GRAYSCALE)
        cv2.imwrite(str(a), np.full_like(im, 128))
        ib, ic = b.read_bytes(), c.read_bytes()
        b.write_bytes(ic)
        c.write_bytes(ib)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """{name: output folder} of one run of each command that writes a report (CLI, as a user runs it)."""
    d = tmp_path_factory.mktemp("html")
    assert main(["simulate", RX90, "--poses", "12", "--frames", "2", "--seed", "3", "--workers", "1", "--json",
                 "--out", str(d / "sim"), "--export-recording", str(d / "rec")]) == 0
    damage(d / "rec", d / "bad")
    assert main(["process", str(d / "bad"), "--out", str(d / "proc"), "--json"]) == 0
    flange, _, _ = flange_pose_folder(d / "rec", d / "flange", robot_std_mm=0.2, robot_std_deg=0.02)
    assert main(["process", str(flange), "--out", str(d / "handeye"), "--json"]) == 0
    mp = measured_pose_file(d / "mp.yaml", RX90)
    assert main(["process-poses", str(mp), "--out", str(d / "poses"), "--json"]) == 0
    return {name: d / name for name in ("sim", "proc", "handeye", "poses")}


def section(text: str, sid: str) -> str:
    m = re.search(rf'<section id="{sid}".*?</section>', text, re.S)
    assert m, f"no section {sid}"
    return m.group(0)


def cells(row_html: str) -> list[str]:
    return [re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<td[^>]*>(.*?)</td>", row_html, re.S)]


ALL = ["sim", "proc", "handeye", "poses"]


@pytest.mark.slow
@pytest.mark.parametrize("name", ALL)
def test_every_command_writes_a_self_contained_page(runs, name):
    out = runs[name]
    rep = json.loads((out / "report.json").read_text())
    text = (out / "report.html").read_text()
    assert rep["files"]["html"] == "report.html"
    assert not [w for w in rep["warnings"] if w.startswith(("overlay images failed", "report.html failed",
                                                             "plotting failed"))]
    assert network_references(text) == []
    for root in (out.parent, out.parent.resolve(), SCENES_DIR.resolve()):  # no absolute path: the folder can move
        assert str(root) not in text
    # the verdict first, with its status in words
    first = re.search(r"<section id=\"(\w+)\"", text).group(1)
    assert first == "verdict"
    status = rep["verdict"]["status"]
    assert {"ok": "OK", "warning": "WARNING", "failed": "FAILED"}[status] in section(text, "verdict")
    for w in rep["warnings"]:
        assert w[:60].replace("'", "&#x27;").replace(">", "&gt;").replace("<", "&lt;") in text
    # the sections in the promised order
    order = [m for m in re.findall(r'<section id="(\w+)"', text)]
    want = ["verdict", "parameters", "identifiability", "adequacy", "poses", "plots"]
    assert [s for s in order if s in want] == want
    # every identified parameter is a row, with its identified value in the display unit
    params = section(text, "parameters")
    for r in [r for r in rep.get("parameters") or [] if r["free"]]:
        row = re.search(rf"<tr[^>]*><td class=\"l\">{re.escape(r['name'])}</td>.*?</tr>", params, re.S)
        assert row, r["name"]
        c = cells(row.group(0))
        f = {"m": 1e3, "rad": np.degrees(1.0)}[r["unit"]]
        assert float(c[3]) == pytest.approx(r["identified"] * f, rel=1e-4, abs=1e-4)
        if r["true"] is not None:  # simulation: z against the truth
            assert float(c[7]) == pytest.approx((r["identified"] - r["true"]) / r["std"], abs=0.006)
    # per-pose residuals worst first: the page's rows follow report.json's order, chi2 decreasing
    poses = section(text, "poses")
    pr = rep["pose_residuals"]["poses"]
    rows = [cells(m) for m in re.findall(r"<tr[^>]*>.*?</tr>", poses.split("<h3>")[0], re.S)]
    assert [c[0] for c in rows if c] == [p["pose_id"] for p in pr]  # every kept pose, in that order
    chi2 = [p["chi2"] for p in pr]
    assert chi2 == sorted(chi2, reverse=True)


@pytest.mark.slow
def test_overlays_show_the_rejected_and_the_worst_poses(runs):
    """The damaged recording: pose 003 failed to measure (blank frames), 005 and 009 are outliers (swapped images);
    each gets an overlay with its reason, then the worst kept poses; every overlay a JPEG <= 640 px wide."""
    out = runs["proc"]
    rep = json.loads((out / "report.json").read_text())
    assert [r["pose_id"] for r in rep["measurements"]["rejected"]] == ["003"]
    assert sorted(o["pose_id"] for o in rep["outliers"]) == ["005", "009"]
    ov = section((out / "report.html").read_text(), "overlays")
    caps = re.findall(r"<figcaption>(.*?)</figcaption>", ov, re.S)
    assert caps[0].startswith("pose 003, rejected: no valid frame") and "0 corners detected" in caps[0]
    assert {c.split(",")[0] for c in caps[1:3]} == {"pose 005", "pose 009"}
    assert all("outlier" in c and "does not follow its joints" in c for c in caps[1:3])
    worst = [p["pose_id"] for p in rep["pose_residuals"]["poses"][:3]]
    assert [c.split(",")[0] for c in caps[3:]] == [f"pose {p}" for p in worst]
    # the outliers' model reprojection is far off the detected corners (images of another pose), the worst kept
    # poses' within a pixel
    rms = [float(m) for m in re.findall(r"RMS ([0-9.e+-]+) px", " ".join(caps))]
    assert len(rms) == 5 and min(rms[:2]) > 20 and max(rms[2:]) < 1
    imgs = re.findall(r'src="data:image/jpeg;base64,([^"]+)"', ov)
    assert len(imgs) == 6
    for b in imgs:
        im = cv2.imdecode(np.frombuffer(base64.b64decode(b), np.uint8), cv2.IMREAD_COLOR)
        assert im is not None and 0 < im.shape[1] <= MAX_WIDTH_PX


@pytest.mark.slow
@pytest.mark.parametrize("name", ALL)
def test_page_in_a_headless_browser(runs, name, tmp_path):
    need_chromium()
    out = runs[name]
    rep = json.loads((out / "report.json").read_text())
    text = (out / "report.html").read_text()
    probe = browser_probe(out / "report.html")
    assert probe["errors"] == [], probe["errors"]
    assert console_errors(probe["stderr"]) == []
    n_img = len(re.findall(r"<img ", text))
    n_plots = sum(1 for k in rep["files"] if k.endswith("_plot"))
    assert probe["n_images"] == n_img >= n_plots
    assert probe["decoded"] == n_img  # every image decodes
    assert probe["verdict_top"] < 150 and probe["verdict_height"] > 40  # the verdict box is the first thing seen
    assert rep["verdict"]["status"].upper() in probe["verdict_text"].upper()
    # the table of the identified parameters is rendered (the fixed ones folded away); hand-eye: its 2 transforms
    assert probe["param_rows_visible"] == (sum(r["free"] for r in rep["parameters"]) if "parameters" in rep else 2)
    shot, log = screenshot(out / "report.html", tmp_path / f"report_{name}.png")
    assert console_errors(log) == []
    im = cv2.imread(str(shot))[:, :, ::-1]
    top = im[:300].reshape(-1, 3)
    colour = np.array(STATUS_RGB[rep["verdict"]["status"]])
    assert np.mean(np.all(np.abs(top.astype(int) - colour) <= 2, axis=1)) > 0.05  # the verdict's colour on top


@pytest.mark.slow
def test_failed_and_warning_verdicts_read_first(runs, tmp_path):
    """The page of the same report with a failed (gross input error) and a warning verdict: the state, its reason
    and whether a model was written, in the verdict box."""
    from vision_calib.io.report_html import report_html

    rep = json.loads((runs["proc"] / "report.json").read_text())
    failed = {**rep, "verdict": {**rep["verdict"], "status": "failed", "ok": False, "usable": False,
                                 "failure": "wrong_robot", "message": "the joints do not fit this robot"},
              "failure": {"kind": "wrong_robot", "message": "the joints do not fit this robot"}}
    box = section(report_html(failed, runs["proc"]), "verdict")
    assert 'class="verdict failed"' in box and "Verdict: FAILED (wrong_robot)" in box
    assert box.count("the joints do not fit this robot") == 1 and "no calibrated model was written" in box
    warn = {**rep, "verdict": {**rep["verdict"], "status": "warning", "ok": False, "message": "model does not fit"}}
    box = section(report_html(warn, runs["proc"]), "verdict")
    assert 'class="verdict warning"' in box and "Verdict: WARNING" in box and "<li>model does not fit</li>" in box
