"""Helpers of the deploy tests: one synthetic calibration of a shipped scene (identify-synthetic style: truth ->
noisy pose measurements -> identification) written as a result folder the way ``io.report.write_report`` writes
it (calibrated_model.yaml with the fit's covariance, fixed and folded parameters), and workspace joint sets."""

import numpy as np

from vision_calib.deploy import CalibratedRobot
from vision_calib.deploy.solve import joint_jacobian
from vision_calib.experiment.steps import analyze_setup
from vision_calib.experiment.synthetic import run_synthetic
from vision_calib.io.model_export import write_calibrated_model
from vision_calib.rig import SCENES_DIR

SCENES = ("rx90_eye_in_hand", "ur5e_eye_in_hand", "h4_vision")
#: smallest singular value [m or rad per rad] of the tool's joint Jacobian of a workspace joint set: the shipped
#: RX-90 scene works next to its elbow singularity (q3 = 90 deg), where a calibrated pose may not be reachable
MIN_SINGULAR = 0.02


def calibrate(name: str, folder, seed: int = 1, n_poses=None):
    """(run, folder): run_synthetic on the scene (its default poses), the result written into ``folder``."""
    run = run_synthetic(SCENES_DIR / f"{name}.yaml", seed=seed, n_poses=n_poses)
    rep, _ = analyze_setup(run.setup, run.poses, run.residual)
    res = run.result
    write_calibrated_model(folder / "calibrated_model.yaml", run.setup, res.identified, res.std, res.free, res,
                           run.problem, rep.to_dict())
    return run, folder


def workspace_joints(robot: CalibratedRobot, setup, n: int = 200, seed: int = 5) -> np.ndarray:
    """n joint sets (n, n_joints) of the scene's workspace as the nominal model commands them: serial arms, the
    scene's random joint sets (target in view) away from singular configurations (MIN_SINGULAR); H4, the joints
    of random workspace poses by the nominal inverse model."""
    rng = np.random.default_rng(seed)
    if robot.n_joints == 4:
        X = setup.sample_poses(rng, n)
        return setup.robot.igm(X, robot.x_nominal)
    q = setup.sample_poses(rng, 6 * n)
    f = lambda v: robot.kin.tool(v, robot.x_nominal)  # noqa: E731
    sv = np.linalg.svd(joint_jacobian(f, q, f(q)), compute_uv=False)[:, -1]
    q = q[sv > MIN_SINGULAR]
    assert len(q) >= n, f"only {len(q)} of {6 * n} joint sets away from singular configurations"
    return q[:n]
