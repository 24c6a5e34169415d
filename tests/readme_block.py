"""The README's Python block (tests/test_readme.py runs it from a temporary folder, tests/test_install.py from an
installed wheel): the block, and the check of what it prints and writes."""

import hashlib
import re
from pathlib import Path

import numpy as np

from vision_calib.rig import SCENES_DIR, load_scene

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_python_block() -> str:
    """The README's one Python block."""
    (code,) = re.findall(r"^```python\n(.*?)^```", README.read_text(), flags=re.S | re.M)
    return code


def tree_digest(folder: Path) -> dict:
    """{relative path: sha256} of every file under ``folder``."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def check_python_block_output(stdout: str, out_dir: Path) -> None:
    """What the README's Python block prints (its comments: the verdict, free parameters in SI units, the calibrated
    flange position in mm) and writes (``out/api/calibrated_model.yaml``)."""
    lines = stdout.strip().splitlines()
    assert lines[0] == "ok consistent"  # the block's comment says so
    rows = [ln.split() for ln in lines[1:-1]]
    assert rows and all(r[2] == "+-" and r[-1] in ("m", "rad") for r in rows)
    xyz = np.array([float(v) for v in lines[-1].strip("[] mm").split()])
    # the calibrated flange position: the nominal chain's at the same joints, corrected by a calibration-sized move
    nominal = load_scene(SCENES_DIR / "rx90_eye_in_hand.yaml").setup.chain.flange(
        np.radians([[0.0, 35.0, 95.0, 0.0, 50.0, 0.0]]))[0][:3, 3] * 1000
    assert xyz.shape == (3,) and 0.01 < np.linalg.norm(xyz - nominal) < 10.0, (xyz, nominal)
    assert (out_dir / "api" / "calibrated_model.yaml").exists()
