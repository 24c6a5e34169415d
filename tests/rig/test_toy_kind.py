"""A new robot kind is a one-place change: a 2-link planar arm defined HERE (no package module
edited), registered through ``rig.register``, runs ``identify-synthetic`` end to end from a scene file,
recovers its true parameters within the predicted std, and round-trips its calibrated-model file."""

import json
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
import pytest

from vision_calib import frames as F
from vision_calib.cli import main
from vision_calib.config import load_yaml
from vision_calib.identify.problem import IdentificationProblem
from vision_calib.io.model_export import load_calibrated_model, write_calibrated_model
from vision_calib.kinematics.params import ParameterSet
from vision_calib.rig import Evaluation, Setup, load_scene, register, unregister

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

    kind: ClassVar[str] = "planar2"
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

    @staticmethod
    def claims(robot_path, doc):
        return doc is not None and doc.get("kind") == "planar2"

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


@pytest.fixture
def toy_scene(tmp_path):
    register(Planar2Setup)
    (tmp_path / "arm.yaml").write_text("kind: planar2\nL1: 0.4\nL2: 0.3\n")
    (tmp_path / "scene.yaml").write_text(
        "name: toy\nrobot: arm.yaml\nmount: fixed\n"
        "truth: {seed: 3, sigma_length_mm: 2.0, sigma_angle_deg: 0.3}\n"
        "poses: {kind: random, count: 40}\nvalidation: {kind: random, count: 20}\n"
        "measurement: {sigma_mm: 0.05, sigma_deg: 0.01}\n")
    yield tmp_path / "scene.yaml"
    unregister("planar2")


def test_toy_kind_runs_identify_synthetic_end_to_end(toy_scene, capsys):
    assert load_scene(toy_scene).kind == "planar2"
    assert main(["identify-synthetic", str(toy_scene), "--json", "--seed", "5"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["converged"] and out["residual"] == "position" and out["method"] == "lse"
    z = [(p["identified"] - p["true"]) / p["std"] for p in out["parameters"] if p["free"]]
    assert len(z) == 7 and np.max(np.abs(z)) < 4, z
    moved = [abs(p["true"] - p["nominal"]) for p in out["parameters"]]
    assert max(moved) > 10 * max(p["std"] for p in out["parameters"])  # the truth is not the nominal
    a, b = out["accuracy"]["after"], out["accuracy"]["before"]
    assert a["position_rms_mm"] < 0.2 * b["position_rms_mm"]


def test_toy_kind_analytic_jacobian_and_model_file(toy_scene, tmp_path):
    setup = load_scene(toy_scene).setup
    rng = np.random.default_rng(0)
    q = setup.sample_poses(rng, 6)
    x = setup.params.nominal + rng.normal(size=7) * 1e-2
    meas = setup.synthetic_measurements(q, x, rng, 1e-4, 1e-4)
    prob = setup.problem(meas)
    J = prob.jacobian(x)
    eps = 1e-7
    fd = np.stack([(prob.residual(x + eps * e) - prob.residual(x - eps * e)) / (2 * eps) for e in np.eye(7)], -1)
    np.testing.assert_allclose(J, fd, atol=1e-7)
    write_calibrated_model(tmp_path / "m.yaml", setup, x)
    robot = load_calibrated_model(tmp_path / "m.yaml")
    np.testing.assert_allclose(robot.T_cam_tip(q, robot.params.nominal), setup.robot.T_cam_tip(q, x), atol=1e-12)


def test_unknown_robot_kind_is_named(tmp_path):
    (tmp_path / "arm.yaml").write_text("kind: delta3\n")
    (tmp_path / "s.yaml").write_text("robot: arm.yaml\nmount: fixed\n")
    from vision_calib.errors import ConfigError

    with pytest.raises(ConfigError, match="no robot kind reads this file"):
        load_scene(tmp_path / "s.yaml")


def test_register_names_what_a_robot_kind_lacks():
    """register takes a Setup subclass of the rig.registry.RobotKind interface; TypeError naming the rest."""

    class NotASetup:
        kind, mounts = "x", ("fixed",)

    with pytest.raises(TypeError, match="must be a Setup subclass"):
        register(NotASetup)
    with pytest.raises(TypeError, match=r"robot kind Planar2Setup lacks 'mounts'"):
        register(type("Planar2Setup", (Setup,), {"claims": Planar2Setup.claims, "from_scene": Planar2Setup.from_scene,
                                                 "load_model": Planar2Setup.load_model}))
    assert register(Planar2Setup) is Planar2Setup
    unregister("planar2")
