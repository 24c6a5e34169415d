"""``import-visp`` reads the folder's own pattern file (``chessboard-data.txt`` or ``apriltag-data.txt``) and
ViSP's real file names (``franka_camera.xml``, ``franka_image-N.png``, ``franka_pose_rPe_N.yaml``); without a
pattern the error names the files looked for; the help documents the layout."""

import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from vision_calib import frames as F
from vision_calib.cli import build_parser, main
from vision_calib.errors import DataError
from vision_calib.io.visp import read_pattern_file

REAL = Path(os.environ["VISION_CALIB_SHARED_DATA"]) / "real" / "visp_eye_to_hand_apriltag"  # tests/conftest.py
CHESSBOARD_DATA = "Chessboard\n9 x 6\nsquare size: 0.0236 m\n"  # as ViSP's eye-in-hand data folder has it


def _board(inner=(9, 6), sq=20, size=(320, 240)):
    img = np.full((size[1], size[0]), 255, np.uint8)
    for r in range(inner[1] + 1):
        for c in range(inner[0] + 1):
            if (r + c) % 2 == 0:
                img[40 + r * sq:40 + (r + 1) * sq, 40 + c * sq:40 + (c + 1) * sq] = 0
    return cv2.GaussianBlur(img, (3, 3), 0.8)


def _franka_folder(d: Path, pattern: str | None = CHESSBOARD_DATA, n=3) -> Path:
    """A ViSP folder with the names visp-acquire-franka-calib-data writes."""
    d.mkdir()
    (d / "franka_camera.xml").write_text(
        "<root><camera><name>Camera</name><image_width>320</image_width><image_height>240</image_height>"
        "<model><type>perspectiveProjWithDistortion</type><px>300</px><py>300</py><u0>160</u0><v0>120</v0>"
        "<kud>-0</kud><kdu>0</kdu></model></camera></root>")
    for i in range(1, n + 1):
        (d / f"franka_pose_rPe_{i}.yaml").write_text("rows: 6\ncols: 1\ndata: \n" + "".join(
            f"  - [{v}]\n" for v in (0.3, 0.1 * i, 0.5, 0.0, 0.1 * i, 0.0)))
        cv2.imwrite(str(d / f"franka_image-{i}.png"), _board())
    if pattern is not None:
        (d / "chessboard-data.txt").write_text(pattern)
    return d


def test_chessboard_data_file_read_without_options(tmp_path, capsys):
    src = _franka_folder(tmp_path / "visp")
    assert main(["import-visp", str(src), "--out", str(tmp_path / "rec")]) == 0
    doc = yaml.safe_load((tmp_path / "rec" / "recording.yaml").read_text())
    assert doc["target"] == {"kind": "chessboard", "rows": 7, "cols": 10, "square_m": 0.0236, "margin_m": 0.0236}
    assert doc["camera_mount"] == "eye_in_hand" and doc["poses"] == "flange_pose"
    rows = (tmp_path / "rec" / "poses.csv").read_text().splitlines()
    assert len(rows) == 4 and sorted(p.name for p in (tmp_path / "rec" / "images").iterdir()) == ["1", "2", "3"]
    xyz, q = F.xyz_quat_from_T(F.T_from_xyz_rotvec([0.3, 0.2, 0.5, 0.0, 0.2, 0.0]))
    np.testing.assert_allclose([float(v) for v in rows[2].split(",")[1:]], [*xyz, *q], atol=1e-15)
    # the options override the file: another square side, the camera on a tripod
    assert main(["import-visp", str(src), "--out", str(tmp_path / "rec2"), "--square-m", "0.03", "--mount",
                 "fixed"]) == 0
    doc = yaml.safe_load((tmp_path / "rec2" / "recording.yaml").read_text())
    assert doc["target"]["square_m"] == 0.03 and doc["camera_mount"] == "fixed"


def test_no_pattern_file_names_the_files_looked_for(tmp_path, capsys):
    src = _franka_folder(tmp_path / "visp", pattern=None)
    assert main(["import-visp", str(src), "--out", str(tmp_path / "rec")]) == 2
    err = capsys.readouterr().err
    assert "no pattern description: looked for chessboard-data.txt and apriltag-data.txt" in err
    assert "--chessboard COLSxROWS --square-m S" in err and "--tag-size-m S" in err
    assert not (tmp_path / "rec" / "recording.yaml").exists()


@pytest.mark.parametrize("text,match", [
    ("Chessboard\nsquare size: 0.02 m\n", r"chessboard-data.txt: expected a line 'W x H' .*found no W x H line"),
    ("Chessboard\n9 x 6\n", r"chessboard-data.txt: expected .*found no square size"),
])
def test_unreadable_chessboard_data_named(tmp_path, text, match):
    src = _franka_folder(tmp_path / "visp", pattern=text)
    with pytest.raises(DataError, match=match):
        read_pattern_file(src)


def test_two_pattern_files_refused(tmp_path, capsys):
    src = _franka_folder(tmp_path / "visp")
    (src / "apriltag-data.txt").write_text("36h11 Apriltag\nsize: 0.048 m\n")
    assert main(["import-visp", str(src), "--out", str(tmp_path / "rec")]) == 2
    assert "both chessboard-data.txt and apriltag-data.txt" in capsys.readouterr().err


@pytest.mark.skipif(not REAL.is_dir(), reason="real ViSP data not available")
def test_real_visp_folder_pattern_and_names(tmp_path, capsys):
    """The real eye-to-hand folder (read in place): its apriltag-data.txt gives the 48 mm 36h11 tag; its
    franka_* files are the 8 poses."""
    info = read_pattern_file(REAL)
    assert info["kind"] == "apriltag" and info["tag_m"] == 0.048 and info["dictionary"] == "DICT_APRILTAG_36h11"
    assert main(["import-visp", str(REAL), "--out", str(tmp_path / "rec")]) == 0
    doc = yaml.safe_load((tmp_path / "rec" / "recording.yaml").read_text())
    assert doc["camera_mount"] == "fixed" and doc["target"]["tag_m"] == 0.048
    assert len((tmp_path / "rec" / "poses.csv").read_text().splitlines()) == 1 + 8


def test_help_documents_the_visp_file_names():
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices["import-visp"]
    text = sub.format_help()
    for name in ("franka_camera.xml", "franka_image-N.png", "franka_pose_rPe_N.yaml", "chessboard-data.txt",
                 "apriltag-data.txt"):
        assert name in text, name
