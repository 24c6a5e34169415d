"""The H4's camera chain: its external parameters (camera on the base, target on the nacelle) and the camera
measurement T_cam_target of a pose X, with its Jacobians, and back from a measured T_cam_target to X and to the
joints (seed eq. 3). :class:`H4CameraChain` holds these methods of :class:`~.h4.H4Robot` (its base class; it
reads the robot's ``names``, ``R_BC0``, ``R_ME0``, ``tilt_params`` and the IGM of :mod:`.h4`). numpy only.

External parameters (seed §4.1)
-------------------------------
Camera on the base, target on the nacelle, target plane parallel to the nacelle:

    T_base_cam       = [Rz(B_T_C.theta) R_BC0, (B_T_C.x, B_T_C.y, B_T_C.z)]
    T_target_nacelle = [Rz(M_T_E.theta) R_ME0, (M_T_E.x, M_T_E.y, M_T_E.z)]   (seed's M_T_E)
    T_base_nacelle   = T_base_cam @ T_cam_target @ T_target_nacelle            (seed eq. 3)

R_BC0 and R_ME0 are fixed rotations (default Rx(pi): camera looking down, target facing up),
not identified: the camera tilt is measured beforehand from the rotation axis of the nacelle
seen by the camera (seed §4.1; vision_calib.identify.camera_axis.estimate_camera_axis, and
robot_with_camera_axis to set R_BC0 / R_ME0 from it), else taken from the scene file.
Measured pose -> X: (x, y, z) = translation of T_base_nacelle; theta = yaw of its rotation R,
theta = atan2(R10 - R01, R00 + R11), the angle of the z-rotation closest to R (Frobenius); it
equals theta exactly when R = Rz(theta), and ignores a small residual tilt from noise.
Only 7 of the 8 external parameters are identifiable: M_T_E.z (target offset along its normal)
acts exactly like B_T_C.z (seed eq. 24); it is fixed by default.

Tilt parameters (optional, ``tilt_params=True``, :func:`.h4_variants.with_tilt_params`): four more
angles (rad) after the externals, TILT_NAMES = B_T_C.tilt_x, B_T_C.tilt_y (camera tilt w about the
camera x / y axes) and M_T_E.tilt_x, M_T_E.tilt_y (target tilt u about the target x / y axes):

    R_BC = Rz(B_T_C.theta) R_BC0 so3_exp(w),   R_ME = so3_exp(u) Rz(M_T_E.theta) R_ME0

(the conventions of ``identify.camera_axis``: its tilt_cam_rad / tilt_target_rad are w and u).
The camera tilt moves every measured position (about the camera, ~0.65 m lever) and is identified
with the rest; the target tilt enters X only through the yaw, to second order (not identifiable
from the IGM residuals: it stays at the value measured from the rotation axis).
"""

from __future__ import annotations

import numpy as np

from ..errors import DataError
from ..frames import inv_T, make_T, rot_z, skew, so3_exp, so3_right_jacobian


def nacelle_T(X) -> np.ndarray:
    """T_base_nacelle (N, 4, 4) of poses X (N, 4)."""
    X = np.atleast_2d(np.asarray(X, float))
    return make_T(rot_z(X[:, 3]), X[:, :3])


def yaw_of(R) -> np.ndarray:
    """Angle (...,) rad of the z-rotation closest to R (..., 3, 3): atan2(R10 - R01, R00 + R11)."""
    R = np.asarray(R, float)
    return np.arctan2(R[..., 1, 0] - R[..., 0, 1], R[..., 0, 0] + R[..., 1, 1])


def _dyaw(R, dR):
    """Derivative of yaw_of at R (N,3,3) along dR (N,3,3) -> (N,)."""
    c = R[..., 0, 0] + R[..., 1, 1]
    s = R[..., 1, 0] - R[..., 0, 1]
    dc = dR[..., 0, 0] + dR[..., 1, 1]
    ds = dR[..., 1, 0] - dR[..., 0, 1]
    return (c * ds - s * dc) / (c * c + s * s)


class H4CameraChain:
    """The camera-chain methods of :class:`~.h4.H4Robot` (module doc): external parameters, camera measurement and
    its Jacobians, nacelle pose and joints from a measured T_cam_target."""

    def _ext(self, x):
        v = dict(zip(self.names, x))
        R_BC = rot_z(v["B_T_C.theta"]) @ self.R_BC0
        t_BC = np.array([v["B_T_C.x"], v["B_T_C.y"], v["B_T_C.z"]])
        R_ME = rot_z(v["M_T_E.theta"]) @ self.R_ME0
        t_ME = np.array([v["M_T_E.x"], v["M_T_E.y"], v["M_T_E.z"]])
        if self.tilt_params:
            w, u = self._tilts(v)
            R_BC, R_ME = R_BC @ so3_exp(w), so3_exp(u) @ R_ME
        return R_BC, t_BC, R_ME, t_ME

    @staticmethod
    def _tilts(v):
        """Camera tilt w (3,) and target tilt u (3,) rad (z components 0) from a name -> value dict."""
        return (np.array([v["B_T_C.tilt_x"], v["B_T_C.tilt_y"], 0.0]),
                np.array([v["M_T_E.tilt_x"], v["M_T_E.tilt_y"], 0.0]))

    def T_base_cam(self, x=None) -> np.ndarray:
        """(4, 4) pose of the camera in B."""
        R, t, _, _ = self._ext(self._x(x))
        return make_T(R, t)

    def T_target_nacelle(self, x=None) -> np.ndarray:
        """(4, 4) pose of the nacelle (effector) frame in the target frame (seed's M_T_E)."""
        _, _, R, t = self._ext(self._x(x))
        return make_T(R, t)

    def camera_measurement(self, X, x=None) -> np.ndarray:
        """Noise-free T_cam_target (N, 4, 4) for poses X (N, 4):
        inv(T_base_cam) @ T_base_nacelle(X) @ inv(T_target_nacelle)."""
        X = self._check_X(X)
        x = self._x(x)
        return inv_T(self.T_base_cam(x)) @ nacelle_T(X) @ inv_T(self.T_target_nacelle(x))

    def camera_measurement_jacobian(self, X, x=None):
        """Derivatives of :meth:`camera_measurement` as changes delta = [dt (m), drot (rad)] of T_cam_target in
        the :func:`frames.perturb_pose` convention (camera frame): (d delta / dX (N, 6, 4), d delta / dx
        (N, 6, n) at fixed X; only the external and tilt columns of the latter are non-zero)."""
        X, x = self._check_X(X), self._x(x)
        R_BC, t_BC, R_ME, t_ME = self._ext(x)
        ix = {nm: i for i, nm in enumerate(self.names)}
        N, n, ez = len(X), len(x), np.array([0.0, 0.0, 1.0])
        R_BT = rot_z(X[:, 3]) @ R_ME.T  # T_base_target = T_base_nacelle @ inv(T_target_nacelle)
        a = R_BT @ t_ME
        # base-frame changes (dt_B, w_B) of T_base_target (per pose component and target-mount parameter)
        JT = np.zeros((N, 6, 4 + n))
        JT[:, :3, :3] = np.eye(3)
        JT[:, :3, 3], JT[:, 3:, 3] = -np.cross(ez, a), ez
        u = self._tilts(dict(zip(self.names, x)))[1] if self.tilt_params else np.zeros(3)
        eta = {"M_T_E.theta": so3_exp(u) @ ez}  # target-frame rotation of T_target_nacelle per parameter
        if self.tilt_params:
            Ju = so3_right_jacobian(-u)
            eta.update({"M_T_E.tilt_x": Ju[:, 0], "M_T_E.tilt_y": Ju[:, 1]})
        for c, nm in enumerate("xyz"):
            JT[:, :3, 4 + ix[f"M_T_E.{nm}"]] = -R_BT[:, :, c]
        for nm, e in eta.items():
            w = -R_BT @ e
            JT[:, 3:, 4 + ix[nm]], JT[:, :3, 4 + ix[nm]] = w, -np.cross(w, a)
        # T_cam_target = inv(T_base_cam) T_base_target: a change of T_base_target maps by R_BC^T; a change
        # (dt_B, w_B) of T_base_cam gives drot = -R_BC^T w_B, dt = -R_BC^T (dt_B + w_B x (t_BT - t_BC))
        J = np.concatenate([R_BC.T @ JT[:, :3], R_BC.T @ JT[:, 3:]], 1)
        lever = X[:, :3] - a - t_BC
        cam = {f"B_T_C.{c}": (np.eye(3)[k], np.zeros(3)) for k, c in enumerate("xyz")}
        cam["B_T_C.theta"] = (np.zeros(3), ez)
        if self.tilt_params:
            Jw = R_BC @ so3_right_jacobian(self._tilts(dict(zip(self.names, x)))[0])
            cam.update({"B_T_C.tilt_x": (np.zeros(3), Jw[:, 0]), "B_T_C.tilt_y": (np.zeros(3), Jw[:, 1])})
        for nm, (dt, w) in cam.items():
            J[:, :3, 4 + ix[nm]] = -(dt + np.cross(w, lever)) @ R_BC
            J[:, 3:, 4 + ix[nm]] = -R_BC.T @ w
        return J[..., :4], J[..., 4:]

    @staticmethod
    def _check_T(T):
        T = np.asarray(T, float)
        if T.ndim == 2:
            T = T[None]
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise DataError(f"T_cam_target must have shape (N, 4, 4), got {T.shape}")
        bad = ~np.isfinite(T)
        if bad.any():
            raise DataError(f"T_cam_target {int(np.argwhere(bad)[0][0])} contains a non-finite value (NaN or inf)")
        return T

    def nacelle_pose_from_camera(self, T_cam_target, x=None):
        """Measured T_cam_target (N, 4, 4) -> (X (N, 4), dX/dx (N, 4, n)): X = (translation,
        yaw) of T_base_cam @ T_cam_target @ T_target_nacelle; only the 8 external columns of
        dX/dx are non-zero."""
        T = self._check_T(T_cam_target)
        x = self._x(x)
        R_BC, t_BC, R_ME, t_ME = self._ext(x)
        R_CM, t_CM = T[:, :3, :3], T[:, :3, 3]
        R_BM = R_BC @ R_CM
        v = t_CM + R_CM @ t_ME
        p = t_BC + v @ R_BC.T
        R = R_BM @ R_ME
        X = np.column_stack([p, yaw_of(R)])
        N = len(T)
        J = np.zeros((N, 4, len(x)))
        ix = {nm: i for i, nm in enumerate(self.names)}
        ez = np.array([0.0, 0.0, 1.0])
        for c, nm in enumerate("xyz"):
            J[:, c, ix[f"B_T_C.{nm}"]] = 1.0
            J[:, :3, ix[f"M_T_E.{nm}"]] = R_BM[:, :, c]
        J[:, :3, ix["B_T_C.theta"]] = np.cross(ez, p - t_BC)
        J[:, 3, ix["B_T_C.theta"]] = _dyaw(R, skew(ez) @ R)
        J[:, 3, ix["M_T_E.theta"]] = _dyaw(R, R @ self.R_ME0.T @ skew(ez) @ self.R_ME0)
        if self.tilt_params:
            w, u = self._tilts(dict(zip(self.names, x)))
            # exp(w + dw) = exp(w) exp(Jr(w) dw); exp(u + du) = exp(Jl(u) du) exp(u), Jl(u) = Jr(-u)
            Jw, Ju = so3_right_jacobian(w), so3_right_jacobian(-u)
            for k, c in enumerate("xy"):
                S = skew(Jw[:, k])
                J[:, :3, ix[f"B_T_C.tilt_{c}"]] = v @ (R_BC @ S).T
                J[:, 3, ix[f"B_T_C.tilt_{c}"]] = _dyaw(R, R_BC @ S @ R_CM @ R_ME)
                J[:, 3, ix[f"M_T_E.tilt_{c}"]] = _dyaw(R, R_BM @ skew(Ju[:, k]) @ R_ME)
        return X, J

    def nacelle_pose_jacobian_meas(self, T_cam_target, x=None) -> np.ndarray:
        """dX / d delta (N, 4, 6) where delta = [dt (m), drot (rad)] is a pose error of the
        measured T_cam_target in the :func:`frames.perturb_pose` convention (camera frame)."""
        T = self._check_T(T_cam_target)
        R_BC, t_BC, R_ME, t_ME = self._ext(self._x(x))
        R_CM = T[:, :3, :3]
        R = R_BC @ R_CM @ R_ME
        w = R_CM @ t_ME  # (N,3)
        N = len(T)
        J = np.zeros((N, 4, 6))
        J[:, :3, :3] = R_BC
        J[:, :3, 3:] = -R_BC @ skew(w)
        for k in range(3):
            J[:, 3, 3 + k] = _dyaw(R, skew(R_BC[:, k]) @ R)
        return J

    def igm_from_camera(self, T_cam_target, x=None) -> np.ndarray:
        """q (N, 4) rad predicted from measured T_cam_target (N, 4, 4) (seed eq. 3 then IGM)."""
        X, _ = self.nacelle_pose_from_camera(T_cam_target, x)
        return self.igm(X, x)

    def igm_from_camera_jacobian(self, T_cam_target, x=None, with_meas=False):
        """d q / d x (N, 4, n) of :meth:`igm_from_camera` (geometric + external columns); with
        with_meas=True also d q / d delta (N, 4, 6) wrt the measured-pose error."""
        x = self._x(x)
        X, JXe = self.nacelle_pose_from_camera(T_cam_target, x)
        s = self._solve(X, x)
        if not np.all(np.isfinite(s["q"])):
            self._raise_unreachable(X, s["q"], s["sq"])
        Jp = self._jac_pose(s)
        J = self._jac_params(s) + Jp @ JXe
        if with_meas:
            return J, Jp @ self.nacelle_pose_jacobian_meas(T_cam_target, x)
        return J
