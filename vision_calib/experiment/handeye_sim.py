"""Simulated flange-pose data for hand-eye calibration (no images): what a robot controller reports and
what PnP measures, with the truth beside them.

For a serial scene (``mount`` eye_in_hand or fixed) and joint sets q drawn as the scene draws its
identification poses (target in view):

- true flange poses ``T_base_flange = chain.flange(q, x_true)`` (the arm alone, true geometry);
- reported flange poses: the true ones perturbed by the robot's pose error, ``frames.perturb_pose`` with
  independent N(0, robot_std_mm^2) per translation axis and N(0, robot_std_deg^2) per rotation axis (base
  frame axes, about the flange origin);
- measured ``T_cam_target`` = truth perturbed by N(0, pose_cov), pose_cov = ``pnp_scale^2`` x the image-model
  Cramér-Rao bound of the pose (``measure.covariance.image_bound_pose_cov``: the scene's camera, target,
  sensor effects and frames per pose). The default pnp_scale 10 gives the total PnP error of the image
  chain (README, RX-90 A5 board: total RMS 0.009 / 0.007 / 0.056 mm and 0.015 / 0.012 / 0.003 deg, about
  10x the random part, the detector's bias dominating), with the bound's anisotropy (depth and tilt worst).
- the true mounts: A, B of :mod:`vision_calib.identify.handeye_problem` (``T_cam_flange``,
  ``T_base_target`` for eye_in_hand; ``T_cam_base``, ``T_flange_target`` for fixed).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import frames
from ..errors import ConfigError
from ..rig import Scene, load_scene
from .steps import rngs, scene_truth

#: factor on the image-model bound that gives the image chain's total PnP error (module docstring)
PNP_SCALE = 10.0


@dataclass(frozen=True)
class HandeyeData:
    """Simulated hand-eye recording. Arrays: (N, 4, 4) transforms [m], pose_cov (N, 6, 6) [m, rad] in the
    ``frames.pose_error`` convention of T_cam_target; A_true, B_true (4, 4); robot_std_m / robot_std_rad:
    the std per axis of the flange pose error that was simulated."""

    mount: str
    T_base_flange: np.ndarray
    T_base_flange_true: np.ndarray
    T_cam_target: np.ndarray
    pose_cov: np.ndarray
    A_true: np.ndarray
    B_true: np.ndarray
    labels: tuple
    robot_std_m: float
    robot_std_rad: float


def simulate_handeye(scene: Scene | str | Path, n_poses: int, seed: int, robot_std_mm: float = 0.2,
                     robot_std_deg: float = 0.02,
                     pnp_scale: float = PNP_SCALE, n_frames: int | None = None) -> HandeyeData:
    """Hand-eye data of a serial ``scene`` (path or Scene) with ``n_poses`` poses; seed: the run seed
    (poses and noise streams of :func:`.steps.rngs`; the truth from the scene's truth seed)."""
    from ..measure.covariance import image_bound_pose_cov
    from ..targets import load_target

    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    setup = scene.setup
    if setup.kind != "serial" or setup.mount not in ("eye_in_hand", "fixed"):
        raise ConfigError(f"{scene.path}: hand-eye simulation needs a serial robot with mount eye_in_hand or fixed")
    rng_poses, rng_noise, _ = rngs(seed)
    x_true = scene_truth(scene)
    q = setup.sample_poses(rng_poses, int(n_poses))
    F_true = setup.chain.flange(q, x_true)
    TL, TR = setup.chain.nominal_transforms(x_true)
    if setup.mount == "eye_in_hand":  # chain T_target_base . flange . T_flange_cam
        A, B = frames.inv_T(TR), frames.inv_T(TL)
        M_true = A @ frames.inv_T(F_true) @ B
    else:  # chain T_cam_base . flange . T_flange_target
        A, B = TL, TR
        M_true = A @ F_true @ B
    np.testing.assert_allclose(M_true, setup.T_cam_target(q, x_true), atol=1e-9)  # one truth, two routes
    target = load_target(scene.target_path)
    nf = int(n_frames or scene.measurement.frames)
    cov = np.array([pnp_scale**2 * image_bound_pose_cov(target, setup.camera, Mk, scene.effects, nf) for Mk in M_true])
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    d = np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng_noise.normal(size=(len(q), 6)))
    st, sr = robot_std_mm * 1e-3, np.radians(robot_std_deg)
    e = np.concatenate([rng_noise.normal(scale=st, size=(len(q), 3)), rng_noise.normal(scale=sr, size=(len(q), 3))], 1)
    return HandeyeData(setup.mount, frames.perturb_pose(F_true, e), F_true, frames.perturb_pose(M_true, d), cov, A, B,
                       tuple(f"p{k:03d}" for k in range(len(q))), float(st), float(sr))


#: a single AR tag's pose noise, std per axis of the tag frame: translation x, y, z [mm] (depth along z the worst),
#: rotation x, y, z [deg] (tilt about the in-plane axes the worst)
TAG_STD_MM = (0.5, 0.5, 3.0)
TAG_STD_DEG = (1.0, 1.0, 0.1)


def _look_at(eye: np.ndarray, at: np.ndarray, roll: float) -> np.ndarray:
    """(3, 3) camera rotation (OpenCV: z forward) at ``eye`` looking at ``at``, rolled by ``roll`` [rad]."""
    z = (at - eye) / np.linalg.norm(at - eye)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.95 else np.array([1.0, 0.0, 0.0])
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z]) @ frames.so3_exp(np.array([0.0, 0.0, roll]))


def simulate_pose_pairs(n_pairs: int, seed: int, mount: str = "fixed", tag_std_mm=TAG_STD_MM, tag_std_deg=TAG_STD_DEG,
                        robot_std_mm: float = 0.1, robot_std_deg: float = 0.01) -> HandeyeData:
    """Pose pairs of a tag cell (no robot model, no images): what a TF recording of a tag detector and a robot
    gives. ``fixed``: a camera on a stand 1.1 m from the workspace, the tag on the arm tip (T_flange_target 5 cm
    out, turned), flange poses that show the tag to the camera at 0.25-0.6 m tilted by up to ~45 deg;
    ``eye_in_hand``: the camera on the flange (T_flange_cam), the tag on the table, camera poses 0.25-0.6 m from
    it, seen from up to ~50 deg off its normal. Measured T_cam_target: the truth perturbed per axis of the TAG
    frame (``tag_std_mm``, ``tag_std_deg``: anisotropic, a single tag's depth and tilt the worst); reported flange
    poses: perturbed by N(0, robot_std^2) per axis (``frames.perturb_pose``). ``pose_cov``: the true covariance of
    the measured poses in the camera frame (``frames.pose_error`` convention). Seeded by ``seed``."""
    if mount not in ("fixed", "eye_in_hand"):
        raise ConfigError(f"simulate_pose_pairs: mount must be fixed or eye_in_hand, got {mount!r}")
    rng = np.random.default_rng([int(seed), 27])
    centre = np.array([0.6, 0.0, 0.3])
    if mount == "fixed":
        T_base_cam = frames.make_T(_look_at(np.array([0.6, -0.8, 1.0]), centre, 0.0), [0.6, -0.8, 1.0])
        X = frames.make_T(frames.so3_exp(np.array([0.1, -0.2, 0.3])), [0.0, 0.03, 0.05])  # T_flange_target
    else:
        T_base_tgt = frames.make_T(frames.so3_exp(np.array([np.pi, 0.0, 0.4])), centre - [0.0, 0.0, 0.3])
        X = frames.make_T(frames.so3_exp(np.array([0.0, 0.05, np.pi / 2])), [0.0, 0.05, 0.08])  # T_flange_cam
    F, M = [], []
    while len(F) < n_pairs:
        if mount == "fixed":
            p = centre + rng.uniform(-0.15, 0.15, 3)
            R_view = _look_at(T_base_cam[:3, 3], p, rng.uniform(-np.pi, np.pi))  # a tag facing the camera: z away
            R_tag = R_view @ frames.so3_exp(np.r_[rng.normal(scale=0.45, size=2), 0.0])
            Mk = frames.inv_T(T_base_cam) @ frames.make_T(R_tag, p)
            Fk = frames.make_T(R_tag, p) @ frames.inv_T(X)
        else:
            d = rng.normal(size=3)
            d[2] = abs(d[2]) * 2.5  # above the tag (its z points down into the table)
            eye = T_base_tgt[:3, 3] + rng.uniform(0.25, 0.6) * d / np.linalg.norm(d)
            R_cam = _look_at(eye, T_base_tgt[:3, 3] + rng.uniform(-0.03, 0.03, 3), rng.uniform(-np.pi, np.pi))
            T_base_cam = frames.make_T(R_cam, eye)
            Mk = frames.inv_T(T_base_cam) @ T_base_tgt
            Fk = T_base_cam @ frames.inv_T(X)
        dist = np.linalg.norm(Mk[:3, 3])
        normal_z = (Mk[:3, :3] @ [0.0, 0.0, 1.0])[2]  # the tag's z in the camera: away from it when seen
        if 0.25 <= dist <= 0.6 * 1.0 + 0.35 and normal_z > np.cos(np.radians(50)):
            F.append(Fk)
            M.append(Mk)
    F, M = np.array(F), np.array(M)
    st = np.r_[np.asarray(tag_std_mm, float) * 1e-3, np.radians(np.asarray(tag_std_deg, float))]
    Bk = np.zeros((n_pairs, 6, 6))
    Bk[:, :3, :3] = M[:, :3, :3]
    Bk[:, 3:, 3:] = M[:, :3, :3]
    cov = np.einsum("nij,j,nkj->nik", Bk, st**2, Bk)
    e = np.einsum("nij,nj->ni", Bk, rng.normal(size=(n_pairs, 6)) * st)
    sr_m, sr_rad = robot_std_mm * 1e-3, np.radians(robot_std_deg)
    er = np.concatenate([rng.normal(scale=sr_m, size=(n_pairs, 3)), rng.normal(scale=sr_rad, size=(n_pairs, 3))], 1)
    if mount == "fixed":  # M = A G B: A = T_cam_base, B = T_flange_target
        A, B = frames.inv_T(T_base_cam), X
    else:  # A = T_cam_flange, B = T_base_target
        A, B = frames.inv_T(X), T_base_tgt
    return HandeyeData(mount, frames.perturb_pose(F, er), F, frames.perturb_pose(M, e), cov, A, B,
                       tuple(f"p{k:03d}" for k in range(n_pairs)), float(sr_m), float(sr_rad))


__all__ = ["HandeyeData", "simulate_handeye", "simulate_pose_pairs", "PNP_SCALE", "TAG_STD_MM", "TAG_STD_DEG"]
