"""The chain's reprojection figures of ``process`` (experiment/process.py): they count only the points the
measurement used and say so ("over N of M points", the dropped ones named per view), and a reprojection RMS far
above the noise model with given (not refined) intrinsics is a warning naming the figures and pointing to
--refine-intrinsics (simulated recording with fx 2 % off; the real ViSP set)."""

import json
import os
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from vision_calib.experiment.process import process_folder, process_once
from vision_calib.experiment.reprojection_check import (REPROJECTION_K, label_points, reprojection_noise_check,
                                                        used_corners)
from vision_calib.measure.detect import Detection
from vision_calib.measure.reprojection import chain_reprojection
from vision_calib.rig import SCENES_DIR, load_scene

RX90 = SCENES_DIR / "rx90_eye_in_hand.yaml"
REAL = Path(os.environ["VISION_CALIB_SHARED_DATA"]) / "real" / "visp_eye_to_hand_apriltag"  # tests/conftest.py


def _pm(pid, frames, sigma=0.1, valid=True):
    return SimpleNamespace(pose_id=pid, frames=tuple(frames), sigma_px=sigma, valid=valid)


def test_reprojection_counts_only_the_points_the_measurement_used():
    """Three corners the view rule dropped (planted 20 px off) and a frame it rejected: the figure is that of the
    other points exactly (here 0 px), labelled "over N of M points (K dropped ...)"; the raw one counts them."""
    from vision_calib.targets import load_target

    cam = load_scene(RX90).setup.camera
    target = load_target(SCENES_DIR.parent / "targets" / "charuco_a5.yaml")
    ids, p = target.corner_points()
    T = np.eye(4)
    T[:3, 3] = [-0.05, -0.03, 0.5]
    uv = cam.project(p @ T[:3, :3].T + T[:3, 3])
    bad = np.array([2, 7, 11])
    uv_bad = uv.copy()
    uv_bad[bad] += 20.0
    d0 = Detection(True, "", np.asarray(ids), uv_bad, (cam.width, cam.height), frame_index=0)
    d1 = Detection(True, "", np.asarray(ids), uv + 50.0, (cam.width, cam.height), frame_index=1)  # rejected frame
    frames = [{"frame_index": 0, "valid": True, "dropped_corners": [{"id": int(ids[k]), "residual_px": 20.0}
                                                                      for k in bad]},
              {"frame_index": 1, "valid": False, "reason": "corners inconsistent with one plane"}]
    dets = {"p0": [d0, d1]}
    used, counts = used_corners(dets, [_pm("p0", frames)], target)
    n = len(ids)
    assert counts == {"p0": (n - 3, 2 * n)} and [len(d.ids) for d in used["p0"]] == [n - 3]
    raw = chain_reprojection(T[None], dets, ["p0"], target, cam)
    block = label_points(chain_reprojection(T[None], used, ["p0"], target, cam), counts)
    assert raw["rms_px"] > 40 and block["rms_px"] < 1e-9 and block["n_corners"] == n - 3
    e = block["per_pose"][0]
    assert e["n_detected"] == 2 * n and e["n_dropped"] == n + 3
    assert e["points"] == f"over {n - 3} of {2 * n} points ({n + 3} dropped by the view rule: not counted)"
    assert block["points"] == e["points"] and block["worst_poses"][0]["points"] == e["points"]


@pytest.mark.parametrize("source,robot,sigma,rms,warned", [
    ("recording.yaml", None, 0.1, 3.0 * np.sqrt(2) * 0.1, False),  # 3 x the corner noise: explained
    ("recording.yaml", None, 0.1, 5.0 * np.sqrt(2) * 0.1, True),   # 5 x: the warning
    ("calibrated from the recording", None, 0.1, 50.0, False),     # refined intrinsics: not the pointer
    ("recording.yaml", {"source": "given", "translation_mm": 0.2, "rotation_deg": 0.02}, 0.1, 2.0, False),
    ("recording.yaml", {"source": "estimated", "translation_mm": 1.3, "rotation_deg": 0.2}, 0.1, 2.0, "note"),
])
def test_noise_check_threshold(source, robot, sigma, rms, warned):
    """Ratio to sqrt(2 sigma^2 + robot px^2) above REPROJECTION_K warns with given intrinsics; a given robot
    error that explains the RMS does not; an estimated one that explains it is a note (not a warning) naming the
    estimate for the user to judge."""
    pms = [_pm(str(k), [], sigma) for k in range(5)]
    robot_px2 = 0.0 if robot is None else 1.5**2
    rec, warn = reprojection_noise_check({"rms_px": rms, "points": "over 40 of 40 points"}, pms, {"source": source},
                                         robot_px2, robot)
    assert rec["corner_noise_px"] == pytest.approx(sigma)
    assert rec["ratio"] == pytest.approx(rms / np.sqrt(2 * sigma**2 + robot_px2))
    if warned == "note":
        warn, warned = rec["note"], True
    else:
        assert "note" not in rec
    assert (warn is not None) == warned, warn
    if warned:
        assert f"reprojection RMS {rms:.3g} px over 40 of 40 points" in warn and "process --refine-intrinsics" in warn
        assert f"above {REPROJECTION_K:g} x" in warn
        if robot:
            assert "estimated from these data at 1.3 mm, 0.2 deg per axis" in warn


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from vision_calib.experiment.simulate import run_simulation

    d = tmp_path_factory.mktemp("reproj")
    run_simulation(RX90, out_dir=d / "sim", seed=3, n_poses=12, frames=2, export_recording=d / "rec", workers=2,
                   plots=False)
    return d / "rec"


def focal_off(recording, tmp_path, factor=1.02):
    """A copy of ``recording`` (tmp_path/rec_fx) whose recording.yaml gives fx and fy ``factor`` x the true ones."""
    bad = tmp_path / "rec_fx"
    shutil.copytree(recording, bad)
    doc = yaml.safe_load((bad / "recording.yaml").read_text())
    doc["camera"]["fx"] *= factor
    doc["camera"]["fy"] *= factor
    (bad / "recording.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return bad


@pytest.mark.slow
def test_wrong_given_focal_length_warns_and_points_to_refine(recording, tmp_path):
    """The same images with the recording's fx, fy 2 % off: the reprojection RMS rises above REPROJECTION_K x its
    prediction and the warning names it; with the right intrinsics no such warning, all points counted."""
    ok = process_folder(recording, tmp_path / "ok", plots=False)
    chk = ok["reprojection"]["noise_check"]
    assert chk["ratio"] < REPROJECTION_K and not any("reprojection RMS" in w for w in ok["warnings"])
    n = ok["reprojection"]["n_corners"]
    assert ok["reprojection"]["points"] == f"over {n} of {n} points"
    assert "reprojection points: the figures count the points the measurement used" in ok["summary_text"]
    bad = focal_off(recording, tmp_path)
    rep = process_once(bad, tmp_path / "fx", plots=False)  # the given intrinsics alone
    chk = rep["reprojection"]["noise_check"]
    assert chk["ratio"] > REPROJECTION_K
    warn = [w for w in rep["warnings"] if w.startswith("reprojection RMS")]
    assert len(warn) == 1 and f"{chk['ratio']:.1f} x what the noise model predicts" in warn[0]
    assert "the intrinsics were given (recording.yaml), not refined" in warn[0] and "--refine-intrinsics" in warn[0]
    # process tests that cause (experiment/cause.py): the refined intrinsics win decisively and are applied
    full = process_folder(bad, tmp_path / "fx2", plots=False)
    assert full["cause"]["chosen"] == "refined" and full["intrinsics"]["source"] == "calibrated from the recording"
    assert full["reprojection"]["noise_check"]["ratio"] < chk["ratio"] / 2


@pytest.mark.slow
def test_the_cause_test_reads_what_the_reports_say(recording, tmp_path):
    """process's cause test compares each hypothesis' ``view`` (fitted without the work only the written report
    needs: the held-out mounts-only fits, the intrinsics sensitivity); it holds the figures the reports then say,
    for both hypotheses (fx, fy 2 % off)."""
    from vision_calib.experiment.cause import cause_test_applies, hypothesis
    from vision_calib.experiment.process import fit_measured, measure_folder
    from vision_calib.io.recording import read_recording

    bad = focal_off(recording, tmp_path)
    rec = read_recording(bad)
    given = measure_folder(rec)
    fits = [fit_measured(given, tmp_path / "given", plots=False),
            fit_measured(measure_folder(rec, True, reuse=given), tmp_path / "refined", plots=False)]
    assert cause_test_applies(fits[0].view)
    for fit, name in zip(fits, ("given", "refined")):
        view = fit.full_view()  # (its k-fold fits made now: the cause test asks for them when the BIC is decisive)
        rep = fit.finish()
        assert "mounts_only" in rep["holdout"] and "mounts_only" not in view["holdout"]
        assert cause_test_applies(view) == cause_test_applies(rep)
        assert hypothesis(view, name) == hypothesis(rep, name)


@pytest.mark.slow
def test_an_error_building_the_chosen_refined_report_keeps_the_given_one(recording, tmp_path, monkeypatch):
    """The refined hypothesis' report is built only once it is chosen: an error there (planted in its intrinsics
    sensitivity) is one of the refined fit, as when its fit fails: the given intrinsics are kept and the cause block
    says why."""
    import vision_calib.experiment.camera_step as camera_step
    from vision_calib.errors import DataError

    sensitivity = camera_step.intrinsics_sensitivity

    def planted(*a, given_std=None, **k):
        if given_std:  # the refined hypothesis: intrinsics with their std
            raise DataError("planted sensitivity error")
        return sensitivity(*a, given_std=given_std, **k)

    monkeypatch.setattr(camera_step, "intrinsics_sensitivity", planted)
    bad = focal_off(recording, tmp_path)
    rep = process_folder(bad, tmp_path / "out", plots=False)
    assert rep["cause"]["chosen"] == "given" and "planted sensitivity error" in rep["cause"]["message"]
    assert rep["intrinsics"]["source"] == "recording.yaml"
    assert json.loads((tmp_path / "out" / "report.json").read_text())["cause"]["chosen"] == "given"


@pytest.mark.skipif(not REAL.is_dir(), reason="real ViSP data not available")
def test_real_visp_set_notes_its_factory_intrinsics(tmp_path, capsys):
    """The real ViSP eye-to-hand set (read in place): 5-6 px with the camera's factory intrinsics, far above its
    corner noise, which the fit ascribes to an estimated robot error. Eight poses cannot tell that robot error from
    wrong intrinsics (a clean simulated 0.2 mm robot gives the same pattern), so it is a printed note naming the
    estimate and pointing to --refine-intrinsics, not a verdict warning."""
    from vision_calib.cli import main

    assert main(["import-visp", str(REAL), "--out", str(tmp_path / "rec")]) == 0
    assert main(["process", str(tmp_path / "rec"), "--out", str(tmp_path / "out")]) == 0
    cap = capsys.readouterr()
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    chk = rep["reprojection"]["noise_check"]
    assert chk["ratio_corner_noise"] > REPROJECTION_K and chk["ratio"] <= REPROJECTION_K
    robot = rep["handeye"]["robot_pose_std"]
    assert not [w for w in rep["warnings"] if w.startswith("reprojection RMS")]
    note = chk["note"]
    assert f"{rep['reprojection']['rms_px']:.3g} px over 32 of 32 points" in note
    assert f"estimated from these data at {robot['translation_mm']:.3g} mm" in note
    assert "--refine-intrinsics" in note and note in cap.out + cap.err
