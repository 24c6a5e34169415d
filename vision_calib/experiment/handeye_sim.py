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


__all__ = ["HandeyeData", "simulate_handeye", "PNP_SCALE"]
