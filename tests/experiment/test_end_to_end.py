"""End-to-end: render + effects + measure + identify; export a recorded folder and process it;
real-world damage to the folder (missing, corrupt, blank, odd-size images, extra files)."""

import json
import shutil

import cv2
import numpy as np
import pytest

from vision_calib.cli import main
from vision_calib.experiment.process import process_folder
from vision_calib.experiment.simulate import run_simulation

pytestmark = pytest.mark.slow
H4 = "scenes/h4_vision.yaml"


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    d = tmp_path_factory.mktemp("e2e")
    rep = run_simulation(H4, out_dir=d / "sim", seed=4, n_poses=24, frames=2, export_recording=d / "rec", workers=2)
    return d, rep


def test_simulate_writes_report_plots_and_loadable_model(exported):
    d, rep = exported
    out = json.loads((d / "sim" / "report.json").read_text())
    assert out["version"] and out["seed"] == 4
    for key in ("identifiability", "parameters", "accuracy", "measurements", "timings_s"):
        assert key in out
    assert out["measurements"]["n_valid"] == 24
    b, a = out["accuracy"]["before"], out["accuracy"]["after"]
    assert a["V2_rad"] < 0.2 * b["V2_rad"]
    for f in ("residuals.png", "parameters.png", "error_map.png", "calibrated_model.yaml"):
        assert (d / "sim" / f).stat().st_size > 0
    from vision_calib.io.model_export import load_calibrated_model

    # every free parameter within its reported uncertainty of the truth (std scaled by the a-posteriori
    # variance factor: the image chain's systematic error is not in the per-pose covariances)
    z = np.array([(p["identified"] - p["true"]) / p["std"] for p in out["parameters"] if p["free"]])
    assert out["variance_factor"] >= 1 and np.max(np.abs(z)) < 5, z
    robot = load_calibrated_model(d / "sim" / "calibrated_model.yaml")
    ident = {p["name"]: p["identified"] for p in out["parameters"]}
    np.testing.assert_allclose(robot.params.values()["h4.L"], ident["h4.L"], rtol=0, atol=1e-12)
    X = robot.pose_grid()[:3]
    assert np.all(np.isfinite(robot.igm(X)))


def test_process_of_the_export_gives_the_same_parameters(exported, tmp_path):
    d, rep = exported
    out = process_folder(d / "rec", tmp_path / "proc")
    sim = {p["name"]: p for p in rep["parameters"]}
    for p in out["parameters"]:
        s = sim[p["name"]]
        assert abs(p["identified"] - s["identified"]) <= 1e-9 * max(1.0, abs(s["identified"])), p["name"]
    assert (tmp_path / "proc" / "report.json").exists() and (tmp_path / "proc" / "measurements.json").exists()
    # reprojection of the identified chain into the images: the corners' own noise level (sub-pixel)
    rp = out["reprojection"]
    assert rp["n_poses"] >= 20 and rp["n_corners"] > 20 * 2 * 6
    assert 0 < rp["rms_px"] < 1.0 and rp["worst_poses"][0]["rms_px"] == max(e["rms_px"] for e in rp["per_pose"])
    assert "reprojection: RMS" in out["summary_text"]
    # an independent measurement of the exported images (plain OpenCV: ChArUco detection + solvePnP with the
    # recording's distortion, frame by frame) agrees with the pipeline's poses within the single-frame noise
    import yaml

    from vision_calib import frames as F
    from vision_calib.targets import target_from_dict

    recd = yaml.safe_load((d / "rec" / "recording.yaml").read_text())
    tgt = target_from_dict(recd["target"])
    cam = recd["camera"]
    K = np.array([[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1]])
    det = cv2.aruco.CharucoDetector(tgt.cv_board())
    ids3, p3 = tgt.corner_points()
    measured = {p["pose_id"]: np.array(p["T_cam_target"]) for p in out["measurements"]["poses"] if p["valid"]}
    for pid in ("000", "007", "015"):
        img = cv2.imread(str(d / "rec" / "images" / pid / "00.png"), cv2.IMREAD_GRAYSCALE)
        cc, ci, _, _ = det.detectBoard(img)
        ok, rvec, tvec = cv2.solvePnP(p3[ci.ravel()], cc, K, np.array(cam["dist"]), flags=cv2.SOLVEPNP_IPPE)
        err = F.pose_error(F.T_from_rvec_tvec(rvec.ravel(), tvec.ravel())[None], measured[pid][None])[0]
        assert np.linalg.norm(err[:3]) < 1e-3 and np.degrees(np.linalg.norm(err[3:])) < 0.2, (pid, err)


def test_damaged_folder_skips_bad_poses_with_reasons(exported, tmp_path):
    d, _ = exported
    rec = tmp_path / "rec"
    shutil.copytree(d / "rec", rec)
    shutil.rmtree(rec / "images" / "001")                                   # images missing
    (rec / "images" / "002" / "00.png").write_bytes(b"\x89PNG\r\n garbage")  # corrupt PNG
    (rec / "images" / "002" / "01.png").write_bytes(b"")                     # empty file
    for f in (rec / "images" / "003").glob("*.png"):                        # target not visible
        cv2.imwrite(str(f), np.full((768, 1024), 128, np.uint8))
    (rec / "images" / "notes.txt").write_text("operator notes")             # extra files
    (rec / "images" / "005" / "thumbs.db").write_bytes(b"x")
    out = process_folder(rec, tmp_path / "out")
    rej = {r["pose_id"]: r["reason"] for r in out["measurements"]["rejected"]}
    assert set(rej) == {"001", "002", "003"}, rej  # (an image of the wrong size is refused up front: fuzz)
    assert "no images" in rej["001"]
    assert out["measurements"]["n_valid"] == 21
    assert any("notes.txt" in f for f in out["measurements"]["extra_files_ignored"])
    assert out["identification"]["converged"]


def test_too_few_usable_poses_fails_clearly_and_keeps_measurements(exported, tmp_path, capsys):
    d, _ = exported
    rec = tmp_path / "rec"
    shutil.copytree(d / "rec", rec)
    for sub in sorted((rec / "images").iterdir())[2:]:
        shutil.rmtree(sub)
    assert main(["process", str(rec), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "usable poses" in err or "equations" in err
    kept = json.loads((tmp_path / "out" / "measurements.json").read_text())
    assert kept["n_valid"] == 2


def test_missing_poses_csv_names_the_file(exported, tmp_path, capsys):
    d, _ = exported
    rec = tmp_path / "rec"
    shutil.copytree(d / "rec", rec)
    (rec / "poses.csv").unlink()
    assert main(["process", str(rec), "--out", str(tmp_path / "out")]) == 2
    assert "poses.csv: file not found" in capsys.readouterr().err
    # NaN joint value
    shutil.copy(d / "rec" / "poses.csv", rec / "poses.csv")
    lines = (rec / "poses.csv").read_text().splitlines()
    lines[3] = lines[3].rsplit(",", 1)[0] + ",nan"
    (rec / "poses.csv").write_text("\n".join(lines) + "\n")
    assert main(["process", str(rec), "--out", str(tmp_path / "out")]) == 2
    assert "line 4" in capsys.readouterr().err


def test_recording_contradicting_the_scene_is_refused(exported, tmp_path, capsys):
    d, _ = exported
    rec = tmp_path / "rec"
    shutil.copytree(d / "rec", rec)
    y = (rec / "recording.yaml").read_text()
    (rec / "recording.yaml").write_text(y.replace("camera_mount: base", "camera_mount: fixed"))
    assert main(["process", str(rec), "--out", str(tmp_path / "out")]) == 2
    assert "camera_mount" in capsys.readouterr().err


def test_export_into_a_used_folder_is_refused_before_rendering(exported, capsys):
    d, _ = exported
    assert main(["simulate", H4, "--out", str(d / "again"), "--poses", "20", "--export-recording", str(d / "rec")]) == 2
    assert "new or empty folder" in capsys.readouterr().err


def test_failed_identification_keeps_the_measurements(tmp_path, capsys):
    # a sensor so noisy that no target is detected: measurement runs, identification cannot
    from vision_calib.rig import SCENES_DIR

    text = (SCENES_DIR / "rx90_eye_in_hand.yaml").read_text()
    text = text.replace("robot: robots/rx90.yaml", f"robot: {SCENES_DIR / 'robots/rx90.yaml'}")
    text = text.replace("target: ../targets/charuco_a5.yaml", f"target: {SCENES_DIR.parent / 'targets/charuco_a5.yaml'}")
    text = text.replace("effects: {noise_grey: 2.0, blur_px: 0.6}", "effects: {noise_grey: 300.0, blur_px: 6.0}")
    scene = tmp_path / "noisy.yaml"
    scene.write_text(text)
    out = tmp_path / "out"
    assert main(["simulate", str(scene), "--out", str(out), "--poses", "8", "--frames", "1", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "usable poses" in err and "rejected" in err
    kept = json.loads((out / "measurements.json").read_text())
    assert kept["n_poses"] == 8 and kept["n_valid"] < 6
