"""Accuracy of the measurement chain against ground truth on rendered data (used by
``benchmarks/bench_measure.py`` and a slow test).

Chain per pose: TargetRenderer (ideal pinhole image, once) -> sensor.apply_effects (distortion, blur,
noise; n_frames independent frames) -> detect -> undistort -> PnP -> average -> PoseMeasurement.
Errors are ``frames.pose_error(T_true, T_measured)`` = [dt (m), dtheta (rad)] in the camera frame.
Split: *bias* = error of the same pose measured on one noise-free frame (distortion, blur and
quantisation only); *random part* = error - bias; compared with the bound computed from the image model
alone (``covariance.image_bound_pose_cov``: sensor noise and blur, target contrast, detector window; not
from the measured frames). z-scores: the error whitened by the pose covariance, per component, for the
covariance ``measure_pose`` gives (random + systematic, ``covariance.pose_covariance``) and for the
random-only one it gave before (corner scatter sigma_px^2 (J^T diag(n) J)^-1).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .. import frames
from ..camera import CameraIntrinsics
from ..measure.batch import detect_batch
from ..measure.detect import DetectConfig
from ..measure.covariance import image_bound_pose_cov
from ..measure.pnp import pose_cov_from_jacobian, project_pinhole, reprojection_jacobian, target_lookup
from ..measure.pose import MeasureConfig, measure_pose

COMPONENTS = ("tx", "ty", "tz", "rx", "ry", "rz")


def random_view_pose(rng: np.random.Generator, target, intr: CameraIntrinsics, dist_range=(0.4, 0.8),
                     tilt_deg: float = 35.0, min_visible: float = 0.9, max_tries: int = 100) -> np.ndarray:
    """Random T_cam_target: board centre at distance U(dist_range) [m] near the optical axis (offset up to
    a quarter of the field), board tilted by a random rotation of angle U(0, tilt_deg) about a random
    axis, with at least ``min_visible`` of the target corners inside the image."""
    x0, y0, x1, y1 = target.texture_extent_m()
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    _, p = target.corner_points()
    for _ in range(max_tries):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R = frames.T_from_xyz_rotvec(np.r_[0, 0, 0, axis * np.radians(rng.uniform(0, tilt_deg))])[:3, :3]
        d = rng.uniform(*dist_range)
        off = rng.uniform(-0.25, 0.25, 2) * np.array([intr.width / intr.fx, intr.height / intr.fy]) * d
        T = frames.make_T(R, np.array([off[0], off[1], d]) - R @ centre)
        uv = project_pinhole(T, p, intr)
        inside = (uv[:, 0] > 5) & (uv[:, 0] < intr.width - 6) & (uv[:, 1] > 5) & (uv[:, 1] < intr.height - 6)
        if inside.mean() >= min_visible:
            return T
    raise RuntimeError("random_view_pose: no pose with the target in view; widen dist_range or reduce tilt")


def pose_seeds(seed: int, n: int) -> list[int]:
    """n independent 63-bit seeds from a user seed (numpy SeedSequence)."""
    return [int(s.generate_state(1, np.uint64)[0] >> np.uint64(1)) for s in np.random.SeedSequence(seed).spawn(n)]


def measure_rendered_pose(renderer, effects, T_cam_target, n_frames: int, seed: int, intr: CameraIntrinsics,
                          detect_config: DetectConfig = DetectConfig(), config: MeasureConfig = MeasureConfig(),
                          pose_id=0, ideal=None):
    """Render (unless ``ideal`` (H, W) is given), apply effects to n_frames frames, measure.
    intr: the camera (with distortion) used by effects and measurement. Returns (PoseMeasurement, detections)."""
    from ..sensor import apply_effects

    target = renderer.target if renderer is not None else None
    if ideal is None:
        ideal = renderer.render(T_cam_target)
    imgs = apply_effects(ideal, effects, n_frames, seed, intr)
    dets = detect_batch(imgs, target, intr, detect_config)
    return measure_pose(dets, target, intr, pose_id, config), dets


def random_only_cov(m, dets, target, intr: CameraIntrinsics) -> np.ndarray:
    """The frame-scatter-only covariance sigma_px^2 (J^T diag(n) J)^-1 of a PoseMeasurement m (what
    ``measure_pose`` returned before the systematic part was added), n = frames per corner."""
    lookup = target_lookup(target)
    n = {}
    for d in dets:
        if d.valid:
            for i in d.ids:
                if int(i) in lookup:
                    n[int(i)] = n.get(int(i), 0) + 1
    ids = sorted(n)
    J = reprojection_jacobian(m.T_cam_target, np.array([lookup[i] for i in ids]), intr)
    return pose_cov_from_jacobian(J, m.sigma_px, np.array([n[i] for i in ids], dtype=float))


def _stats(acc: dict) -> dict:
    e, b, c = (np.array(acc[k]).reshape(-1, 6) for k in ("err", "bias", "bound"))
    r = e - b
    bound_rms = np.sqrt(c.mean(0))
    random_rms = np.sqrt((r**2).mean(0))
    bias_rms = np.sqrt((b**2).mean(0))
    zn, zo = (np.array(acc[k]).reshape(-1, 6) for k in ("z_new", "z_old"))
    return {"n_valid": int(len(e)), "rms": np.sqrt((e**2).mean(0)), "bias_rms": bias_rms, "mean": e.mean(0),
            "random_rms": random_rms, "bound_rms": bound_rms, "random_over_bound": random_rms / bound_rms,
            "bias_over_random": bias_rms / random_rms, "errors": e, "bias": b, "z_new": zn, "z_old": zo,
            "z_new_rms": np.sqrt((zn**2).mean(0)), "z_old_rms": np.sqrt((zo**2).mean(0)),
            "z_new_max": np.abs(zn).max(0), "z_old_max": np.abs(zo).max(0)}


def accuracy_study(target, intr: CameraIntrinsics, effects, n_poses: int = 50, n_frames: int = 10, seed: int = 0,
                   modes=("corners", "poses"), dist_range=(0.4, 0.8), tilt_deg: float = 35.0,
                   detect_config: DetectConfig = DetectConfig(), supersample: int = 2, renderer=None) -> dict:
    """Pose error statistics over ``n_poses`` random poses (seeded), for each averaging mode.

    Returns {"n_poses", "n_frames", "sigma_px" (pooled corner scatter), "effects": dict,
    mode: {"rms", "bias_rms", "random_rms", "bound_rms" (each (6,) [m, m, m, rad, rad, rad]),
    "random_over_bound", "bias_over_random" (6,), "z_new", "z_old" (P, 6) and their "_rms"/"_max" (6,),
    "n_valid", "errors" (P, 6), "bias" (P, 6)}}."""
    from ..render import TargetRenderer
    from ..sensor import apply_effects, effects_for_render

    own = renderer is None
    if own:  # the image chain's renderer: lens distortion drawn geometrically (experiment/image_chain.py)
        renderer = TargetRenderer(target, intr, supersample, distort=True)
    try:
        rng = np.random.default_rng(seed)
        seeds = pose_seeds(seed, n_poses)
        noiseless = dataclasses.replace(effects, full_well_e=0.0, read_noise_grey=0.0)
        out = {"n_poses": n_poses, "n_frames": n_frames, "effects": effects.to_dict(), "intrinsics": intr.to_dict()}
        acc = {m: {k: [] for k in ("err", "bias", "bound", "z_new", "z_old")} for m in modes}
        sig2, dof = 0.0, 0.0
        for k in range(n_poses):
            T = random_view_pose(rng, target, intr, dist_range, tilt_deg)
            ideal = renderer.render(T)
            eff, eff0 = effects_for_render(renderer, effects), effects_for_render(renderer, noiseless)
            dets0 = detect_batch(apply_effects(ideal, eff0, 1, seeds[k], intr), target, intr, detect_config)
            dets = detect_batch(apply_effects(ideal, eff, n_frames, seeds[k], intr), target, intr, detect_config)
            bound = np.diag(image_bound_pose_cov(target, intr, T, effects, n_frames, detect_config))
            for mode in modes:
                cfg = MeasureConfig(mode=mode)
                m0 = measure_pose(dets0, target, intr, k, cfg)
                m = measure_pose(dets, target, intr, k, cfg)
                if not (m.valid and m0.valid):
                    continue
                e = frames.pose_error(T, m.T_cam_target)
                a = acc[mode]
                a["err"].append(e)
                a["bias"].append(frames.pose_error(T, m0.T_cam_target))
                a["bound"].append(bound)
                a["z_new"].append(e / m.std)
                a["z_old"].append(e / np.sqrt(np.diag(random_only_cov(m, dets, target, intr))))
                if mode == modes[0] and np.isfinite(m.sigma_px) and m.n_frames_used > 1:
                    n_obs = sum(d.n_corners for d in dets if d.valid)
                    sig2 += m.sigma_px**2 * 2 * (n_obs - m.n_corners)
                    dof += 2 * (n_obs - m.n_corners)
        out["sigma_px"] = float(np.sqrt(sig2 / dof)) if dof > 0 else float("nan")
        for mode in modes:
            out[mode] = _stats(acc[mode])
        return out
    finally:
        if own:
            renderer.close()


def format_study(res: dict, modes=("corners", "poses")) -> str:
    """Human-readable table: per component rms / bias / random / image-model bound in mm and deg, the
    ratios random/bound and bias/random, and the z-score RMS / max of the new and the old covariance."""
    scale = np.array([1e3, 1e3, 1e3, *(3 * [np.degrees(1.0)])])
    lines = [f"poses={res['n_poses']} frames={res['n_frames']} corner sigma={res['sigma_px']:.4f} px"]
    head = "  {:<8}{:<10}" + "{:>10}" * 6
    lines.append(head.format("mode", "stat", "tx[mm]", "ty[mm]", "tz[mm]", "rx[deg]", "ry[deg]", "rz[deg]"))
    for mode in modes:
        if mode not in res:
            continue
        s = res[mode]
        for key in ("rms", "bias_rms", "random_rms", "bound_rms"):
            v = s[key] * scale
            lines.append(head.format(mode, key, *[f"{x:.4f}" for x in v]))
        for key, lab in (("random_over_bound", "rand/bound"), ("bias_over_random", "bias/rand"),
                         ("z_new_rms", "z rms new"), ("z_new_max", "|z|max new"), ("z_old_rms", "z rms old"),
                         ("z_old_max", "|z|max old")):
            lines.append(head.format(mode, lab, *[f"{x:.3f}" for x in s[key]]))
        lines.append(f"  {mode}: valid {s['n_valid']}/{res['n_poses']}")
    return "\n".join(lines)


def scene_z_study(scene_path, n_poses: int = 20, seeds=(1, 2, 3, 4, 5), pose_seed: int = 123) -> dict:
    """z-scores of the measured pose vs the true pose on a scene's own camera, target and sensor effects:
    ``n_poses`` of the scene's identification poses (at its true robot), each rendered once and measured
    with every noise seed. Returns {"n": measurements, "z_new", "z_old" (n, 6), "z_new_rms", "z_new_max",
    "z_old_rms", "z_old_max" (6,)}."""
    from ..experiment.simulate import image_chain_of
    from ..experiment.steps import scene_truth
    from ..render import TargetRenderer
    from ..rig import load_scene, scene_poses
    from ..sensor import apply_effects, effects_for_render
    from ..targets import load_target

    scene = load_scene(scene_path)
    chain = image_chain_of(scene)
    target, intr = load_target(chain.target_path), chain.camera
    Ts = scene.setup.T_cam_target(scene_poses(scene, np.random.default_rng(pose_seed), n_poses), scene_truth(scene))
    z_new, z_old = [], []
    with TargetRenderer(target, intr, chain.supersample, distort=True) as r:  # as the image chain renders
        for k, T in enumerate(Ts):
            ideal = r.render(T)
            for s in seeds:
                dets = detect_batch(apply_effects(ideal, effects_for_render(r, chain.effects), 10, 1000 * k + s, intr),
                                    target, intr)
                m = measure_pose(dets, target, intr, k, MeasureConfig(mode=chain.averaging))
                if not m.valid:
                    continue
                e = frames.pose_error(T, m.T_cam_target)
                z_new.append(e / m.std)
                z_old.append(e / np.sqrt(np.diag(random_only_cov(m, dets, target, intr))))
    zn, zo = np.array(z_new).reshape(-1, 6), np.array(z_old).reshape(-1, 6)
    return {"n": len(zn), "z_new": zn, "z_old": zo, "z_new_rms": np.sqrt((zn**2).mean(0)), "z_new_max": np.abs(zn).max(0),
            "z_old_rms": np.sqrt((zo**2).mean(0)), "z_old_max": np.abs(zo).max(0)}
