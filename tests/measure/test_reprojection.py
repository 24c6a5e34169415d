"""Reprojection RMS in pixels of a calibrated chain (hand-eye report): zero on exact data, the corner noise
on noisy data, and the worst pose named."""

import numpy as np
import pytest

from vision_calib import frames
from vision_calib.identify.handeye_problem import solve_handeye
from vision_calib.report.handeye import handeye_report
from vision_calib.measure import Detection
from vision_calib.measure.reprojection import chain_reprojection

from test_pnp import DIST_INTR


def _handeye_data(charuco, rng, N=12):
    F = np.array([frames.T_from_xyz_rotvec(np.r_[rng.uniform([0.3, -0.1, 0.2], [0.5, 0.1, 0.3]),
                                                 [np.pi, 0, 0] + rng.normal(scale=0.15, size=3)]) for _ in range(N)])
    A = frames.inv_T(frames.T_from_xyz_rpy([0.4, 0.0, 0.9], np.radians([180, 0, 0])))  # camera above, looking down
    B = frames.T_from_xyz_rpy([-0.13, -0.09, 0.05], [np.pi, 0, 0])  # board below the flange, facing the camera
    return F, A, B, A @ F @ B


def _detections(charuco, T_model, rng, sigma, shift=None):
    ids, p = charuco.corner_points()
    out = {}
    for k, T in enumerate(T_model):
        uv = DIST_INTR.project(frames.transform_points(T, p))
        if shift is not None and k == shift[0]:
            uv = uv + shift[1]
        out[str(k)] = [Detection(True, "", ids, uv + rng.normal(0, sigma, uv.shape), DIST_INTR.size, f)
                       for f in range(2)]
    return out


def test_exact_data_reproject_to_zero_and_noise_to_its_rms(charuco):
    rng = np.random.default_rng(0)
    F, A, B, M = _handeye_data(charuco, rng)
    labels = [str(k) for k in range(len(M))]
    exact = chain_reprojection(M, _detections(charuco, M, rng, 0.0), labels, charuco, DIST_INTR)
    assert exact["rms_px"] < 1e-6 and exact["n_poses"] == len(M) and exact["n_corners"] == 2 * 54 * len(M)
    noisy = chain_reprojection(M, _detections(charuco, M, rng, 0.3), labels, charuco, DIST_INTR)
    assert noisy["rms_px"] == pytest.approx(0.3 * np.sqrt(2), rel=0.05)  # 2-D distance of 0.3 px per coordinate


def test_handeye_report_reprojection_names_the_worst_pose(charuco):
    rng = np.random.default_rng(1)
    F, A, B, M = _handeye_data(charuco, rng)
    labels = [str(k) for k in range(len(M))]
    d = np.concatenate([2e-4 * rng.normal(size=(len(M), 3)), 2e-4 * rng.normal(size=(len(M), 3))], 1)
    Mm = frames.perturb_pose(M, d)
    res, Ae, Be, pb = solve_handeye(F, Mm, "fixed", sigma_t_m=2e-4, sigma_rot_rad=2e-4, labels=labels)
    dets = _detections(charuco, M, rng, 0.1, shift=(5, np.array([3.0, 4.0])))  # pose 5's corners 5 px off
    rep = handeye_report(res, Ae, Be, pb, detections=dets, target=charuco, intrinsics=DIST_INTR)["reprojection"]
    assert rep["worst_poses"][0]["pose_id"] == "5" and rep["worst_poses"][0]["rms_px"] == pytest.approx(5.0, abs=0.5)
    others = [e["rms_px"] for e in rep["per_pose"] if e["pose_id"] != "5"]
    assert max(others) < 1.0  # the chain's 0.2 mm / 0.2 mrad fit error is well below a pixel here
    assert handeye_report(res, Ae, Be, pb)["reprojection"] is None
