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


def recording_intrinsics(rec, refine: bool = False, progress: bool = False, camera_file=None, detections=None):
    """(Recording with its camera set, report block). camera_file: a camera.yaml (``process --camera``)
    that replaces recording.yaml's intrinsics (size checked against the images; ConfigError naming it).
    The calibration uses the first frame of every pose
    (one view per pose; the other frames of a pose add noise averaging, not geometry). Report block:
    {source, values {fx, fy, cx, cy, k1, k2, p1, p2, k3}, std (None when given), rms_px, n_views_used,
    n_views_rejected, rejected_views [{name, reason}], coverage, warnings, given (recording.yaml's values
    when refined)}. DataError naming the folder when the calibration is impossible. detections: {pose id:
    [Detection per frame]} of these images measured with other intrinsics (``process.measure_recording``): the
    calibration takes their first frames instead of detecting again where that gives the same corners
    (``measure.batch.reusable_detections``)."""
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
        if rec.camera_file is not None:  # calibrate-camera's std (and covariance): carried as on the refine route
            block.update(_file_uncertainty(rec.camera_file))
        return rec, block
    pids = [pid for pid in rec.pose_ids if rec.images.get(pid)]
    try:
        res = calibrate_from_images([rec.images[p][0] for p in pids], rec.target, rec.image_size,
                                    names=[f"pose {p}" for p in pids], progress=progress,
                                    detected=_first_frames(detections, pids, rec.target))
    except DataError as exc:
        why = "recording.yaml has no camera fx/fy/cx/cy, and calibrating them" if rec.camera is None else \
            "refining recording.yaml's intrinsics"
        raise DataError(f"{rec.folder}: {why} from the images failed: {exc}") from None
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


def _first_frames(detections, pids, target) -> dict | None:
    """{index in pids: the pose's first-frame Detection} when those are what the calibration would detect, or
    carry the edge samples it refits (AprilTag grids: ``measure.batch.refit_detection``), else None."""
    from ..measure.batch import refittable, reusable_detections
    from ..measure.detect import DetectConfig
    from ..measure.intrinsics import CALIBRATION_DETECT

    if not detections:
        return None
    first = {i: detections[p][0] for i, p in enumerate(pids) if detections.get(p)}
    if refittable(first.values()):
        return first
    if replace(DetectConfig(), batch="per_frame") != DetectConfig(**CALIBRATION_DETECT) \
            or not reusable_detections(target):
        return None
    return first


def _file_uncertainty(path) -> dict:
    """{std, covariance, warnings} of a camera file's intrinsics (``io.camera_file.load_camera_uncertainty``):
    its covariance, or diag(std^2) with a warning when it gives std only; {} when it gives none."""
    import numpy as np

    from ..io.camera_file import load_camera_uncertainty

    std, cov = load_camera_uncertainty(path)
    if std is None:
        return {}
    warn = []
    if cov is None:
        cov = np.diag(np.square([std[k] for k in PARAM_NAMES]))
        warn = [f"camera intrinsics: {path} gives std without a covariance: their correlations are taken as zero"]
    return {"std": std, "covariance": np.asarray(cov, float).tolist(), "warnings": warn}


def intrinsics_directions(block: dict, camera):
    """[(CameraIntrinsics moved by one std along an eigenvector of the intrinsics covariance)] for a report
    block whose intrinsics carry a ``covariance`` (9, 9) of PARAM_NAMES (calibrated from the recording, or a
    camera file's), else []."""
    import numpy as np

    from ..camera import CameraIntrinsics

    cov = block.get("covariance")
    if cov is None:
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


def remeasure(dets: dict, labels, target, camera, config, original: dict | None = None,
              prepared: dict | None = None):
    """(N, 4, 4) T_cam_target of the poses ``labels`` re-measured from their detections with ``camera``
    (undistortion + PnP only; no detection; config: measure.MeasureConfig, the recording's
    ``Recording.measure_config()``); None when one of them is no longer valid. original: {label:
    PoseMeasurement} of these detections: each pose keeps its frames and corners (``measure_pose(selection=)``,
    the derivative of the measurement, not of its data association); None: the view rule is run again.
    prepared: a dict kept by the caller over its cameras (filled here, {label: ``measure.remeasure.Remeasurable``
    or None}): with ``original``, each pose's corners are gathered once and the poses re-measured together by
    ``measure.remeasure.remeasure_many`` (the same poses; ``measure_pose`` where it declines)."""
    import numpy as np

    from ..measure import measure_pose
    from ..measure.remeasure import remeasurable, remeasure_many

    light = {}  # label -> T of the light path (all the prepared poses at once)
    if original is not None and prepared is not None:
        for lab in labels:
            pm0 = original.get(str(lab))
            if pm0 is not None and str(lab) not in prepared:
                prepared[str(lab)] = remeasurable(dets[lab], target, pm0, config)
        labs = [str(lab) for lab in labels if prepared.get(str(lab)) is not None]
        light = dict(zip(labs, remeasure_many([prepared[lab] for lab in labs], camera)))
    T = []
    for lab in labels:
        if light.get(str(lab)) is not None:
            T.append(light[str(lab)])
            continue
        pm0 = None if original is None else original.get(str(lab))
        sel = None if pm0 is None else pm0.frames
        pm = measure_pose(dets[lab], target, camera, pose_id=lab, config=config, covariance=False, selection=sel)
        if not pm.valid:
            return None
        T.append(pm.T_cam_target)
    return np.array(T)


def fitted_camera(camera, directions, coefficients):
    """The camera the fit ended at: ``camera`` (CameraIntrinsics calibrated from the recording, theta) moved by
    the fitted nuisance coefficients c (d,) (prior std units) along the d directions the fit used
    (``directions``: the cameras theta_k one std away, as :func:`residual_response` kept them). The fit reads
    the poses measured with theta as carrying the shared error U c (residual r - U c, U_k the residual change
    from theta to theta_k), so the poses of the identified chain are, to first order, those measured with
    theta - sum_k c_k (theta_k - theta): the camera returned."""
    import numpy as np

    from ..camera import CameraIntrinsics

    def vec(c):
        return np.array([c.fx, c.fy, c.cx, c.cy, *c.dist], float)

    c = np.asarray(coefficients, float)
    if len(directions) != c.size:
        raise DataError(f"fitted_camera: {c.size} coefficients for {len(directions)} directions")
    t0 = vec(camera)
    t = t0 - sum((ck * (vec(d) - t0) for ck, d in zip(c, directions)), np.zeros_like(t0))
    return CameraIntrinsics(camera.width, camera.height, *t[:4], tuple(float(v) for v in t[4:]))


def intrinsics_response(dets: dict, rec, block: dict, used: list | None = None, original: dict | None = None):
    """For intrinsics calibrated from the same recording (``block``): a callable (setup, meas, problem, x) ->
    U (n_obs, m, d), the change of every pose's residual (measured - model, SI; the residual kind of the
    problem given) at x (n,) when the camera
    moves one std along each eigen-direction of their covariance (``intrinsics_directions``; poses
    re-measured from their detections, ``remeasure``), for ``steps.identify_measurements(nuisance=)``: their
    error is shared by all poses, so it enters the fit as nuisance coefficients (the measurement covariance
    becomes obs_cov + U U^T; first order, independent of the pose noise). A direction under which a pose is
    no longer measurable is left out (None when all are). None when the intrinsics carry no covariance. used: a list
    that each call refills with the directions (cameras) of U's columns (for :func:`fitted_camera`). original: {label:
    PoseMeasurement}: the corner selection each re-measurement keeps (:func:`remeasure`)."""
    import numpy as np

    dirs = intrinsics_directions(block, rec.camera)
    if not dirs or not dets:
        return None

    def response(setup, meas, problem, x):
        labels = list(problem.labels)
        sub = meas.select(labels)
        return residual_response(dirs, dets, labels, rec, x, np.asarray(problem.residual(x), float),
                                 lambda T: setup.problem(replace(sub, T_cam_target=T),
                                                         problem.residual_kind, params=problem.params), used,
                                 original)

    return response


def residual_response(dirs, dets: dict, labels, rec, x, r0, problem_for, used: list | None = None,
                      original: dict | None = None):
    """U (n_obs, m, d): for each camera of ``dirs`` (``intrinsics_directions``) the change of the residual at x
    (n,) from r0 (n_obs, m) when the poses ``labels`` are re-measured from their detections with that camera
    (``remeasure``) and put into ``problem_for(T (n_obs, 4, 4))``; a direction under which a pose is no
    longer measurable is left out; None when all are. used: a list refilled with the cameras of U's columns.
    original: {label: PoseMeasurement}, the corner selection each re-measurement keeps (:func:`remeasure`)."""
    import numpy as np

    cols, prepared = [], {}
    if used is not None:
        used.clear()
    for cam in dirs:
        T = remeasure(dets, labels, rec.target, cam, rec.measure_config(), original, prepared)
        if T is not None:
            cols.append(np.asarray(problem_for(T).residual(x), float) - r0)
            if used is not None:
                used.append(cam)
    return np.stack(cols, axis=2) if cols else None


#: intrinsics whose 1 px change :func:`intrinsics_sensitivity` propagates ("f": fx and fy together, a focal
#: length error; fx alone also changes the aspect ratio, which the poses' rotations show)
SENSITIVITY_PX = ("f", "fx", "fy", "cx", "cy")
#: intrinsics given without uncertainty are warned about when 1 px of focal length moves a parameter by more
#: than this many of its std (the std then ignore an error the data cannot show: the parameters absorb it)
SENSITIVITY_WARN_STD = 1.0


def shifted_camera(camera, name: str, px: float = 1.0):
    """``camera`` (CameraIntrinsics) with intrinsic ``name`` (fx, fy, cx or cy; "f": fx and fy) moved by ``px``
    pixels."""
    if name == "f":
        return replace(camera, fx=camera.fx + px, fy=camera.fy + px)
    return replace(camera, **{name: getattr(camera, name) + px})


def projected_remeasure(target, camera, T_cam_target: dict):
    """A ``remeasure_with(camera', labels) -> (N, 4, 4)`` for data without detections (simulation): the target's
    corners projected at each measured pose {label: T_cam_target (4, 4)} with ``camera`` (distortion included),
    then undistorted and solved by PnP with camera'; the change from the same PnP with ``camera`` is applied to
    the measured pose (noise-free first-order response of the measurement to the intrinsics)."""
    import cv2
    import numpy as np

    from ..frames import inv_T, rvec_tvec_from_T
    from ..measure.pnp import solve_pnp_planar, undistort_px

    _, p = target.corner_points()
    p = np.asarray(p, float)

    def pnp(uv, cam):
        return solve_pnp_planar(p[uv[1]], undistort_px(uv[0][uv[1]], cam), cam)[0]

    def project(T):
        rvec, tvec = rvec_tvec_from_T(T)
        uv = cv2.projectPoints(p.reshape(-1, 1, 3), rvec, tvec, camera.K, camera.dist_array)[0].reshape(-1, 2)
        z = p @ T[:3, :3].T[:, 2] + T[2, 3]
        ok = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] < camera.width) & (uv[:, 1] < camera.height)
        return uv, ok

    base = {}  # label -> (projected corners, inv(PnP with ``camera``) @ T): the same for every shifted camera

    def remeasure_with(cam, labels):
        out = []
        for lab in labels:
            if lab not in base:
                T = np.asarray(T_cam_target[lab], float)
                uv = project(T)
                base[lab] = (uv, inv_T(pnp(uv, camera)) @ T if uv[1].sum() >= 4 else None)
            uv, rest = base[lab]
            if rest is None:
                return None
            out.append(pnp(uv, cam) @ rest)
        return np.array(out)

    return remeasure_with


def intrinsics_sensitivity(ident, meas, camera, remeasure_with, given_std: bool | None, px: float = 1.0) -> dict:
    """How far 1 px of each of f (fx and fy together), fx, fy, cx, cy moves every identified parameter, in units
    of its reported std (first order: the kept poses re-measured with the shifted camera by ``remeasure_with(camera', labels) ->
    T (N, 4, 4)`` or None, their residual change at the solution propagated by
    ``identify.lack_of_fit.parameter_shift``; the setup and free set of the fit stay). ident:
    ``steps.Identified``; meas: the Measurements it was fitted on (labels pick the kept poses); camera: the
    intrinsics used; given_std: whether the intrinsics carry an uncertainty (False: a warning names the largest
    focal-length effect when it exceeds SENSITIVITY_WARN_STD std; None: exact intrinsics, a simulation).

    Returns {px, std_per_px {intrinsic: {parameter: shift / std}}, shift_per_px {intrinsic: {parameter: SI
    shift}}, largest {intrinsic: {parameter, std_per_px}}, intrinsics_std_given, warning (or None)}."""
    import numpy as np

    from ..identify.lack_of_fit import parameter_shift

    problem, result, setup = ident.problem, ident.result, ident.setup
    labels = list(problem.labels)
    sub = meas.select(labels)
    x = np.asarray(result.identified, float)
    r0 = np.asarray(problem.residual(x), float)
    names, dR = [], []
    for nm in SENSITIVITY_PX:
        T = remeasure_with(shifted_camera(camera, nm, px), labels)
        if T is None:
            continue
        moved = replace(sub, T_cam_target=T)
        dR.append(np.asarray(setup.problem(moved, problem.residual_kind, params=problem.params).residual(x)) - r0)
        names.append(nm)
    out = {"px": float(px), "std_per_px": {}, "shift_per_px": {}, "largest": {}, "intrinsics_std_given": given_std,
           "warning": None, "how": "first order: poses re-measured with the intrinsic moved by px, the residual change "
                                   "propagated through the fit's whitened Jacobian (setup and free set fixed)"}
    if not names:
        out["warning"] = "intrinsics sensitivity not computed: no pose re-measurable with shifted intrinsics"
        return out
    shift = parameter_shift(problem, result, np.stack(dR, axis=2)) / px
    free = np.flatnonzero(result.free)
    std = np.asarray(result.std, float)
    for j, nm in enumerate(names):
        z = {result.names[i]: float(shift[i, j] / std[i]) for i in free if std[i] > 0}
        out["std_per_px"][nm] = z
        out["shift_per_px"][nm] = {result.names[i]: float(shift[i, j]) for i in free}
        if z:
            k = max(z, key=lambda n: abs(z[n]))
            out["largest"][nm] = {"parameter": k, "std_per_px": z[k]}
    focal = [(abs(v["std_per_px"]), nm, v["parameter"]) for nm, v in out["largest"].items() if nm in ("f", "fx", "fy")]
    if focal and given_std is False:
        big, nm, par = max(focal)
        if big * px > SENSITIVITY_WARN_STD:
            what = "fx and fy" if nm == "f" else nm
            out["warning"] = (f"intrinsics given without uncertainty: a {px:g} px focal error ({what}) would "
                              f"move {par} by {big * px:.3g} std, which the reported std ignore; give the intrinsics' "
                              "std or calibrate them from the recording (process --refine-intrinsics)")
    return out
