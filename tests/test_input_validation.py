"""Strict input schemas (config.check_keys), the output lock (io/lock.py), --scheduler validation,
ViSP import safety (symlinks, permissions), target memory estimate."""

import os
import subprocess
import sys

import cv2
import numpy as np
import pytest

from vision_calib.camera import CameraIntrinsics
from vision_calib.cli import main
from vision_calib.config import ANY, Section, check_keys
from vision_calib.errors import ConfigError, DataError
from vision_calib.io.lock import LOCK_NAME, LockedError, OutputLock
from vision_calib.io.visp import import_visp_eye_to_hand


def sec(data):
    return Section(data, "scene.yaml")


def test_check_keys_names_file_key_and_suggests_the_closest():
    tree = {"camera": {"width", "height"}, "truth": {"sigma_length_mm"}, "poses": [{"q"}], "confs": {"*": {"q"}},
            "notes": ANY}
    check_keys(sec({"camera": {"width": 1}, "poses": [{"q": 1}], "confs": {"a": {"q": 1}}, "notes": {"x": 1}}), tree)
    with pytest.raises(ConfigError, match=r"scene.yaml: truth.sigma_lenght_mm: unknown key \(did you mean 'sigma_length_mm'\?\)"):
        check_keys(sec({"truth": {"sigma_lenght_mm": 1}}), tree)
    with pytest.raises(ConfigError, match=r"scene.yaml: poses\[1\].qq: unknown key \(did you mean 'q'\?\)"):
        check_keys(sec({"poses": [{"q": 1}, {"qq": 2}]}), tree)
    with pytest.raises(ConfigError, match=r"confs.b.z: unknown key"):
        check_keys(sec({"confs": {"b": {"z": 1}}}), tree)
    with pytest.raises(ConfigError, match=r"scene.yaml: measurment: unknown key; allowed here"):
        check_keys(sec({"measurment": {}}), {"camera"})  # too far from any known key: no suggestion


def test_number_checks_range_and_names_the_key():
    s = sec({"sigma_length_mm": -1, "n": 3, "big": float("inf")})
    with pytest.raises(ConfigError, match=r"scene.yaml: sigma_length_mm: expected a value >= 0 mm, got -1"):
        s.number("sigma_length_mm", min=0, unit="mm")
    assert s.number("n", int, min=1, max=3) == 3
    with pytest.raises(ConfigError, match="expected a value <= 2"):
        s.number("n", int, max=2)
    with pytest.raises(ConfigError, match="big: expected a finite number"):
        s.number("big")
    assert s.number("missing", float, 0.5, min=0) == 0.5


def test_camera_from_dict_is_strict():
    d = dict(width=640, height=480, fx=500.0, fy=500.0, cx=320.0, cy=240.0)
    assert CameraIntrinsics.from_dict(d).dist == (0.0,) * 5
    with pytest.raises(ConfigError, match=r"rec.yaml: camera: missing key\(s\) dist.*dist: \[0, 0, 0, 0, 0\]"):
        CameraIntrinsics.from_dict(d, where="rec.yaml: camera", require_dist=True)
    with pytest.raises(ConfigError, match=r"camera.k9: unknown key"):
        CameraIntrinsics.from_dict({**d, "k9": 1})
    with pytest.raises(ConfigError, match=r"camera.fy: expected a focal length > 0"):
        CameraIntrinsics.from_dict({**d, "fy": 0})


HOLDER = "import sys,time; from vision_calib.io.lock import OutputLock; l=OutputLock(sys.argv[1]).acquire(); print('held', flush=True); time.sleep(60)"


def test_lock_refuses_a_second_run_naming_the_pid_and_takes_over_a_stale_one(tmp_path):
    out = tmp_path / "out"
    child = subprocess.Popen([sys.executable, "-c", HOLDER, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "held"
        with pytest.raises(LockedError, match=f"pid {child.pid}"):
            OutputLock(out).acquire()
        assert main(["process", str(tmp_path / "nowhere"), "--out", str(out)]) == 2  # the lock is checked first
    finally:
        child.kill()
        child.wait()
    assert (out / LOCK_NAME).read_text().strip() == str(child.pid)  # stale: the holder died
    with OutputLock(out) as lock:
        assert lock.path.read_text().strip() == str(os.getpid())
    assert not (out / LOCK_NAME).exists()


def test_cli_error_names_the_other_runs_pid(tmp_path, capsys):
    out = tmp_path / "out"
    child = subprocess.Popen([sys.executable, "-c", HOLDER, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        child.stdout.readline()
        assert main(["target", "targets/charuco_a5.yaml", "--out", str(out / "t.png")]) == 0  # a file: own lock
        assert main(["process", str(tmp_path / "rec"), "--out", str(out)]) == 2
        assert f"in use by another vision-calib run (pid {child.pid}" in capsys.readouterr().err
    finally:
        child.kill()
        child.wait()


@pytest.mark.parametrize("address,message", [("not an address", "expected tcp://host:port"),
                                             ("http://localhost:8787", "dashboard"),
                                             ("tcp://host:70000", "port out of range")])
def test_scheduler_address_is_validated(address, message, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["study", "x.yaml", "--out", "o", "--scheduler", address])
    assert exc.value.code == 2 and message in capsys.readouterr().err


def test_target_refuses_a_huge_allocation(tmp_path, capsys):
    assert main(["target", "targets/charuco_a5.yaml", "--out", str(tmp_path / "t.png"), "--dpi", "20000"]) == 2
    err = capsys.readouterr().err
    assert "GiB of memory" in err and "dpi" in err
    assert not (tmp_path / "t.png").exists()


def _visp_folder(d):
    d.mkdir()
    (d / "cam_camera.xml").write_text(
        "<root><camera><name>c</name><image_width>64</image_width><image_height>48</image_height>"
        "<model><type>perspectiveProjWithoutDistortion</type><px>60</px><py>60</py><u0>32</u0><v0>24</v0></model>"
        "</camera></root>")
    (d / "r_pose_rPe_1.yaml").write_text("rows: 6\ncols: 1\ndata:\n" + "".join(f"  - [{v}]\n" for v in (0, 0, 0.5, 0, 0, 0)))
    cv2.imwrite(str(d / "r_image-1.png"), np.zeros((48, 64), np.uint8))
    return d


def test_visp_import_keeps_permissions_and_refuses_symlinks_out(tmp_path):
    src = _visp_folder(tmp_path / "visp")
    os.chmod(src / "r_image-1.png", 0o600)
    dst = import_visp_eye_to_hand(src, tmp_path / "rec", tag_m=0.03, tag_id=0)
    assert (dst / "images" / "1" / "00.png").stat().st_mode & 0o777 == 0o600
    secret = tmp_path / "secret.png"
    os.replace(src / "r_image-1.png", secret)
    (src / "r_image-1.png").symlink_to(secret)
    with pytest.raises(DataError, match="r_image-1.png: a symbolic link leading out"):
        import_visp_eye_to_hand(src, tmp_path / "rec2", tag_m=0.03, tag_id=0)
    assert import_visp_eye_to_hand(src, tmp_path / "rec3", tag_m=0.03, tag_id=0, allow_symlinks=True).is_dir()


def test_visp_pose_yaml_unknown_key(tmp_path):
    from vision_calib.io.visp import read_visp_pose_yaml

    p = tmp_path / "p.yaml"
    p.write_text("rows: 6\ncols: 1\ndatta: [1, 2, 3, 4, 5, 6]\n")
    with pytest.raises(DataError, match=r"p.yaml: datta: unknown key \(did you mean 'data'\?\)"):
        read_visp_pose_yaml(p)
    p.write_bytes(b"rows: 6\ncols: 1\ndata: [1, 2, 3, 4, 5, 6] # caf\xe9\n")
    with pytest.raises(DataError, match="p.yaml: line 3: not UTF-8 text \\(byte 0xe9"):
        read_visp_pose_yaml(p)
