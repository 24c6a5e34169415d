"""The H4 parallel robot (``kinematics.h4.H4Robot``), camera on the base, target on the nacelle.

Commanded poses are nacelle poses X (N, 4) = (x, y, z [m], theta [rad]) mapped to joints by the
TRUE inverse model. Identification: the paper's inverse-geometric-model method (``igm``: joint residuals;
``ekf`` on the same residuals) or least squares on the forward model's pose residuals (``lse``); igm and lse
check each other (:attr:`H4Setup.cross_methods`, ``identify.method_check``).
Evaluation adds the paper's criteria (§6.1): V1 mean and V2 RMS joint residual on validation
measurements [rad], V3 straightness of reconstructed straight-line motions [m].

Scene keys of this kind: ``model`` ("12" | "31") and ``variant`` (paper table 2, A..H); pose grid
``grid81`` (the paper's 81-pose grid on the robot file's workspace).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..config import Section
from ..errors import ConfigError, ParameterError
from ..identify.problem import IdentificationProblem
from ..kinematics.h4 import TILT_NAMES, H4Robot
from ..kinematics.params import ParameterSet
from .base import Evaluation, Measurements, Setup

@dataclass(frozen=True)
class H4Setup(Setup):
    """H4 robot (``robot``: kinematics.h4.H4Robot) + base camera + nacelle target. ``sigma_q_rad``:
    joint-reading noise of the IGM problem (0: measurement noise only). ``robot_path``, ``model``,
    ``variant``: where the robot came from (for variants and the calibrated-model file)."""

    robot: H4Robot | None = None
    sigma_q_rad: float = 0.0
    robot_path: str = ""
    variant: str | None = None
    #: what the preparation step (``experiment.prepare``, capability ``rig.base.TiltsFromAxis``) does with the
    #: camera/target tilts: "identify" (measure, then identify what the IGM determines better), "axis" (measure
    #: only, paper §4.1), "off" (keep the scene's nominal tilts)
    tilt_mode: str = "identify"
    #: (4,) rad std of the prior on the tilt parameters TILT_NAMES (their nominal = the rotation-axis estimate),
    #: set by :meth:`with_tilts`; empty: no prior (tilts fixed, or identified from the joints alone)
    tilt_prior_std_rad: tuple[float, ...] = ()
    tilt_names: ClassVar[tuple[str, ...]] = TILT_NAMES

    kind: ClassVar[str] = "h4"
    residuals: ClassVar[tuple[str, ...]] = ("joint", "pose")
    #: igm: least squares on the joint residuals (the paper's inverse-model method); ekf: EKF on the same
    #: residuals; lse: least squares on the pose residuals of the forward model (identify.h4_problem)
    methods: ClassVar[tuple[str, ...]] = ("igm", "ekf", "lse")
    method_residuals: ClassVar[dict] = {"igm": "joint", "ekf": "joint", "lse": "pose"}
    cross_methods: ClassVar[dict] = {"igm": "lse", "lse": "igm"}
    mounts: ClassVar[tuple[str, ...]] = ("base",)
    pose_grids: ClassVar[tuple[str, ...]] = ("grid81",)
    scene_keys: ClassVar[tuple[str, ...]] = ("model", "variant")
    truth_keys: ClassVar[tuple[str, ...]] = ("model", "tilt_deg")
    measured_criteria: ClassVar[tuple[str, ...]] = ("V1_rad", "V2_rad")
    reach_check: ClassVar[str] = "inverse model"

    @property
    def n_joints(self) -> int:
        return 4

    @property
    def model(self) -> str:
        return self.robot.model

    def T_cam_target(self, poses: ArrayLike, x: ArrayLike) -> np.ndarray:
        return self.robot.camera_measurement(poses, x)

    def joints(self, poses: ArrayLike, x: ArrayLike) -> np.ndarray:
        return self.robot.igm(poses, x)

    def commanded_from_joints(self, joints: ArrayLike, x: ArrayLike | None = None) -> np.ndarray:
        """Nacelle poses X (N, 4) of joint values (N, 4) rad by the forward model (Newton on the IGM) at x."""
        return self.robot.fgm(joints, self.params.nominal if x is None else x)

    def reachable(self, poses: ArrayLike, x: ArrayLike | None = None, min_margin_rad: float = 0.0) -> np.ndarray:
        """(N,) bool: every chain closes by the inverse model at poses X (N, 4), at least ``min_margin_rad`` from its
        serial singularity (``H4Robot.reach_margin``)."""
        m = self.robot.reach_margin(poses, x)
        return np.all(np.isfinite(m) & (m >= min_margin_rad), axis=1)

    def end_point(self, poses: ArrayLike, x: ArrayLike | None = None) -> np.ndarray:
        """(N, 3) [m] nacelle point of poses X (N, 4) in the base frame."""
        return np.array(np.asarray(poses, float)[:, :3])

    def predict_from_joints(self, joints: ArrayLike, x: ArrayLike) -> np.ndarray:
        """Camera view of the nacelle poses the forward model (Newton on the IGM) gives for joints (N, 4)."""
        return self.robot.camera_measurement(self.robot.fgm(joints, x), x)

    def problem(self, meas: Measurements, residual: str | None = None,
                params: ParameterSet | None = None) -> IdentificationProblem:
        """The IGM problem (``residual`` "joint", default) or the forward-model pose problem ("pose")."""
        from ..identify.h4_problem import h4_igm_problem, h4_pose_problem

        build = h4_pose_problem if self.check_residual(residual) == "pose" else h4_igm_problem
        robot = replace(self.robot, params=params or self.params)
        prob = build(robot, meas.joints, meas.T_cam_target, sigma_q_rad=self.sigma_q_rad or None,
                     pose_cov=meas.cov, labels=meas.labels)
        return self.with_tilt_prior(prob)

    def residual_for(self, method: str, residual: str | None = None) -> str:
        """The method decides the H4 residual (:attr:`method_residuals`); the scene's ``residual`` is not used."""
        return self.method_residuals.get(method) or self.check_residual(residual)

    def noise_response(self, meas: Measurements, residual: str, params: ParameterSet, x: ArrayLike) -> tuple:
        """(B (N, m, 10), cov_e (N, 10, 10)): ``identify.h4_problem.h4_noise_response`` at x of the residual
        kind, raw errors [measured-pose error (6), joint-reading error (4)] of covariance
        blockdiag(meas.cov, sigma_q_rad^2 I4)."""
        from ..identify.h4_problem import h4_noise_response, h4_raw_noise_cov

        robot = replace(self.robot, params=params)
        return (h4_noise_response(robot, meas.joints, meas.T_cam_target, x, self.check_residual(residual)),
                h4_raw_noise_cov(meas.cov, self.sigma_q_rad))


    def with_tilt_prior(self, prob: IdentificationProblem) -> IdentificationProblem:
        """``prob`` with the rotation-axis prior of the tilts (:meth:`with_tilts`) as prior rows, when set."""
        if not self.tilt_prior_std_rad or not self.robot.tilt_params:
            return prob
        ps = prob.params
        prior = 100.0 * ps.scale if prob.prior_std is None else np.array(prob.prior_std, float)
        for n, s in zip(TILT_NAMES, self.tilt_prior_std_rad):
            prior[ps.index(n)] = s
        rows = tuple(prob.prior_rows) + tuple(n for n in TILT_NAMES if n not in prob.prior_rows)
        return replace(prob, prior_std=prior, prior_rows=rows,
                       meta=dict(prob.meta, tilt_prior={n: float(s) for n, s in zip(TILT_NAMES, self.tilt_prior_std_rad)}))

    def evaluate(self, x: ArrayLike, x_true: ArrayLike, validation: ArrayLike, measurements: Measurements | None = None,
                 truth: Setup | None = None) -> Evaluation:
        """Nacelle pose error of the forward model (Newton on the IGM) with parameters x, from the joints
        the TRUE robot (``truth``, default this setup, with x_true) needs for validation poses X (N, 4);
        V1/V2 from validation measurements (joints - IGM of the measured camera poses under x), V3 from
        the straight lines of :meth:`lines`."""
        truth_robot = (truth or self).robot
        X = np.asarray(validation, float)
        Xh = self.robot.fgm(truth_robot.igm(X, x_true), x, X0=X)
        err = np.zeros((len(X), 6))
        err[:, :3] = Xh[:, :3] - X[:, :3]
        err[:, 5] = np.angle(np.exp(1j * (Xh[:, 3] - X[:, 3])))
        crit = {}
        if measurements is not None:
            r = np.angle(np.exp(1j * (measurements.joints - self.robot.igm_from_camera(measurements.T_cam_target, x))))
            crit["V1_rad"], crit["V2_rad"] = float(np.mean(r)), float(np.sqrt(np.mean(r**2)))
        crit["V3_m"] = float(np.mean([self._straightness(L, x, x_true, truth_robot) for L in self.lines()]))
        return Evaluation(X[:, :3], err, crit)

    def lines(self) -> list[np.ndarray]:
        """Two straight-line motions through the workspace (paper §6.1, configurations 1 and 2):
        X (50, 4) each, along a diagonal of the box at theta = 0 and theta = 10 deg."""
        c, s = self.robot.center, self.robot.size
        t = np.linspace(-0.45, 0.45, 50)[:, None]
        d1 = np.array([s[0], s[1], 0.0])
        d2 = np.array([s[0], -s[1], s[2]])
        return [np.column_stack([c + t * d1, np.zeros(len(t))]),
                np.column_stack([c + t * d2, np.full(len(t), np.radians(10.0))])]

    def _straightness(self, line_X, x, x_true, truth_robot) -> float:
        """RMS distance [m] of the forward-model positions (parameters x) of the joints that move the
        TRUE robot along a straight line, to their least-squares line."""
        P = self.robot.fgm(truth_robot.igm(line_X, x_true), x, X0=line_X)[:, :3]
        P = P - P.mean(axis=0)
        u = np.linalg.svd(P, full_matrices=False)[2][0]
        return float(np.sqrt(np.mean(np.sum((P - np.outer(P @ u, u)) ** 2, axis=1))))

    def sample_poses(self, rng: np.random.Generator, n: int, check_view: bool = True) -> np.ndarray:
        from ..kinematics.h4 import random_workspace_poses

        return random_workspace_poses(n, rng, center=self.robot.center, size=self.robot.size)

    def pose_grid(self, name: str) -> np.ndarray:
        """The commanded poses (81, 4) of the grid "grid81" (``rig.base.PoseGrids``)."""
        if name != "grid81":
            raise ConfigError(f"{self.name}: this {self.kind} setup has no pose grid {name!r} (it has grid81)")
        return self.robot.pose_grid()

    def with_params(self, params: ParameterSet) -> "H4Setup":
        return replace(self, params=params, robot=replace(self.robot, params=params))

    def with_variant(self, variant: str | None = None, model: str | None = None) -> "H4Setup":
        """The setup with its robot rebuilt from the robot file: ``variant`` A..H (paper table 2, built
        from the model-12 robot: E..H are model 31) and/or ``model`` "12"|"31"; the free mask follows the
        variant (or the model's default: D for 12, H for 31); names the current free mask fixes stay fixed.
        ConfigError if the variant/model pair is impossible."""
        from ..kinematics import h4_variants
        from ..kinematics.h4_io import load_h4_robot

        if variant is None and model is None:
            return self
        model = model or (("31" if variant in tuple("EFGH") else "12") if variant else self.model)
        robot = load_h4_robot(self.robot_path, model=model)
        if variant is not None:
            if model == "31" and variant in tuple("ABCD"):
                raise ConfigError(f"{self.robot_path}: H4 variant {variant} is built on model 12, not model 31")
            try:
                robot = h4_variants.variant(robot, variant)
            except ParameterError as exc:
                raise ConfigError(f"{self.robot_path}: variant: {exc}") from None
        fix = [n for n in self.meta.get("fix", ()) if n in robot.names]
        params = robot.params.fix(fix) if fix else robot.params
        return replace(self, params=params, robot=replace(robot, params=params), variant=variant)

    # ------------------------------------------------------------------ rig.base.TiltsFromAxis
    def tilt_reference(self) -> tuple[np.ndarray, np.ndarray]:
        """(R_BC0, R_ME0) (3, 3) of the robot without its tilt parameters (their values folded in): what the
        rotation-axis estimate's tilts are relative to."""
        from ..kinematics.h4_variants import without_tilt_params

        base = without_tilt_params(self.robot)
        return base.R_BC0, base.R_ME0

    def with_tilts(self, tilts_rad: ArrayLike, prior_std_rad: ArrayLike | None = None) -> "H4Setup":
        """The setup with the four tilt parameters TILT_NAMES (``kinematics.h4_variants.with_tilt_params``,
        relative to :meth:`tilt_reference`) at tilts_rad (4,): free, with the prior N(tilts_rad, prior_std_rad^2)
        in :meth:`problem` (:meth:`with_tilt_prior`), or fixed when prior_std_rad is None."""
        from ..kinematics.h4_variants import with_tilt_params, without_tilt_params

        free = prior_std_rad is not None
        robot = with_tilt_params(without_tilt_params(self.robot), np.asarray(tilts_rad, float), [free] * 4)
        return replace(self, params=robot.params, robot=robot,
                       tilt_prior_std_rad=tuple(float(v) for v in prior_std_rad) if free else ())

    def truth_model(self, spec: dict, rng: np.random.Generator, where: str = "truth") -> "H4Setup":
        """A true H4 the identified model does not share: ``model: "31"`` (per-chain geometry, free mask H:
        the caller draws deviations on all of it; the paper's real robot needed model 31) and/or
        ``tilt_deg``: std [deg] of random tilts of the camera (about the camera x/y axes) and of the target
        mount (about the target x/y axes), not represented by the 4-parameter external transforms: the truth
        carries them as its (fixed) tilt parameters TILT_NAMES, the identified model measures them from the
        rotation axis (§4.1, ``experiment.prepare``)."""
        bad = set(spec) - set(self.truth_keys)
        if bad:
            raise ConfigError(f"{where}: unknown unmodelled-truth keys {sorted(bad)} (known: {self.truth_keys})")
        setup = self
        model = str(spec.get("model", self.model))
        if model not in ("12", "31"):
            raise ConfigError(f"{where}.model: expected '12' or '31', got {model!r}")
        if model != self.model:
            setup = self.with_variant(model=model)
        try:
            tilt = float(np.radians(float(spec.get("tilt_deg", 0.0))))
        except (TypeError, ValueError):
            raise ConfigError(f"{where}.tilt_deg: expected a number of degrees, got {spec['tilt_deg']!r}") from None
        if not (np.isfinite(tilt) and 0 <= tilt < np.radians(10)):
            raise ConfigError(f"{where}.tilt_deg: expected 0 <= tilt < 10 deg, got {spec['tilt_deg']!r}")
        if tilt > 0:  # carried by the (fixed) tilt parameters, so the report can compare them with the estimate
            from ..kinematics.h4_variants import with_tilt_params

            robot = with_tilt_params(setup.robot, rng.normal(size=4) * tilt)
            setup = replace(setup, robot=robot, params=robot.params)
        return setup

    def model_dict(self) -> dict:
        return {"model": self.robot.model, "variant": self.variant, "shared_L": bool(self.robot.shared_L),
                "tilts": {"R_BC0": self.robot.R_BC0.tolist(), "R_ME0": self.robot.R_ME0.tolist()},
                "tilt_params": bool(self.robot.tilt_params)}

    # ------------------------------------------------------------------ registry hooks
    @staticmethod
    def claims(robot_path: Path, doc: dict | None) -> bool:
        """A YAML robot file with ``kind: h4``."""
        return doc is not None and doc.get("kind") == "h4"

    @classmethod
    def from_scene(cls, ctx) -> "H4Setup":
        from ..kinematics import h4_variants
        from ..kinematics.h4_io import load_h4_robot

        top = ctx.top
        model = str(top.get("model", str, "12", choices=("12", "31")))
        robot = load_h4_robot(ctx.robot_path, model=model)
        variant = top.get("variant", str, None)
        if variant is not None:
            try:
                robot = h4_variants.variant(robot, variant)
            except ParameterError as exc:
                raise top.error("variant", str(exc)) from None
        params = ctx.apply_free(robot.params)
        return cls(name=ctx.name, params=params, camera=ctx.camera, mount=ctx.mount,
                   meta={"robot_path": str(ctx.robot_path), "fix": tuple(ctx.fixed_names)},
                   robot=replace(robot, params=params), sigma_q_rad=ctx.sigma_q_rad,
                   robot_path=str(ctx.robot_path), variant=variant)

    @staticmethod
    def load_model(doc: Section, robot_path: Path) -> H4Robot:
        """The robot of a calibrated-model file (``io.model_export``), nominal values still to set."""
        from ..kinematics import h4_variants
        from ..kinematics.h4_io import load_h4_robot

        robot = load_h4_robot(robot_path, model=str(doc.get("model", str, "12")))
        variant = doc.get("variant", str, None)
        if variant:
            robot = h4_variants.variant(robot, variant)
        elif doc.get("shared_L", bool, False) and not robot.shared_L:
            robot = h4_variants.variant(robot, "E")  # the only variant sharing one arm length
        tilts = doc.section("tilts", default={})
        if "R_BC0" in tilts:
            robot = replace(robot, R_BC0=np.asarray(tilts.get("R_BC0", list), float),
                            R_ME0=np.asarray(tilts.get("R_ME0", list), float))
        if doc.get("tilt_params", bool, False):
            from ..kinematics.h4_variants import with_tilt_params

            robot = with_tilt_params(robot)
        return robot
