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


def remeasure(dets: dict, labels, target, camera, config):
    """(N, 4, 4) T_cam_target of the poses ``labels`` re-measured from their detections with ``camera``
    (undistortion + PnP only; no detection; config: measure.MeasureConfig, the recording's
    ``Recording.measure_config()``); None when one of them is no longer valid."""
    import numpy as np

    from ..measure import measure_pose

    T = []
    for lab in labels:
        pm = measure_pose(dets[lab], target, camera, pose_id=lab, config=config)
        if not pm.valid:
            return None
        T.append(pm.T_cam_target)
    return np.array(T)


def intrinsics_response(dets: dict, rec, block: dict):
    """For intrinsics calibrated from the same recording (``block``): a callable (setup, meas, problem, x) ->
    U (n_obs, m, d), the change of every pose's residual (measured - model, SI; the residual kind of the
    problem given) at x (n,) when the camera
    moves one std along each eigen-direction of their covariance (``intrinsics_directions``; poses
    re-measured from their detections, ``remeasure``), for ``steps.identify_measurements(nuisance=)``: their
    error is shared by all poses, so it enters the fit as nuisance coefficients (the measurement covariance
    becomes obs_cov + U U^T; first order, independent of the pose noise). A direction under which a pose is
    no longer measurable is left out (None when all are). None when the intrinsics were given."""
    import numpy as np

    dirs = intrinsics_directions(block, rec.camera)
    if not dirs or not dets:
        return None

    def response(setup, meas, problem, x):
        labels = list(problem.labels)
        pos = {lab: k for k, lab in enumerate(meas.labels)}
        sub = meas.subset([pos[lab] for lab in labels])
        return residual_response(dirs, dets, labels, rec, x, np.asarray(problem.residual(x), float),
                                 lambda T: setup.problem(type(sub)(sub.poses, sub.joints, T, sub.cov, sub.labels),
                                                         problem.residual_kind, params=problem.params))

    return response


def residual_response(dirs, dets: dict, labels, rec, x, r0, problem_for):
    """U (n_obs, m, d): for each camera of ``dirs`` (``intrinsics_directions``) the change of the residual at x
    (n,) from r0 (n_obs, m) when the poses ``labels`` are re-measured from their detections with that camera
    (``remeasure``) and put into ``problem_for(T (n_obs, 4, 4))``; a direction under which a pose is no
    longer measurable is left out; None when all are."""
    import numpy as np

    cols = []
    for cam in dirs:
        T = remeasure(dets, labels, rec.target, cam, rec.measure_config())
        if T is not None:
            cols.append(np.asarray(problem_for(T).residual(x), float) - r0)
    return np.stack(cols, axis=2) if cols else None
