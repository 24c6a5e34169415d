"""CalibratedRobot: forward kinematics and its covariance (analytic parameter Jacobian against central differences,
and against the spread of sampled parameters), the tcp, inverse and compensate round trips on the model over 200
workspace poses (< 1 um, 1 urad), joint limits kept, and the named errors."""

import numpy as np
import pytest

from vision_calib import frames as F
from vision_calib.deploy import CalibratedRobot, PoseNotReachedError
from vision_calib.deploy.robot import AMPLIFIED_DEG_PER_MM
from vision_calib.errors import DataError, ParameterError

from deploy_helpers import workspace_joints

TOL_T, TOL_R = 1e-6, 1e-6  # the required round trip: 1 um, 1 urad


def test_analytic_covariance_matches_central_differences(result):
    r = result.robot
    q = workspace_joints(r, result.run.setup, 20)
    for fun in (r.forward, r.observed):
        T, C = fun(q)
        Tf, Cf = fun(q, fd=True)
        np.testing.assert_array_equal(T, Tf)
        assert np.abs(C - Cf).max() < 1e-6 * np.abs(C).max(), fun.__name__
        assert np.all(np.linalg.eigvalsh(C)[:, -1] > 0)


def test_forward_covariance_is_the_spread_of_sampled_parameters(result):
    """Monte Carlo: parameters drawn from the covariance, the tool pose's pose error spread = forward()'s covariance."""
    r = result.robot
    q = workspace_joints(r, result.run.setup, 3)
    rng = np.random.default_rng(0)
    lam, V = np.linalg.eigh(r.covariance)
    dx = (V * np.sqrt(np.clip(lam, 0, None))) @ rng.normal(size=(len(lam), 2000))
    T0, C = r.forward(q)
    e = np.array([F.pose_error(T0, r.kin.tool(q, r.x + d)) for d in dx.T])  # (S, N, 6)
    for k in range(len(q)):
        S = np.cov(e[:, k].T)
        sd = np.sqrt(np.diag(C[k]))
        on = sd > 1e-9 * sd.max()  # the H4 tool does not tilt: no rx, ry variance
        assert np.all(np.sqrt(np.diag(S))[~on] < 1e-9 * sd.max())
        np.testing.assert_allclose(np.sqrt(np.diag(S))[on], sd[on], rtol=0.1)
        w = np.outer(sd[on], sd[on])
        assert np.abs(S[np.ix_(on, on)] / w - C[k][np.ix_(on, on)] / w).max() < 0.1


def test_tcp_moves_the_tool_point_in_the_flange_frame(results):
    r0 = results["ur5e_eye_in_hand"].robot
    tcp = np.array([0.01, -0.02, 0.15])
    r1 = CalibratedRobot.load(results["ur5e_eye_in_hand"].folder, tcp=tcp)
    q = results["ur5e_eye_in_hand"].run.poses[:7]
    T0, _ = r0.forward(q)
    T1, C1 = r1.forward(q)
    np.testing.assert_allclose(T1[:, :3, 3], T0[:, :3, 3] + np.einsum("nij,j->ni", T0[:, :3, :3], tcp), atol=1e-15)
    np.testing.assert_allclose(T1[:, :3, :3], T0[:, :3, :3], atol=0)
    _, C1f = r1.forward(q, fd=True)
    assert np.abs(C1 - C1f).max() < 1e-6 * np.abs(C1).max()
    with pytest.raises(ParameterError, match="tcp"):
        CalibratedRobot.load(results["ur5e_eye_in_hand"].folder, tcp=[0.0, 0.1])


def _err(Ta, Tb):
    e = F.pose_error(Ta, Tb)
    return np.linalg.norm(e[:, :3], axis=1).max(), np.linalg.norm(e[:, 3:], axis=1).max()


def test_inverse_round_trip_over_200_workspace_poses(result):
    r = result.robot
    q = workspace_joints(r, result.run.setup, 200)
    T, _ = r.forward(q)
    qi = r.inverse(T, q_start=q + 0.05)
    et, er = _err(T, r.forward(qi)[0])
    assert et < TOL_T and er < TOL_R, (et, er)
    qn = r.inverse(T)  # no start: from the nominal model's solution
    et, er = _err(T, r.forward(qn)[0])
    assert et < TOL_T and er < TOL_R, (et, er)
    lim = r.kin.joint_limits
    if lim is not None:
        assert np.all((qn >= lim[:, 0]) & (qn <= lim[:, 1]))


def test_compensate_round_trip_over_200_workspace_poses(result):
    """Every joint set corrected: the tool within the predicted accuracy of the nominal tool pose; exact (1 um, 1 urad)
    where the joints are well conditioned; near a singularity the correction stays small."""
    r = result.robot
    q = workspace_joints(r, result.run.setup, 200)
    c = r.compensate_rows(q)
    assert c.corrected.all(), c.why[~c.corrected][:3]
    e = F.pose_error(r.nominal.forward(q)[0], r.forward(c.q_corrected)[0])
    et, er = np.linalg.norm(e[:, :3], axis=1), np.linalg.norm(e[:, 3:], axis=1)
    np.testing.assert_allclose(et, c.remaining_t_m, atol=1e-12)  # the report is what the model gives
    assert np.all(et <= c.tolerance_t_m) and np.all(er <= c.tolerance_r_rad)
    well = c.status == "corrected"  # (the RX-90 scene's poses are nearly all near its q1 / q6 singularity)
    assert not well.any() or (et[well].max() < TOL_T and er[well].max() < TOL_R), (et[well].max(), er[well].max())
    assert np.all(c.amplification[~well] > AMPLIFIED_DEG_PER_MM)
    assert np.all(c.amplification[well] <= AMPLIFIED_DEG_PER_MM) or r.kin.closed_form  # (H4: closed form, no figure)
    assert 1e-5 < np.abs(c.q_corrected - q).max() < 0.05  # a real correction, small (~0.1 deg / 1 mm deviations)
    np.testing.assert_allclose(r.compensate(q[0]), c.q_corrected[0], atol=1e-12)  # one joint set in, one out
    np.testing.assert_array_equal(r.compensate(q), c.q_corrected)


def test_nominal_model_is_the_robot_file_with_the_calibrated_mounts(results):
    r = results["ur5e_eye_in_hand"].robot
    nom = r.nominal
    assert nom.nominal is nom and not np.any(nom.covariance)
    arm = [n for n in r.names if n in r.kin.arm_names]
    mounts = [i for i, n in enumerate(r.names) if n not in r.kin.arm_names]
    np.testing.assert_array_equal(nom.x[mounts], r.x[mounts])
    setup = results["ur5e_eye_in_hand"].run.setup
    np.testing.assert_array_equal(nom.x[[r.names.index(n) for n in arm]], setup.params.nominal[setup.params.indices(arm)])
    q = np.zeros((1, 6))
    np.testing.assert_allclose(nom.compensate(q), q, atol=1e-12)  # the nominal compensating itself: nothing to do


def test_joint_limits_are_kept(results):
    """Goals the model reaches only with a joint past its limit: the answer keeps the limits (another branch) or
    names the pose; never a joint set outside them."""
    r = results["rx90_eye_in_hand"].robot
    lim = r.kin.joint_limits
    q = workspace_joints(r, results["rx90_eye_in_hand"].run.setup, 20)
    q[:, 0] = lim[0, 1] + np.radians(8)  # joint 1 beyond +160 deg
    T, _ = r.kin.tool(q, r.x), None
    try:
        qi = r.inverse(T, q_start=np.clip(q, lim[:, 0], lim[:, 1]))
    except PoseNotReachedError as exc:
        assert "not reached" in str(exc) and "#" in str(exc)
    else:
        assert np.all((qi >= lim[:, 0]) & (qi <= lim[:, 1]))
        assert _err(T, r.forward(qi)[0])[0] < TOL_T


def test_unreachable_poses_are_named(results):
    r = results["rx90_eye_in_hand"].robot
    T = np.repeat(np.eye(4)[None], 3, axis=0)
    T[:, 0, 3] = [0.5, 3.0, 0.6]  # 3 m: out of reach
    T[:, 2, 3] = 0.3
    with pytest.raises(PoseNotReachedError, match=r"pose row-b .*not reached by the calibrated model") as e:
        r.inverse(T, labels=["row-a", "row-b", "row-c"])
    assert e.value.exit_code == 3 and e.value.pose_index == 1


def test_h4_inverse_names_unreachable_and_tilted_poses(results):
    r = results["h4_vision"].robot
    X = results["h4_vision"].run.setup.sample_poses(np.random.default_rng(0), 3)
    T = F.make_T(F.rot_z(X[:, 3]), X[:, :3])
    np.testing.assert_allclose(r.forward(r.inverse(T))[0], T, atol=1e-12)
    far = T.copy()
    far[2, 2, 3] -= 5.0
    with pytest.raises(PoseNotReachedError, match="pose #2: not reached by the calibrated model.*unreachable"):
        r.inverse(far)
    tilted = T.copy()
    tilted[1, :3, :3] = tilted[1, :3, :3] @ F.rot_x(0.01)
    with pytest.raises(PoseNotReachedError, match="pose #1: the H4 nacelle only turns about z_B"):
        r.inverse(tilted)


@pytest.mark.parametrize("bad,match", [(np.zeros(5), r"expected shape \(6,\)"), (np.full(6, np.nan), "not finite")])
def test_bad_joint_values_are_named(results, bad, match):
    with pytest.raises(DataError, match=match):
        results["rx90_eye_in_hand"].robot.forward(bad)


def test_bad_goal_poses_are_named(results):
    T = np.repeat(np.eye(4)[None], 2, axis=0)
    T[1, 0, 0] = 2.0
    with pytest.raises(DataError, match="row 1 is not a finite rigid transform"):
        results["rx90_eye_in_hand"].robot.inverse(T)


def test_a_result_folder_without_a_model_is_named(tmp_path):
    (tmp_path / "report.json").write_text('{"kind": "simulation"}')
    with pytest.raises(DataError, match="no calibrated_model.yaml in this result folder"):
        CalibratedRobot.load(tmp_path)
