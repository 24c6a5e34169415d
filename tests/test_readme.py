"""The README's promises: its Python block (and the library block of vision_calib/docs/extending.md) runs as written (on a copy of the shipped example) and prints what its
comments say; .ci/run calls exactly the README's test command; every relative link of the README leads to a file."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from vision_calib.rig import SCENES_DIR, load_scene

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
DOCS = ROOT / "vision_calib" / "docs"


def _blocks(lang: str, text: str = README) -> list:
    return re.findall(rf"^```{lang}\n(.*?)^```", text, flags=re.S | re.M)


def test_python_block_runs(tmp_path):
    (code,) = _blocks("python")
    shutil.copytree(ROOT / "examples" / "rx90_eye_in_hand", tmp_path / "examples" / "rx90_eye_in_hand")
    p = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert p.returncode == 0, p.stderr[-3000:]
    lines = p.stdout.strip().splitlines()
    assert lines[0] == "ok consistent"  # the block's comment says so
    rows = [ln.split() for ln in lines[1:-1]]
    assert rows and all(r[2] == "+-" and r[-1] in ("m", "rad") for r in rows)
    xyz = np.array([float(v) for v in lines[-1].strip("[] mm").split()])
    # the calibrated flange position: the nominal chain's at the same joints, corrected by a calibration-sized move
    nominal = load_scene(SCENES_DIR / "rx90_eye_in_hand.yaml").setup.chain.flange(
        np.radians([[0.0, 35.0, 95.0, 0.0, 50.0, 0.0]]))[0][:3, 3] * 1000
    assert xyz.shape == (3,) and 0.01 < np.linalg.norm(xyz - nominal) < 10.0, (xyz, nominal)
    assert (tmp_path / "out" / "api" / "calibrated_model.yaml").exists()


def test_library_block_of_docs_runs():
    (code,) = _blocks("python", (ROOT / "vision_calib" / "docs" / "extending.md").read_text())
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                       env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert p.returncode == 0, p.stderr[-3000:]
    first, second = p.stdout.strip().splitlines()
    assert "rank 30" in first and "condition number" in first
    err, std = float(second.split()[2]), float(second.split()[5])
    assert abs(err) < 4 * std  # the 1 mm error on a2 recovered within the reported std


def test_ci_runs_the_readme_test_command():
    bash = _blocks("bash")
    test_cmd = next(b.strip() for b in bash if "pytest" in b)
    ci = [ln.strip() for ln in (ROOT / ".ci" / "run").read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    assert test_cmd in ci


def test_relative_links_exist():
    for folder, text in [(ROOT, README)] + [(DOCS, p.read_text()) for p in DOCS.glob("*.md")]:
        for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", text):
            assert (folder / target).exists(), f"{folder}: link to missing {target}"
