"""CLI commands not covered elsewhere: printable target export, errors without tracebacks."""

import subprocess
import sys

from vision_calib.cli import main
from vision_calib.targets import load_target, read_png_phys


def test_target_export_png_carries_the_physical_scale(tmp_path, capsys):
    out = tmp_path / "a5.png"
    assert main(["target", "targets/charuco_a5.yaml", "--out", str(out), "--dpi", "300"]) == 0
    w_px, h_px, ppm_x, ppm_y = read_png_phys(out)
    w_m, h_m = load_target("targets/charuco_a5.yaml").outline_m()
    assert abs(w_px / ppm_x - w_m) < 1 / ppm_x and abs(h_px / ppm_y - h_m) < 1 / ppm_y


def test_bad_target_file_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "t.yaml"
    bad.write_text("kind: charuco\nrows: 5\ncols: 7\ndictionary: DICT_NOPE\nsquare_m: 0.02\nmarker_m: 0.015\n")
    r = subprocess.run([sys.executable, "-m", "vision_calib.cli", "target", str(bad), "--out", str(tmp_path / "x.png")],
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and "DICT_NOPE" in r.stderr
