"""The planner's pose noise model against rendered, detected and PnP-measured poses (issue 34): the image-model
covariance of ``planning.design.pose_covariances`` (Cramér-Rao bound of the frame-averaged corners + the detector's
systematic corner error s, the same in every frame) whitens the true pose errors of the scene's own random poses.
Prints, per scene, chi2/6 of the true errors under the bound alone and under the model with the shipped
``SYSTEMATIC_CORNER_PX``, the s that makes chi2/6 = 1, and the RMS per component against the model's std.

    PYTHONPATH=. python benchmarks/bench_plan_noise.py --scenes ur5e_eye_in_hand.yaml,rx90_eye_in_hand.yaml --poses 60
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.optimize import brentq


def main() -> None:
    from vision_calib import frames as F
    from vision_calib.experiment.image_chain import InlineImagePool, measure_poses
    from vision_calib.experiment.simulate import image_chain_of
    from vision_calib.experiment.steps import rngs, scene_truth
    from vision_calib.measure.covariance import image_bound_pose_cov
    from vision_calib.measure.pnp import reprojection_jacobian
    from vision_calib.planning.design import SYSTEMATIC_CORNER_PX
    from vision_calib.rig import SCENES_DIR, load_scene, scene_poses
    from vision_calib.targets import load_target

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="ur5e_eye_in_hand.yaml,rx90_eye_in_hand.yaml")
    ap.add_argument("--poses", type=int, default=60)
    ap.add_argument("--frames", type=int, default=2)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--by-angle", action="store_true", help="also the information-matched s per 10-degree band of "
                    "the view angle (the board's normal against the line of sight)")
    args = ap.parse_args()
    for name in args.scenes.split(","):
        scene = load_scene(SCENES_DIR / name.strip())
        setup, cam = scene.setup, scene.setup.camera
        rng = rngs(args.seed)[0]
        q = setup.sample_poses(rng, args.poses) if scene.poses.kind == "configurations" else \
            scene_poses(scene, rng, args.poses)  # a named set (thesis): its region's sampler
        T = setup.T_cam_target(q, scene_truth(scene))
        chain = image_chain_of(scene)
        pms, _ = measure_poses(chain, T, [f"{i:03d}" for i in range(len(T))], 7, args.frames, pool=InlineImagePool(chain))
        target = load_target(scene.target_path)
        _, p = target.corner_points()
        E, CR, U, CM = [], [], [], []
        for Tk, pm in zip(T, pms):
            if pm.valid:
                E.append(F.pose_error(Tk[None], pm.T_cam_target[None])[0])
                CM.append(pm.cov)
                CR.append(image_bound_pose_cov(target, cam, Tk, scene.effects, args.frames))
                J = reprojection_jacobian(Tk, p, cam)
                U.append(np.linalg.inv(J.T @ J))
        E, CR, U, CM = map(np.array, (E, CR, U, CM))

        def chi(s):
            return float(np.mean(np.einsum("ki,ki->k", E, np.linalg.solve(CR + s**2 * U, E[..., None])[..., 0])) / 6)

        s1 = brentq(lambda s: chi(s) - 1, 1e-4, 5)
        chi_k = np.einsum("ki,ki->k", E, np.linalg.solve(CR + SYSTEMATIC_CORNER_PX**2 * U, E[..., None])[..., 0]) / 6
        chi_m = np.einsum("ki,ki->k", E, np.linalg.solve(CM, E[..., None])[..., 0]) / 6
        # the planner's covariance against the measurement's own per pose: mean generalised eigenvalue (trace ratio)
        ratio = np.mean([np.trace(np.linalg.solve(CR[k] + SYSTEMATIC_CORNER_PX**2 * U[k], CM[k])) / 6
                         for k in range(len(E))])
        iCM = np.linalg.inv(CM)

        def info(s):  # the planner's information against the measurement's own: mean tr(Cm^-1 Cp(s)) / 6
            return float(np.mean(np.einsum("kij,kji->k", iCM, CR + s**2 * U)) / 6)

        s_info = brentq(lambda s: info(s) - 1, 1e-4, 5)
        # the information the identification gets from the truth: the measurement's, over its mean chi2/6 of the
        # true errors (a weighted fit whose weights are off by a common factor c has the information I_m / c)
        c_m = float(np.mean(chi_m))
        s_true = brentq(lambda s: info(s) - c_m, 1e-4, 5)
        sd = np.sqrt(np.mean(np.diagonal(CR + SYSTEMATIC_CORNER_PX**2 * U, axis1=1, axis2=2), axis=0))
        rms = np.sqrt(np.mean(E**2, axis=0))
        k = np.array([1e3] * 3 + [np.degrees(1.0)] * 3)
        print(f"{name}: {len(E)} of {len(T)} poses measured ({args.frames} frames); chi2/6 bound alone {chi(0.0):.3g}, "
              f"with s = {SYSTEMATIC_CORNER_PX:g} px {chi(SYSTEMATIC_CORNER_PX):.3g} (median {np.median(chi_k):.3g}); "
              f"chi2/6 = 1 at s = {s1:.4g} px; under the measurement's own covariance {np.mean(chi_m):.3g} (median "
              f"{np.median(chi_m):.3g}); measurement / planner covariance, mean trace ratio {ratio:.3g}; the planner's "
              f"information / the measurement's {1 / info(SYSTEMATIC_CORNER_PX):.3g}, equal at s = {s_info:.4g} px; to the true errors' (the measurement's / its chi2/6) at s = {s_true:.4g} px\n"
              f"  RMS  tx ty tz [mm] {np.round(rms[:3] * k[:3], 4)}, rx ry rz [deg] {np.round(rms[3:] * k[3:], 4)}\n"
              f"  model std           {np.round(sd[:3] * k[:3], 4)},                {np.round(sd[3:] * k[3:], 4)}",
              flush=True)
        if args.by_angle:
            by_angle(E, CR, U, iCM, T[[k for k, pm in enumerate(pms) if pm.valid]], target)


def by_angle(E, CR, U, iCM, T, target) -> None:
    """Per 10-degree band of the view angle (``planning.view.incidence_rad``): the s matching the planner's
    information to the measurement's, and the planner's s(theta) there (``planning.design.systematic_corner_px``)."""
    from vision_calib.planning.design import SYSTEMATIC_CORNER_PX, systematic_corner_px
    from vision_calib.planning.view import incidence_rad

    theta = incidence_rad(T, target)
    ang = np.degrees(theta)
    model = systematic_corner_px(theta)
    for lo in range(0, 90, 10):
        m = (ang >= lo) & (ang < lo + 10)
        if m.sum() < 3:
            continue

        def info(s):
            return float(np.mean(np.einsum("kij,kji->k", iCM[m], CR[m] + s**2 * U[m])) / 6) - 1

        s_b = brentq(info, 1e-4, 5) if info(1e-4) < 0 else float("nan")
        print(f"  view angle {lo}-{lo + 10} deg: {m.sum()} poses, information-matched s {s_b:.4g} px; the planner's "
              f"s(theta) {np.median(model[m]):.4g} px (constant part {SYSTEMATIC_CORNER_PX:g})", flush=True)


if __name__ == "__main__":
    main()
