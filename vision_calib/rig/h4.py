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

from ..errors import ConfigError, DataError, ParameterError
from ..kinematics.h4 import TILT_NAMES, H4Robot
from .base import Evaluation, Setup

#: significance level at which a measured camera/target tilt replaces the nominal one (chi-square, 2 dof)
AXIS_LEVEL = 1e-3
#: an axis estimate whose std is below this [rad] is exact (noise-free rotations): the tilts are fixed at it
EXACT_AXIS_STD_RAD = 1e-9
#: the rotation axis is "not fixed" (tilts not applied) when the axis fit's residuals fail the chi-square test
#: against the measurements' rotation covariance (level AXIS_LEVEL) AND their variance exceeds the predicted by
#: this factor (residual std twice the predicted, as steps.UNEXPLAINED_CHI2_DOF): image rotations carry a
#: systematic part (detector bias) the covariances only partly model
AXIS_MAX_VARIANCE_RATIO = 4.0


def _chi2_2(w, c) -> float:
    """w^T c^-1 w for a 2-vector w and its covariance c (2, 2); inf when c is singular (exact data) and w != 0."""
    try:
        return float(w @ np.linalg.solve(c, w))
    except np.linalg.LinAlgError:
        return float("inf") if np.any(w != 0) else 0.0


@dataclass(frozen=True)
class H4Setup(Setup):
    """H4 robot (``robot``: kinematics.h4.H4Robot) + base camera + nacelle target. ``sigma_q_rad``:
    joint-reading noise of the IGM problem (0: measurement noise only). ``robot_path``, ``model``,
    ``variant``: where the robot came from (for variants and the calibrated-model file)."""

    robot: H4Robot | None = None
    sigma_q_rad: float = 0.0
    robot_path: str = ""
    variant: str | None = None
    #: what :meth:`prepare` does with the camera/target tilts: "identify" (measure, then identify what the IGM
    #: determines better), "axis" (measure only, paper §4.1), "off" (keep the scene's nominal tilts)
    tilt_mode: str = "identify"
    #: (4,) rad std of the prior on the tilt parameters TILT_NAMES (their nominal = the rotation-axis estimate),
    #: set by :meth:`prepare`; empty: no prior (tilts fixed, or identified from the joints alone)
    tilt_prior_std_rad: tuple = ()

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

    @property
    def n_joints(self) -> int:
        return 4

    @property
    def model(self) -> str:
        return self.robot.model

    def T_cam_target(self, poses, x) -> np.ndarray:
        return self.robot.camera_measurement(poses, x)

    def joints(self, poses, x) -> np.ndarray:
        return self.robot.igm(poses, x)

    def predict_from_joints(self, joints, x) -> np.ndarray:
        """Camera view of the nacelle poses the forward model (Newton on the IGM) gives for joints (N, 4)."""
        return self.robot.camera_measurement(self.robot.fgm(joints, x), x)

    def problem(self, meas, residual=None, params=None):
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

    def noise_response(self, meas, residual, params, x) -> tuple:
        """(B (N, m, 10), cov_e (N, 10, 10)): ``identify.h4_problem.h4_noise_response`` at x of the residual
        kind, raw errors [measured-pose error (6), joint-reading error (4)] of covariance
        blockdiag(meas.cov, sigma_q_rad^2 I4)."""
        from ..identify.h4_problem import h4_noise_response, h4_raw_noise_cov

        robot = replace(self.robot, params=params)
        return (h4_noise_response(robot, meas.joints, meas.T_cam_target, x, self.check_residual(residual)),
                h4_raw_noise_cov(meas.cov, self.sigma_q_rad))


    def with_tilt_prior(self, prob):
        """``prob`` with the rotation-axis prior of the tilts (:meth:`prepare`) as prior rows, when set."""
        if not self.tilt_prior_std_rad or not self.robot.tilt_params:
            return prob
        ps = prob.params
        prior = 100.0 * ps.scale if prob.prior_std is None else np.array(prob.prior_std, float)
        for n, s in zip(TILT_NAMES, self.tilt_prior_std_rad):
            prior[ps.index(n)] = s
        rows = tuple(prob.prior_rows) + tuple(n for n in TILT_NAMES if n not in prob.prior_rows)
        return replace(prob, prior_std=prior, prior_rows=rows,
                       meta=dict(prob.meta, tilt_prior={n: float(s) for n, s in zip(TILT_NAMES, self.tilt_prior_std_rad)}))

    def evaluate(self, x, x_true, validation, measurements=None, truth=None) -> Evaluation:
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

    def sample_poses(self, rng, n, check_view=True) -> np.ndarray:
        from ..kinematics.h4 import random_workspace_poses

        return random_workspace_poses(n, rng, center=self.robot.center, size=self.robot.size)

    def pose_grid(self, name: str) -> np.ndarray:
        if name != "grid81":
            return super().pose_grid(name)
        return self.robot.pose_grid()

    def with_params(self, params):
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

    def prepare(self, meas) -> tuple["H4Setup", dict]:
        """Camera and target tilts (paper §4.1): measured from the rotation axis of the nacelle
        (``identify.camera_axis``), then carried by the four tilt parameters TILT_NAMES
        (``kinematics.h4_variants.with_tilt_params``). With ``tilt_mode`` "identify" (default) all four are
        identified with the other parameters, the axis estimate entering the fit as a prior N(axis value,
        axis std^2) (one prior row each, ``IdentificationProblem.prior_rows``; the estimate's x/y
        correlation is below 1e-3 on the demo scene, so the prior is diagonal): the IGM refines what it
        determines (the camera tilts, through the camera distance), the target tilts (second order in the
        joints) keep about the axis value and its std, and the std and the verdict of the fit carry the
        axis' uncertainty. No rule decides whether to free them: the prior leaves the degrees of freedom of
        the adequacy test unchanged. "axis": the paper's step alone (tilts fixed at the axis value: their
        uncertainty is then NOT carried, the info says so); "off": nominal tilts kept.
        Nothing is applied when the rotations contradict a fixed axis (``CameraAxisEstimate.consistency``
        against the measured rotation covariance: p < AXIS_LEVEL and chi2/dof > AXIS_MAX_VARIANCE_RATIO);
        the info dict (report's ``prepared`` block) has the estimates, the axis test, and then a ``warning``."""
        from ..identify.camera_axis import estimate_camera_axis
        from ..kinematics.h4_variants import with_tilt_params, without_tilt_params

        from scipy.stats import chi2

        if self.tilt_mode not in ("identify", "axis", "off"):
            raise ConfigError(f"H4Setup.tilt_mode: expected 'identify', 'axis' or 'off', got {self.tilt_mode!r}")
        if self.tilt_mode == "off":
            return self, {"applied": False, "reason": "tilt_mode off"}
        base = without_tilt_params(self.robot)
        # rotation noise from the residuals of the axis fit, not from the per-pose covariances: the measured
        # rotations carry a systematic part (detector bias) that the covariances miss
        try:
            est = estimate_camera_axis(meas.T_cam_target, R_BC0=base.R_BC0, R_ME0=base.R_ME0)
        except DataError as exc:  # e.g. all poses at one theta: the axis is not determined, keep the nominal
            return self, {"applied": False, "reason": str(exc)}
        q = [_chi2_2(w, c) for w, c in ((est.tilt_cam_rad, est.cov_tilt_cam),
                                       (est.tilt_target_rad, est.cov_tilt_target))]
        axis_test = est.consistency(meas.cov[:, 3:, 3:])
        fixed = not (axis_test["chi2"] is not None and axis_test["p_value"] < AXIS_LEVEL
                     and axis_test["chi2_dof"] > AXIS_MAX_VARIANCE_RATIO)
        vals = np.concatenate([est.tilt_cam_rad, est.tilt_target_rad])
        axis_std = np.concatenate([est.tilt_cam_std_rad, est.tilt_target_std_rad])
        usable = bool(fixed and np.all(np.isfinite(vals)) and np.all(np.isfinite(axis_std)))
        # exact rotations (noise-free synthetic data) give an exact axis: fixed at it, with its zero std
        exact = bool(usable and np.max(axis_std) < EXACT_AXIS_STD_RAD)
        identify = usable and self.tilt_mode == "identify" and not exact
        if usable:
            robot = with_tilt_params(base, vals, [identify] * 4)
        else:
            robot = with_tilt_params(base, np.zeros(4))
        out = replace(self, params=robot.params, robot=robot,
                      tilt_prior_std_rad=tuple(float(v) for v in axis_std) if identify else ())
        sd_c, sd_t = np.sqrt(np.diag(est.cov_tilt_cam)), np.sqrt(np.diag(est.cov_tilt_target))
        info = {"camera_tilt_deg": np.degrees(est.tilt_cam_rad).tolist(), "camera_tilt_std_deg": np.degrees(sd_c).tolist(),
                "target_tilt_deg": np.degrees(est.tilt_target_rad).tolist(),
                "target_tilt_std_deg": np.degrees(sd_t).tolist(), "rms_residual_deg": float(np.degrees(est.rms_residual_rad)),
                "applied": bool(usable), "chi2_camera_target": q,
                "identified": list(TILT_NAMES) if identify else [],
                "prior": ({n: {"mean_deg": float(np.degrees(v)), "std_deg": float(np.degrees(s))}
                           for n, v, s in zip(TILT_NAMES, vals, axis_std)} if identify else None),
                "axis_fixed": bool(fixed), "axis_test": axis_test,
                "method": "rotation axis of the nacelle (paper 4.1); tilts relative to the nominal, about the camera "
                          "x/y and target x/y axes; "
                          + ("the four tilts are identified with the other parameters, the axis estimate entering "
                             "the fit as a prior (mean and std above, one prior row each): the parameter table's "
                             "tilt std carry it" if identify else
                             "tilts fixed at the axis value (tilt_mode 'axis', the paper's step): their std is not "
                             "carried into the other parameters' std")
                          + "; none applied when the rotations do not share one fixed axis within the noise (axis_test: "
                          f"chi2 of the axis fit's residuals against the rotation covariance, level {AXIS_LEVEL}, "
                          f"chi2/dof > {AXIS_MAX_VARIANCE_RATIO})"}
        if not fixed:
            info["warning"] = (
                f"the measured rotations do not share one fixed rotation axis within the noise (axis fit chi2/dof "
                f"{axis_test['chi2_dof']:.3g}, p {axis_test['p_value']:.2g}, rotation residual RMS "
                f"{np.degrees(est.rms_residual_rad):.3g} deg): the camera/target tilts are not measured from it and "
                "stay nominal (the nacelle or a mount moves with the pose: the model does not hold)")
        elif not usable:
            info["warning"] = "the rotation axis estimate is not finite: the camera/target tilts stay nominal"
        elif self.tilt_mode == "axis":
            info["note"] = ("tilt_mode 'axis': camera/target tilts fixed at the rotation-axis estimate (std "
                            f"{', '.join(f'{np.degrees(s):.3g}' for s in axis_std)} deg), not carried into the std")
        return out, info

    def truth_model(self, spec: dict, rng: np.random.Generator, where: str = "truth") -> "H4Setup":
        """A true H4 the identified model does not share: ``model: "31"`` (per-chain geometry, free mask H:
        the caller draws deviations on all of it; the paper's real robot needed model 31) and/or
        ``tilt_deg``: std [deg] of random tilts of the camera (about the camera x/y axes) and of the target
        mount (about the target x/y axes), not represented by the 4-parameter external transforms: the truth
        carries them as its (fixed) tilt parameters TILT_NAMES, the identified model measures them from the
        rotation axis (§4.1, :meth:`prepare`)."""
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
    def load_model(doc, robot_path: Path):
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
