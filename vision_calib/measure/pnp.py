"""Undistortion, planar PnP, reprojection Jacobian, pose covariance and Cramér–Rao bound.

Pose perturbations use the ``frames.pose_error`` convention on T_cam_target: a 6-vector
``delta = [dt (m), dtheta (rad)]`` acts as ``frames.perturb_pose(T_cam_target, delta)``, i.e.
``p_cam' = dR(dtheta) R p_target + t + dt`` (rotation about the camera origin, in camera axes).
"""

from __future__ import annotations

import cv2
import numpy as np

from .. import frames
from ..camera import CameraIntrinsics

_UNDIST_CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)


def undistort_px(uv_px: np.ndarray, intr: CameraIntrinsics) -> np.ndarray:
    """Distorted pixels (K, 2) -> ideal pinhole pixels (K, 2) with the same K (P = K), iterative."""
    uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 1, 2)
    if len(uv) == 0 or not any(intr.dist):
        return uv.reshape(-1, 2).copy()
    K = intr.K
    return cv2.undistortPointsIter(uv, K, intr.dist_array, None, K, _UNDIST_CRIT).reshape(-1, 2)


def target_lookup(target) -> dict[int, np.ndarray]:
    """{corner id: p_target (3,) m} from ``target.corner_points()``."""
    ids, p = target.corner_points()
    return {int(i): np.asarray(q, dtype=float) for i, q in zip(ids, p)}


def pinhole(pc: np.ndarray, intr: CameraIntrinsics, z: np.ndarray | None = None, derivative: bool = False):
    """Ideal (undistorted) pixels uv (..., 2) of camera-frame points pc (..., 3) m; z (...): the depths divided by
    (default pc's own, e.g. 1 where a padded point has none). With ``derivative``, (uv, d uv / d pc (..., 2, 3))."""
    x, y = pc[..., 0], pc[..., 1]
    z = pc[..., 2] if z is None else z
    uv = np.stack([intr.fx * x / z + intr.cx, intr.fy * y / z + intr.cy], axis=-1)
    if not derivative:
        return uv
    d = np.zeros(pc.shape[:-1] + (2, 3))
    d[..., 0, 0] = intr.fx / z
    d[..., 0, 2] = -intr.fx * x / z**2
    d[..., 1, 1] = intr.fy / z
    d[..., 1, 2] = -intr.fy * y / z**2
    return uv, d


def project_pinhole(T_cam_target: np.ndarray, p_target: np.ndarray, intr: CameraIntrinsics) -> np.ndarray:
    """Ideal (undistorted) projection of target points (K, 3) m -> (K, 2) px."""
    return pinhole(frames.transform_points(T_cam_target, p_target), intr)


def reprojection_jacobian(T_cam_target: np.ndarray, p_target: np.ndarray, intr: CameraIntrinsics) -> np.ndarray:
    """d(uv_px)/d(delta) (2K, 6) of the ideal pinhole projection, rows (u0, v0, u1, v1, ...),
    delta = [dt (m), dtheta (rad)] applied by ``frames.perturb_pose`` to T_cam_target."""
    p_target = np.asarray(p_target, dtype=float)
    q = p_target @ T_cam_target[:3, :3].T  # R p, (K, 3)
    pc = q + T_cam_target[:3, 3]
    K = len(pc)
    dproj = pinhole(pc, intr, derivative=True)[1]
    dpc = np.concatenate([np.broadcast_to(np.eye(3), (K, 3, 3)), -frames.skew(q)], axis=2)  # (K, 3, 6)
    return np.einsum("kij,kjl->kil", dproj, dpc).reshape(2 * K, 6)


def solve_pnp_planar(p_target: np.ndarray, uv_undist_px: np.ndarray, intr: CameraIntrinsics,
                     method: str = "ippe") -> tuple[np.ndarray, np.ndarray]:
    """Pose of a planar target from >= 4 correspondences: IPPE (or SQPnP) then Levenberg–Marquardt
    (cv2.solvePnPRefineLM) on ideal pixels (no distortion).

    p_target: (K, 3) m; uv_undist_px: (K, 2) undistorted px. Returns (T_cam_target (4, 4),
    residuals (K, 2) px = observed - projected). Raises cv2.error / ValueError on failure
    (callers turn that into a rejection)."""
    obj = np.ascontiguousarray(p_target, dtype=np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(uv_undist_px, dtype=np.float64).reshape(-1, 1, 2)
    K = intr.K
    zero = np.zeros(5)
    flag = {"ippe": cv2.SOLVEPNP_IPPE, "sqpnp": cv2.SOLVEPNP_SQPNP}[method]
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(obj, img, K, zero, flags=flag)
    if n == 0:
        raise ValueError("solvePnP found no solution")
    best = int(np.argmin(np.asarray(errs).ravel())) if errs is not None and len(errs) else 0
    return _refined(obj, img, intr, rvecs[best].copy(), tvecs[best].copy(), p_target, uv_undist_px)


def refine_pnp_planar(p_target: np.ndarray, uv_undist_px: np.ndarray, intr: CameraIntrinsics,
                      T_start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`solve_pnp_planar`'s Levenberg-Marquardt alone, from T_start (4, 4) T_cam_target (e.g. the pose measured
    under nearby intrinsics: the same minimum, no IPPE). Same arguments, returns and errors."""
    obj = np.ascontiguousarray(p_target, dtype=np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(uv_undist_px, dtype=np.float64).reshape(-1, 1, 2)
    T_start = np.asarray(T_start, float)
    rvec = frames.rotvec_from_matrix(T_start[:3, :3]).reshape(3, 1)
    return _refined(obj, img, intr, rvec, T_start[:3, 3].reshape(3, 1).copy(), p_target, uv_undist_px)


#: :func:`refine_pnp_many` stops when no pose moves by more than this (m and rad) in a Gauss-Newton step
GN_PNP_TOL = 1e-13


def refine_pnp_many(p_target: np.ndarray, uv_undist_px: np.ndarray, weight: np.ndarray, intr: CameraIntrinsics,
                    T_start: np.ndarray, max_iter: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """The minimum of :func:`refine_pnp_planar`'s cost (sum of squared reprojection errors, ideal pinhole) for P
    poses at once by undamped Gauss-Newton steps from nearby starts: p_target (P, C, 3) m, uv_undist_px (P, C, 2)
    px, weight (P, C) 1 for a corner, 0 for padding; T_start (P, 4, 4). Steps in the ``frames.perturb_pose``
    convention (:func:`reprojection_jacobian`) until none moves by more than :data:`GN_PNP_TOL`. Returns
    (T (P, 4, 4), settled (P,) bool: False where a step was singular or not finite, a point came behind the
    camera, or the steps did not settle: the caller refines that pose with :func:`refine_pnp_planar`)."""
    P = np.asarray(p_target, float)
    uv = np.asarray(uv_undist_px, float)
    w = np.asarray(weight, float)[..., None]  # (P, C, 1)
    T = np.array(T_start, float)
    n = T.shape[0]
    active, settled = np.ones(n, bool), np.zeros(n, bool)
    for _ in range(max_iter):
        a = np.flatnonzero(active)
        if not a.size:
            break
        q = P[a] @ np.swapaxes(T[a, :3, :3], 1, 2)  # R p (k, C, 3)
        pc = q + T[a, None, :3, 3]
        z = pc[..., 2]
        proj, dproj = pinhole(pc, intr, np.where(w[a, :, 0] > 0, z, 1.0), derivative=True)
        r = (uv[a] - proj) * w[a]
        J = np.concatenate([dproj, -(dproj @ frames.skew(q))], axis=-1) * w[a][..., None]  # (k, C, 2, 6)
        J = J.reshape(a.size, -1, 6)
        A = np.swapaxes(J, 1, 2) @ J
        g = (np.swapaxes(J, 1, 2) @ r.reshape(a.size, -1, 1))[..., 0]
        bad = ~np.all(np.isfinite(A), axis=(1, 2)) | ~np.all(np.isfinite(g), axis=1) | np.any(
            (z <= 0) & (w[a, :, 0] > 0), axis=1)
        d = np.zeros((a.size, 6))
        try:
            d[~bad] = np.linalg.solve(A[~bad], g[~bad][..., None])[..., 0]
        except np.linalg.LinAlgError:
            bad[:] = True  # one singular: every pose of this step to the caller's refinement
        T[a[~bad]] = frames.perturb_pose(T[a[~bad]], d[~bad])
        done = ~bad & (np.max(np.abs(d), axis=1) <= GN_PNP_TOL)
        settled[a[done]] = True
        active[a[done | bad]] = False
    return T, settled


def _refined(obj, img, intr, rvec, tvec, p_target, uv_undist_px):
    """(T, residuals (K, 2) px) after cv2.solvePnPRefineLM from (rvec, tvec) (3, 1) (tolerance 1e-12, 50 steps)."""
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, intr.K, np.zeros(5), rvec, tvec,
                                      (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-12))
    T = frames.T_from_rvec_tvec(rvec.ravel(), tvec.ravel())
    if not np.all(np.isfinite(T)) or T[2, 3] <= 0:
        raise ValueError("PnP solution behind the camera or not finite")
    res = uv_undist_px - project_pinhole(T, p_target, intr)
    return T, res


def pose_cov_from_jacobian(J: np.ndarray, sigma_px: float, weights: np.ndarray | None = None) -> np.ndarray:
    """sigma^2 (J^T W J)^-1 (6, 6). J: (2K, 6); weights: (K,) observations per corner (or None)."""
    if weights is not None:
        w = np.repeat(np.asarray(weights, dtype=float), 2)
        JtJ = J.T @ (J * w[:, None])
    else:
        JtJ = J.T @ J
    return sigma_px**2 * np.linalg.pinv(JtJ)


def crlb_pose_cov(target, intrinsics: CameraIntrinsics, T_cam_target: np.ndarray, sigma_px: float,
                  n_frames: int = 1) -> np.ndarray:
    """Cramér–Rao bound (6, 6) on T_cam_target in the pose_error convention, for i.i.d. Gaussian
    corner noise of std ``sigma_px`` (per coordinate, ideal pixel space) on every target corner in
    front of the camera and inside the image, averaged over ``n_frames`` independent frames."""
    _, p = target.corner_points()
    p = np.asarray(p, dtype=float)
    pc = frames.transform_points(T_cam_target, p)
    uv = project_pinhole(T_cam_target, p, intrinsics)
    inside = (pc[:, 2] > 0) & (uv[:, 0] >= -0.5) & (uv[:, 0] <= intrinsics.width - 0.5) \
        & (uv[:, 1] >= -0.5) & (uv[:, 1] <= intrinsics.height - 0.5)
    J = reprojection_jacobian(T_cam_target, p[inside], intrinsics)
    return pose_cov_from_jacobian(J, sigma_px) / n_frames


def pose_bound_from_corner_info(J: np.ndarray, info_blocks: np.ndarray, n_frames: int = 1) -> np.ndarray:
    """Cramér–Rao bound (6, 6) of the pose from independent corners with Fisher information blocks
    info_blocks (K, 2, 2) [1/px^2] each, J (2K, 6) the reprojection Jacobian, n_frames independent
    frames: (n_frames sum_k J_k^T F_k J_k)^-1."""
    Jr = J.reshape(-1, 2, 6)
    info = np.einsum("kai,kab,kbj->ij", Jr, info_blocks, Jr)
    return np.linalg.pinv(info * n_frames)


def corner_edge_normals(T_cam_target: np.ndarray, p_target: np.ndarray, intr: CameraIntrinsics):
    """Unit image normals (K, 2, 2) of the two target edges through each corner (the images of the
    target x and y axes at p_target (K, 3)) and the image length (K, 2) px of a unit target length
    along each axis."""
    pc = frames.transform_points(T_cam_target, p_target)
    x, y, z = pc[:, 0], pc[:, 1], pc[:, 2]
    dproj = np.zeros((len(pc), 2, 3))
    dproj[:, 0, 0] = intr.fx / z
    dproj[:, 0, 2] = -intr.fx * x / z**2
    dproj[:, 1, 1] = intr.fy / z
    dproj[:, 1, 2] = -intr.fy * y / z**2
    d = np.einsum("kij,jl->kli", dproj, T_cam_target[:3, :2])  # (K, axis, 2) image direction per metre
    scale = np.linalg.norm(d, axis=2)
    t = d / scale[..., None]
    normals = np.stack([-t[..., 1], t[..., 0]], axis=2)
    return normals, scale
