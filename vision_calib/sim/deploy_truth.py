"""Compensation against the true robot, in simulation (``tests/deploy/test_truth_robot.py``,
``benchmarks/bench_deploy.py``).

A controller commands joint sets q computed with the NOMINAL model; :meth:`CalibratedRobot.compensate` changes
them into q_c. Driven through the TRUE robot of a synthetic run, where does the frame the calibration observes end,
compared with where the nominal model meant it? All in the camera frame, as the camera measured it:
``T_cam_target`` (``Setup.predict_from_joints``; eye-in-hand: where the target is seen from the camera):

- intended: the nominal arm with the calibrated mounts at q (``CalibratedRobot.x_nominal``);
- compensated: the true robot at q_c; uncompensated: the true robot at q;
- predicted: the calibrated model's covariance of that transform at q_c (``CalibratedRobot.observed``, mapped into
  the camera frame by ``frames.inverse_error_map`` when the observed transform is its inverse).

Figures: RMS over the poses of the translation error norm [m] and of the rotation angle [rad], and the predicted
RMS sqrt(mean(trace(cov))) of each. :func:`calibrate_scene` and :func:`workspace_joints` give the runs and the
joint sets (tests/deploy, benchmarks/bench_deploy.py).
"""

from __future__ import annotations

import numpy as np

from pathlib import Path

from .. import frames as F
from ..errors import DataError
from ..deploy import CalibratedRobot
from ..deploy.solve import joint_jacobian
from ..experiment.steps import analyze_setup
from ..experiment.synthetic import SyntheticRun, run_synthetic
from ..io.model_export import write_calibrated_model
from ..rig import SCENES_DIR

#: smallest singular value [m or rad per rad] of the tool's joint Jacobian of a workspace joint set: the shipped
#: RX-90 scene works next to its elbow singularity (q3 = 90 deg), where a calibrated pose may not be reachable
MIN_SINGULAR = 0.02


def calibrate_scene(name: str, folder, seed: int = 1, n_poses: int | None = None) -> tuple[SyntheticRun, Path]:
    """(run, folder): ``run_synthetic`` on the shipped scene ``name`` (its default poses, ``n_poses`` to change it),
    the result written into ``folder`` as ``report.write.write_report`` writes it (calibrated_model.yaml with the
    fit's covariance, fixed and folded parameters)."""
    run = run_synthetic(SCENES_DIR / f"{name}.yaml", seed=seed, n_poses=n_poses)
    rep, _ = analyze_setup(run.setup, run.poses, run.residual)
    res = run.result
    folder = Path(folder)
    write_calibrated_model(folder / "calibrated_model.yaml", run.setup, res.identified, res.std, res.free, res,
                           run.problem, rep.to_dict())
    return run, folder


def workspace_joints(robot: CalibratedRobot, setup, n: int = 200, seed: int = 5) -> np.ndarray:
    """n joint sets (n, n_joints) of the scene's workspace as the nominal model commands them: serial arms, the
    scene's random joint sets (target in view) away from singular configurations (MIN_SINGULAR); H4, the joints
    of random workspace poses by the nominal inverse model."""
    rng = np.random.default_rng(seed)
    if robot.n_joints == 4:
        return setup.robot.igm(setup.sample_poses(rng, n), robot.x_nominal)
    q = setup.sample_poses(rng, 6 * n)
    T = robot.kin.tool(q, robot.x_nominal)
    sv = np.linalg.svd(joint_jacobian(lambda v: robot.kin.tool(v, robot.x_nominal), q, T), compute_uv=False)[:, -1]
    q = q[sv > MIN_SINGULAR]
    if len(q) < n:
        raise DataError(f"{setup.name}: only {len(q)} of {6 * n} joint sets away from singular configurations")
    return q[:n]


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


def compensation_against_truth(run: SyntheticRun, robot: CalibratedRobot, q: np.ndarray) -> dict:
    """Compensation of the nominal joint sets q (N, n_joints) through the true robot of ``run`` (module docstring),
    ``robot`` being the calibrated model of that run. Returns {n, compensated_t_m, compensated_r_rad,
    uncompensated_t_m, uncompensated_r_rad, predicted_t_m, predicted_r_rad, ratio_t, ratio_r (compensated /
    uncompensated), vs_predicted_t, vs_predicted_r (compensated / predicted), max_compensated_t_m}."""
    setup, truth = run.setup, run.truth or run.setup
    q = np.asarray(q, float)
    qc = robot.compensate(q)
    T_int = setup.predict_from_joints(q, robot.x_nominal)
    T_comp = truth.predict_from_joints(qc, run.x_true)
    T_unc = truth.predict_from_joints(q, run.x_true)
    T_obs, C = robot.observed(qc)
    T_cam = setup.predict_from_joints(qc, robot.x)
    if not np.allclose(T_obs, T_cam, atol=1e-9):  # the observed transform is T_target_cam: into the camera frame
        G = F.inverse_error_map(T_obs)
        C = G @ C @ np.swapaxes(G, 1, 2)
    e_c, e_u = F.pose_error(T_int, T_comp), F.pose_error(T_int, T_unc)
    pred_t = float(np.sqrt(np.mean(np.trace(C[:, :3, :3], axis1=1, axis2=2))))
    pred_r = float(np.sqrt(np.mean(np.trace(C[:, 3:, 3:], axis1=1, axis2=2))))
    out = {"n": int(len(q)), "compensated_t_m": _rms(e_c[:, :3]), "compensated_r_rad": _rms(e_c[:, 3:]),
           "uncompensated_t_m": _rms(e_u[:, :3]), "uncompensated_r_rad": _rms(e_u[:, 3:]),
           "predicted_t_m": pred_t, "predicted_r_rad": pred_r,
           "max_compensated_t_m": float(np.linalg.norm(e_c[:, :3], axis=1).max())}
    out["ratio_t"] = out["compensated_t_m"] / out["uncompensated_t_m"]
    out["ratio_r"] = out["compensated_r_rad"] / out["uncompensated_r_rad"]
    out["vs_predicted_t"] = out["compensated_t_m"] / pred_t
    out["vs_predicted_r"] = out["compensated_r_rad"] / pred_r
    return out


__all__ = ["MIN_SINGULAR", "calibrate_scene", "compensation_against_truth", "workspace_joints"]
