"""The cause of a large reprojection error tested, not guessed (experiment/cause.py, issue 28 item 2): a simulated
eye-in-hand hand-eye recording (an accurate robot: 0.05 mm / 0.005 deg per axis, estimated), processed with
intrinsics 1.5 % off the true ones and no distortion where the lens has some: the fit would ascribe the misfit to
a robot pose error of millimetres; both hypotheses are fitted, the refined intrinsics win decisively, are applied,
and the robot pose error is estimated near the truth. With the true intrinsics the test does not apply."""

from __future__ import annotations

import importlib
import shutil

import pytest
import yaml
from flange_folder import simulated_flange_recording

from vision_calib.experiment.process import process_folder

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def flange_rec(tmp_path_factory):
    return simulated_flange_recording(tmp_path_factory.mktemp("cause"), 4, 20, 0.05, 0.005, 2)


def test_wrong_intrinsics_named_as_the_cause_and_refined(flange_rec, tmp_path):
    bad = tmp_path / "bad"
    shutil.copytree(flange_rec, bad)
    doc = yaml.safe_load((bad / "recording.yaml").read_text())
    cam = doc["camera"]
    doc["camera"] = {**cam, "fx": cam["fx"] * 1.015, "fy": cam["fy"] * 1.015, "dist": [0.0] * 5}
    (bad / "recording.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    rep = process_folder(bad, tmp_path / "out", plots=False)
    cause = rep["cause"]
    assert cause["chosen"] == "refined" and cause["decisive"], cause["message"]
    given, refined = cause["hypotheses"]
    assert given["rms_px"] > 4 * refined["rms_px"] and refined["n_intrinsics_refined"] >= 4
    # decisive: both hypotheses' k-fold held-out prediction fitted and compared
    assert "holdout" in given and "holdout" in refined and cause["holdout_agrees"] is True
    assert given["robot_pose_std"]["translation_mm"] > 0.3  # the misfit read as a robot error ...
    assert rep["intrinsics"]["source"] == "calibrated from the recording"  # ... the refined hypothesis applied
    robot = rep["handeye"]["robot_pose_std"]
    assert robot["translation_mm"] < 0.25 and robot["rotation_deg"] < 0.03, robot  # near the true 0.05 / 0.005
    assert "cause tested" in rep["summary_text"] and "the refined ones are applied" in rep["summary_text"]


def test_true_intrinsics_are_kept(flange_rec, tmp_path, monkeypatch):
    """With the true intrinsics (the robot's 0.05 mm error still puts the reprojection above 4x the corner
    noise, so the test runs) the given intrinsics are kept; the BIC not decisive, the refined hypothesis' held-out
    folds are not fitted (only the given one's, for its report)."""
    import vision_calib.experiment.poses as poses
    from vision_calib.experiment.cause import DECISIVE_BIC

    calls, holdout = [], poses.pair_holdout
    monkeypatch.setattr(poses, "pair_holdout", lambda *a, **k: calls.append(1) or holdout(*a, **k))
    rep = process_folder(flange_rec, tmp_path / "out", plots=False)
    cause = rep.get("cause") or {}
    assert cause.get("chosen", "given") == "given", cause["message"]
    assert rep["intrinsics"]["source"] == "recording.yaml"
    assert rep["holdout"]["decision"]["ok"] and len(calls) == 1
    if cause:
        assert cause["delta_bic"] <= DECISIVE_BIC and cause["holdout_agrees"] is None
        assert all("holdout" not in h for h in cause["hypotheses"]) and "held-out" not in cause["message"]
        assert cause["message"].endswith("the given intrinsics decisively: they are kept" if cause["delta_bic"]
                                         < -DECISIVE_BIC else "the given ones are kept")


def test_both_hypotheses_from_one_decode_and_detection_per_image(flange_rec, tmp_path, monkeypatch):
    """process decodes and detects every image once although it fits both hypotheses (the refined intrinsics are
    calibrated from, and the poses re-measured on, the given run's detections), and the chosen hypothesis's result
    is the one a run with --refine-intrinsics alone gives (OpenCV single-threaded: its calibration is then
    deterministic)."""
    import cv2
    import numpy as np

    from vision_calib.experiment.process import process_once

    D = importlib.import_module("vision_calib.measure.detect")  # the module (the package exports a function so named)

    bad = tmp_path / "bad"
    shutil.copytree(flange_rec, bad)
    doc = yaml.safe_load((bad / "recording.yaml").read_text())
    doc["camera"] = {**doc["camera"], "fx": doc["camera"]["fx"] * 1.015, "fy": doc["camera"]["fy"] * 1.015}
    (bad / "recording.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    loads, finds, load, find = [], [], D.load_gray, D._find_corners
    monkeypatch.setattr(D, "load_gray", lambda image, *a, **k: loads.append(str(image)) or load(image, *a, **k))
    monkeypatch.setattr(D, "_find_corners", lambda *a, **k: finds.append(1) or find(*a, **k))
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        rep = process_folder(bad, tmp_path / "out", plots=False)
        n_images = len(list((bad / "images").rglob("*.png")))
        assert rep["cause"]["chosen"] == "refined" and len(rep["cause"]["hypotheses"]) == 2
        assert sorted(loads) == sorted(set(loads)) and len(loads) == len(finds) == n_images
        alone = process_once(bad, tmp_path / "alone", plots=False, refine_intrinsics=True)
    finally:
        cv2.setNumThreads(threads)
    a, b = (r["handeye"]["transforms"] for r in (rep, alone))
    for k in a:
        assert np.array_equal(a[k]["matrix"], b[k]["matrix"]) and a[k]["std_xyz_m"] == b[k]["std_xyz_m"], k
    assert rep["intrinsics"]["values"] == alone["intrinsics"]["values"]
