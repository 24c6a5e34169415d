"""Toy robot kind shipped by a plugin package: the tip of a planar 2R arm seen by a fixed camera."""

from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from vision_calib import frames as F
from vision_calib.config import load_yaml
from vision_calib.identify.problem import IdentificationProblem
from vision_calib.kinematics.params import ParameterSet
from vision_calib.rig import Evaluation, Setup

NAMES = ("L1", "L2", "q0_1", "q0_2", "T_cam_base.tx", "T_cam_base.ty", "T_cam_base.tz")
KINDS = ("length", "length", "angle", "angle", "length", "length", "length")
R_CAM_BASE = F.T_from_xyz_rpy(np.zeros(3), np.array([np.pi, 0.0, 0.0]))[:3, :3]  # camera looking down


@dataclass(frozen=True)
class PlanarArm:
    """The toy robot: tip of a planar 2R arm seen by a fixed camera 1 m above its base."""

    params: ParameterSet

    def tip_base(self, q, x):
        """(N, 3) tip position in the base frame and (N,) tip angle for joints q (N, 2) rad."""
        L1, L2, o1, o2 = x[:4]
        a1, a2 = q[:, 0] + o1, q[:, 0] + q[:, 1] + o1 + o2
        p = np.stack([L1 * np.cos(a1) + L2 * np.cos(a2), L1 * np.sin(a1) + L2 * np.sin(a2), 0 * a1], axis=1)
        return p, a2

    def T_cam_tip(self, q, x):
        p, a2 = self.tip_base(np.asarray(q, float), x)
        T = np.tile(np.eye(4), (len(p), 1, 1))
        T[:, :3, :3] = R_CAM_BASE @ np.array([F.T_from_xyz_rpy(np.zeros(3), np.array([0, 0, a]))[:3, :3] for a in a2])
        T[:, :3, 3] = x[4:7] + p @ R_CAM_BASE.T
        return T


@dataclass(frozen=True)
class Planar2Setup(Setup):
    robot: PlanarArm = None

    kind: ClassVar[str] = "plugin_planar2"
    mounts: ClassVar[tuple] = ("fixed",)
    residuals: ClassVar[tuple] = ("position",)
    methods: ClassVar[tuple] = ("lse", "ekf")

    @property
    def n_joints(self):
        return 2

    def T_cam_target(self, poses, x):
        return self.robot.T_cam_tip(poses, x)

    def joints(self, poses, x):
        return np.asarray(poses, float).copy()

    def problem(self, meas, residual=None, params=None):
        self.check_residual(residual)
        q, p_meas = np.asarray(meas.joints), meas.T_cam_target[:, :3, 3]
        robot = self.robot

        def residual_fn(x, idx=None):
            i = slice(None) if idx is None else np.asarray(idx, int)
            return p_meas[i] - robot.T_cam_tip(q[i], x)[:, :3, 3]

        def jacobian_fn(x, idx=None):
            qi = q[slice(None) if idx is None else np.asarray(idx, int)]
            L1, L2, o1, o2 = x[:4]
            a1, a2 = qi[:, 0] + o1, qi[:, 0] + qi[:, 1] + o1 + o2
            d = np.zeros((len(qi), 3, 7))  # d model (base frame) / d x, then rotated into the camera frame
            d[:, :2, 0] = np.stack([np.cos(a1), np.sin(a1)], 1)
            d[:, :2, 1] = np.stack([np.cos(a2), np.sin(a2)], 1)
            d[:, :2, 3] = L2 * np.stack([-np.sin(a2), np.cos(a2)], 1)
            d[:, :2, 2] = L1 * np.stack([-np.sin(a1), np.cos(a1)], 1) + d[:, :2, 3]
            J = np.einsum("ij,kjn->kin", R_CAM_BASE, d)
            J[:, :, 4:7] = np.eye(3)
            return -J

        return IdentificationProblem(params or self.params, residual_fn, jacobian_fn, meas.cov[:, :3, :3], "position",
                                     labels=meas.labels)

    def evaluate(self, x, x_true, validation, measurements=None, truth=None):
        p_true, _ = (truth or self).robot.tip_base(validation, x_true)
        p, _ = self.robot.tip_base(validation, x)
        err = np.zeros((len(p), 6))
        err[:, :3] = p - p_true
        return Evaluation(p_true, err)

    def sample_poses(self, rng, n, check_view=True):
        return rng.uniform(-1.5, 1.5, size=(n, 2))

    def model_dict(self):
        return {}

    def with_params(self, params):
        return replace(self, params=params, robot=replace(self.robot, params=params))

    @classmethod
    def claims(cls, robot_path, doc):
        return doc is not None and doc.get("kind") == cls.kind

    @classmethod
    def from_scene(cls, ctx):
        doc = load_yaml(ctx.robot_path)
        ps = ParameterSet.from_lists(NAMES, [doc["L1"], doc["L2"], 0, 0, 0, 0, 1.0], KINDS,
                                     scale=[1e-3, 1e-3, 1e-3, 1e-3, 1e-3, 1e-3, 1e-3])
        ps = ctx.apply_free(ps)
        return cls(ctx.name, ps, ctx.camera, ctx.mount, {"robot_path": str(ctx.robot_path)}, robot=PlanarArm(ps))

    @staticmethod
    def load_model(doc, robot_path):
        d = load_yaml(robot_path)
        return PlanarArm(ParameterSet.from_lists(NAMES, [d["L1"], d["L2"], 0, 0, 0, 0, 1.0], KINDS))
