"""The camera intrinsics a recorded folder is processed with: ``process --camera camera.yaml``'s,
recording.yaml's (``camera`` or ``camera_file``), or calibrated from the recording's own images (no
intrinsics given, or ``process --refine-intrinsics``), and the report's ``intrinsics`` block that says which."""

from __future__ import annotations

from dataclasses import replace

from ..errors import DataError
from ..measure.intrinsics import PARAM_NAMES, calibrate_from_images

SOURCE_FILE = "recording.yaml"
SOURCE_CALIBRATED = "calibrated from the recording"
SOURCE_CAMERA_FILE = "camera file"


def recording_intrinsics(rec, refine: bool = False, progress: bool = False, camera_file=None):
    """(Recording with its camera set, report block). camera_file: a camera.yaml (``process --camera``)
    that replaces recording.yaml's intrinsics (size checked against the images; ConfigError naming it).
    The calibration uses the first frame of every pose
    (one view per pose; the other frames of a pose add noise averaging, not geometry). Report block:
    {source, values {fx, fy, cx, cy, k1, k2, p1, p2, k3}, std (None when given), rms_px, n_views_used,
    n_views_rejected, rejected_views [{name, reason}], coverage, warnings, given (recording.yaml's values
    when refined)}. DataError naming the folder when the calibration is impossible."""
    if camera_file is not None:
        from pathlib import Path

        from ..io.camera_file import load_camera_for_images

        rec = replace(rec, camera=load_camera_for_images(camera_file, rec.image_size, "process --camera"),
                      camera_file=Path(camera_file))
    if rec.camera is not None and not refine:
        c = rec.camera
        block = {"source": SOURCE_FILE if rec.camera_file is None else f"{SOURCE_CAMERA_FILE} {rec.camera_file}",
                 "values": dict(zip(PARAM_NAMES, (c.fx, c.fy, c.cx, c.cy, *c.dist))),
                 "std": None, "rms_px": None, "warnings": []}
        return rec, block
    pids = [pid for pid in rec.pose_ids if rec.images.get(pid)]
    try:
        res = calibrate_from_images([rec.images[p][0] for p in pids], rec.target, rec.image_size,
                                    names=[f"pose {p}" for p in pids], progress=progress)
    except DataError as exc:
        why = "has no camera fx/fy/cx/cy" if rec.camera is None else "asks to refine the intrinsics"
        raise DataError(f"{rec.folder}: recording.yaml {why}, and calibrating them from the images failed: "
                        f"{exc}") from None
    d = res.to_dict()
    block = {"source": SOURCE_CALIBRATED, "values": res.values(), "std": dict(res.std), "rms_px": res.rms_px,
             "n_views_used": d["n_views_used"], "n_views_rejected": d["n_views_rejected"],
             "rejected_views": [{"name": v.name, "reason": v.reason} for v in res.views if not v.used],
             "coverage": res.coverage, "warnings": [f"camera intrinsics: {w}" for w in res.warnings],
             "covariance": None if res.cov is None else res.cov.tolist()}
    if rec.camera is not None:
        c = rec.camera
        block["given"] = dict(zip(PARAM_NAMES, (c.fx, c.fy, c.cx, c.cy, *c.dist)))
    return replace(rec, camera=res.camera), block



def intrinsics_directions(block: dict, camera):
    """[(CameraIntrinsics moved by one std along an eigenvector of the intrinsics covariance)] for a
    report block of intrinsics calibrated from the recording (``covariance`` (9, 9) of PARAM_NAMES), else []."""
    import numpy as np

    from ..camera import CameraIntrinsics

    cov = block.get("covariance")
    if block.get("source") != SOURCE_CALIBRATED or cov is None:
        return []
    cov = np.asarray(cov, float)
    cov = np.where(np.isfinite(cov), cov, 0.0)
    lam, V = np.linalg.eigh(0.5 * (cov + cov.T))
    theta = np.array([camera.fx, camera.fy, camera.cx, camera.cy, *camera.dist], float)
    out = []
    for k in np.flatnonzero(lam > 1e-12 * max(lam.max(), 1e-300)):
        t = theta + np.sqrt(lam[k]) * V[:, k]
        out.append(CameraIntrinsics(camera.width, camera.height, *t[:4], tuple(float(v) for v in t[4:])))
    return out


def remeasure(dets: dict, labels, target, camera, mode: str):
    """(N, 4, 4) T_cam_target of the poses ``labels`` re-measured from their detections with ``camera``
    (undistortion + PnP only; no detection); None when one of them is no longer valid."""
    import numpy as np

    from ..measure import MeasureConfig, measure_pose

    T = []
    for lab in labels:
        pm = measure_pose(dets[lab], target, camera, pose_id=lab, config=MeasureConfig(mode=mode))
        if not pm.valid:
            return None
        T.append(pm.T_cam_target)
    return np.array(T)


def with_intrinsics_uncertainty(result, problem, setup, meas, dets, rec, block: dict, residual: str):
    """The identification ``result`` with the uncertainty of intrinsics calibrated from the same recording
    added to its covariance and std: for each eigen-direction i of their covariance (one std, camera
    moved by ``intrinsics_directions``) the poses are re-measured from their detections and the fit's
    linear response dx_i = -(J^T W J)^-1 J^T W dr_i is computed at the solution (J, W: the fit's Jacobian
    and weights, dr_i: the change of the residuals), then covariance += sum_i dx_i dx_i^T (first order;
    the intrinsics' errors are treated as independent of the pose noise). Unchanged when the intrinsics
    were given. Also returns {n_directions, std_inflation {name: factor}}."""
    import numpy as np

    dirs = intrinsics_directions(block, rec.camera)
    if not dirs or result.covariance is None:
        return result, None
    labels = list(problem.labels)
    pos = {lab: k for k, lab in enumerate(meas.labels)}
    sub = meas.subset([pos[lab] for lab in labels])
    x = np.asarray(result.identified, float)
    free = np.asarray(problem.params.free, bool)
    J = np.asarray(problem.jacobian(x), float)[..., free]  # (k, m, nf)
    W = np.linalg.inv(problem.obs_cov)  # (k, m, m)
    N = np.einsum("kmi,kmn,knj->ij", J, W, J)
    r0 = np.asarray(problem.residual(x), float)
    C = np.zeros_like(N)
    for cam in dirs:
        T = remeasure(dets, labels, rec.target, cam, rec.averaging)
        if T is None:
            continue
        p2 = setup.problem(type(sub)(sub.poses, sub.joints, T, sub.cov, sub.labels), residual,
                           params=problem.params)
        dr = np.asarray(p2.residual(x), float) - r0
        dx = -np.linalg.solve(N, np.einsum("kmi,kmn,kn->i", J, W, dr))
        C += np.outer(dx, dx)
    return add_covariance(result, C, len(dirs))


def add_covariance(result, C, n_directions: int):
    """(result with C (n_free, n_free) added to its covariance and its std updated, {n_directions,
    std_inflation {name: new std / old std}})."""
    from dataclasses import replace

    import numpy as np

    free = np.asarray(result.free, bool)
    cov = np.asarray(result.covariance, float) + C
    std = np.array(result.std, float)
    old = std[free].copy()
    std[free] = np.sqrt(np.diag(cov))
    names = [n for n, f in zip(result.names, free) if f]
    return replace(result, covariance=cov, std=std), {
        "n_directions": n_directions,
        "std_inflation": {n: float(a / b) for n, a, b in zip(names, std[free], old) if b > 0}}
