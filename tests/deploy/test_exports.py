"""Controller exports, each read back by an INDEPENDENT reader written here (xml.etree / csv / yaml + plain numpy:
no vision_calib code between the file and the numbers) and compared with the calibrated model: URDF (URDF and
modified-DH robots), modified-DH table, UR kinematics YAML, ROS static transforms (calibrated models and hand-eye
results); formats that cannot hold a kinematics give a named error."""

import csv
import io
import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from vision_calib import frames
from vision_calib.errors import ConfigError
from vision_calib.deploy.export import FORMATS, FormatNotSupportedError, export

TOL = 1e-9


# ----------------------------------------------------------------------------- plain-numpy readers
def rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def tr(x, y, z):
    T = np.eye(4)
    T[:3, 3] = x, y, z
    return T


def rpy(x, y, z, r, p, yw):
    """URDF origin: Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)."""
    return tr(x, y, z) @ rz(yw) @ ry(p) @ rx(r)


def quat(x, y, z, qx, qy, qz, qw):
    n = np.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    T = tr(x, y, z)
    T[:3, :3] = [[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
                 [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
                 [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]]
    return T


def axis_angle(axis, a):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
    return T


def urdf_fk(text: str, base: str, tip: str):
    """fk(q (n,)) -> T_base_tip of the URDF text, movable joints in chain order (fixed joints folded in)."""
    root = ET.fromstring(text)
    by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    chain, link = [], tip
    while link != base:
        j = by_child[link]
        chain.append(j)
        link = j.find("parent").get("link")
    chain.reverse()

    def fk(q):
        T, k = np.eye(4), 0
        for j in chain:
            o = j.find("origin")
            xyz = [float(v) for v in o.get("xyz", "0 0 0").split()]
            r = [float(v) for v in o.get("rpy", "0 0 0").split()]
            T = T @ rpy(*xyz, *r)
            if j.get("type") != "fixed":
                T = T @ axis_angle([float(v) for v in j.find("axis").get("xyz").split()], q[k])
                k += 1
        return T

    return fk


def dh_rows(text: str) -> list[dict]:
    return list(csv.DictReader(io.StringIO("\n".join(ln for ln in text.splitlines() if not ln.startswith("#")))))


def dh_fk(rows, q, mounts: bool):
    """base . prod Tz(l) Rx(alpha) Ry(beta) Tx(a) Rz(theta + q) Tz(d) . tool (mounts) or the links alone."""
    f = lambda r, k: float(r[k])  # noqa: E731
    pose = {r["frame"]: quat(*(f(r, k) for k in ("x_m", "y_m", "z_m", "qx", "qy", "qz", "qw")))
            for r in rows if r["frame"] in ("base", "tool")}
    T = pose["base"] if mounts else np.eye(4)
    links = [r for r in rows if r["frame"].startswith("joint")]
    for r, qi in zip(links, q):
        T = T @ tr(0, 0, f(r, "l_m")) @ rx(f(r, "alpha_rad")) @ ry(f(r, "beta_rad")) @ tr(f(r, "a_m"), 0, 0)
        T = T @ rz(f(r, "theta_rad") + qi) @ tr(0, 0, f(r, "d_m"))
    return T @ pose["tool"] if mounts else T


def _q(robot, n=25, seed=3):
    return np.random.default_rng(seed).uniform(-np.pi, np.pi, size=(n, robot.n_joints))


# ----------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("name,base,tip", [("ur5e_eye_in_hand", "base_link", "tool0"),
                                           ("rx90_eye_in_hand", "base_link", "link_6")])
def test_urdf_round_trip(results, tmp_path, name, base, tip):
    r = results[name].robot
    text = export(results[name].folder, "urdf", tmp_path / "robot.urdf").read_text()
    fk = urdf_fk(text, base, tip)
    q = _q(r)
    T, _ = r.forward(q)
    err = max(np.abs(fk(qi) - Ti).max() for qi, Ti in zip(q, T))
    assert err < TOL, err
    assert "joint offsets" in text  # the offsets, stated in a comment


def test_dh_table_round_trip(results, tmp_path):
    r = results["rx90_eye_in_hand"].robot
    text = export(results["rx90_eye_in_hand"].folder, "dh", tmp_path / "dh.csv").read_text()
    assert "theta_offset_i = theta_i - theta_i(nominal)" in text
    rows = dh_rows(text)
    assert [row["frame"] for row in rows] == ["base"] + [f"joint{i}" for i in range(1, 7)] + ["tool"]
    q = _q(r)
    T, _ = r.forward(q)
    To, _ = r.observed(q)
    for qi, Ti, Toi in zip(q, T, To):
        assert np.abs(dh_fk(rows, qi, mounts=False) - Ti).max() < TOL
        assert np.abs(dh_fk(rows, qi, mounts=True) - Toi).max() < TOL
    offsets = {f"q{i}": float(rows[i]["theta_offset_rad"]) for i in range(1, 7)}
    assert offsets == pytest.approx({j: o["offset"] for j, o in r.joint_offsets().items()}, abs=1e-15)


def test_ur_kinematics_yaml_round_trip(results, tmp_path):
    res = results["ur5e_eye_in_hand"]
    r = res.robot
    text = export(res.folder, "ur_yaml", tmp_path / "kin.yaml").read_text()
    kin = yaml.safe_load(text)["kinematics"]
    assert list(kin) == ["shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3", "hash"]
    # the fixed links around the six joints, from the source URDF (ur_description keeps them in its xacro)
    src = (res.folder / "robot" / "ur5e.urdf").read_text()
    pre = urdf_fk(src, "base_link", "base_link_inertia")([])
    tail = urdf_fk(src, "wrist_3_link", "tool0")([])
    q = _q(r)
    T, _ = r.forward(q)
    for qi, Ti in zip(q, T):
        F = pre
        for name, a in zip(("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3"), qi):
            o = kin[name]
            F = F @ rpy(o["x"], o["y"], o["z"], o["roll"], o["pitch"], o["yaw"]) @ rz(a)
        assert np.abs(F @ tail - Ti).max() < TOL


def _tf_entries(text: str) -> list[dict]:
    """[{parent, child, T from the YAML numbers, T_args from the static_transform_publisher line}]."""
    out = []
    for t in yaml.safe_load(text)["transforms"]:
        tok = t["static_transform_publisher"].split()
        assert len(tok) == 9
        a = [float(v) for v in tok[:7]]
        tt, rr = t["translation"], t["rotation"]
        out.append({"name": t["name"], "parent": t["parent_frame"], "child": t["child_frame"], "std": t.get("std"),
                     "T": quat(tt["x"], tt["y"], tt["z"], rr["x"], rr["y"], rr["z"], rr["w"]), "T_args": quat(*a),
                     "args_frames": tok[7:]})
    return out


def test_ros_static_transforms_of_a_calibrated_serial_robot(results, tmp_path):
    res = results["ur5e_eye_in_hand"]
    m = res.robot.model
    TL, TR = m.robot.nominal_transforms(m.x)
    tf = {e["name"]: e for e in _tf_entries(export(res.folder, "ros_tf", tmp_path / "tf.yaml").read_text())}
    assert list(tf) == ["T_flange_cam", "T_base_target"]  # the camera mount first
    for name, T, frames_ in (("T_flange_cam", TR, ["tool0", "camera_optical_frame"]),
                             ("T_base_target", np.linalg.inv(TL), ["base_link", "target"])):
        e = tf[name]
        assert [e["parent"], e["child"]] == e["args_frames"] == frames_
        assert np.abs(e["T"] - T).max() < 1e-12 and np.abs(e["T_args"] - T).max() < 1e-12
    # the translation std of the camera mount is its parameters' std (t = the mount's translation parameters)
    sd = [np.sqrt(m.covariance[m.names.index(f"T_flange_cam.t{c}")] [m.names.index(f"T_flange_cam.t{c}")])
          for c in "xyz"]
    assert tf["T_flange_cam"]["std"]["translation_m"] == pytest.approx(sd, rel=1e-6)


def test_ros_static_transforms_of_the_h4_camera(results, tmp_path):
    res = results["h4_vision"]
    m = res.robot.model
    tf = {e["name"]: e for e in _tf_entries(export(res.folder, "ros_tf", tmp_path / "tf.yaml").read_text())}
    assert np.abs(tf["T_base_cam"]["T"] - m.robot.T_base_cam(m.x)).max() < 1e-12
    assert np.abs(tf["T_nacelle_target"]["T"] - np.linalg.inv(m.robot.T_target_nacelle(m.x))).max() < 1e-12
    assert tf["T_base_cam"]["std"]["translation_m"][0] == pytest.approx(
        np.sqrt(m.covariance[m.names.index("B_T_C.x"), m.names.index("B_T_C.x")]), rel=1e-6)


def _handeye_folder(folder, mount="eye_in_hand"):
    """A hand-eye result folder (report.json of kind process_handeye) from a synthetic hand-eye fit; returns the
    true (T_flange_cam or T_base_cam, the other mount)."""
    from vision_calib.identify import solve_lse
    from vision_calib.identify.handeye_problem import handeye_problem, transforms_from_x
    from vision_calib.report.handeye import handeye_report
    from vision_calib.serialize import to_json

    rng = np.random.default_rng(4)
    Fl = np.array([frames.T_from_xyz_rotvec(np.r_[rng.uniform([0.3, -0.3, 0.2], [0.7, 0.3, 0.6]),
                                                  np.array([np.pi, 0, 0]) + rng.normal(scale=0.3, size=3)])
                   for _ in range(15)])
    A = np.linalg.inv(frames.T_from_xyz_rpy([0.01, 0.05, 0.08], [0.02, -0.01, 1.5]))  # T_cam_flange
    B = frames.T_from_xyz_rpy([0.5, 0.0, -0.1], [np.pi, 0.0, 0.3])  # T_base_target
    M = A @ np.linalg.inv(Fl) @ B
    d = np.concatenate([rng.normal(scale=1e-4, size=(15, 3)), rng.normal(scale=2e-4, size=(15, 3))], axis=1)
    pb = handeye_problem(Fl, frames.perturb_pose(M, d), mount, sigma_t_m=1e-4, sigma_rot_rad=2e-4)
    res = solve_lse(pb)
    Ah, Bh = transforms_from_x(pb, res.identified)
    folder.mkdir(parents=True)
    (folder / "report.json").write_text(to_json({"kind": "process_handeye", "handeye": handeye_report(res, Ah, Bh, pb)}))
    return np.linalg.inv(Ah), Bh


def test_ros_static_transforms_of_a_hand_eye_result(tmp_path):
    T_flange_cam, T_base_target = _handeye_folder(tmp_path / "he")
    rep = json.loads((tmp_path / "he" / "report.json").read_text())["handeye"]["transforms"]
    tf = {e["name"]: e for e in _tf_entries(export(tmp_path / "he", "ros_tf", tmp_path / "tf.yaml").read_text())}
    assert [tf["T_flange_cam"]["parent"], tf["T_flange_cam"]["child"]] == ["tool0", "camera_optical_frame"]
    assert np.abs(tf["T_flange_cam"]["T"] - T_flange_cam).max() < 1e-12
    assert np.abs(tf["T_flange_cam"]["T_args"] - T_flange_cam).max() < 1e-12
    assert np.abs(tf["T_base_target"]["T"] - T_base_target).max() < 1e-12
    assert tf["T_flange_cam"]["std"]["translation_m"] == pytest.approx(rep["T_flange_cam"]["std_xyz_m"], rel=1e-12)
    assert tf["T_flange_cam"]["std"]["rotation_rad"] == pytest.approx(
        np.radians(rep["T_flange_cam"]["std_rot_deg"]), rel=1e-12)
    with pytest.raises(FormatNotSupportedError, match="hand-eye result has no robot kinematics"):
        export(tmp_path / "he", "urdf", tmp_path / "x.urdf")


# ----------------------------------------------------------------------------- formats that cannot hold it
@pytest.mark.parametrize("name,fmt,match", [
    ("h4_vision", "dh", "format 'dh' cannot represent this h4 robot"),
    ("h4_vision", "urdf", "format 'urdf' cannot represent this h4 robot"),
    ("h4_vision", "ur_yaml", "format 'ur_yaml' cannot represent this h4 robot"),
    ("ur5e_eye_in_hand", "dh", "format 'dh' cannot represent this urdf robot"),
    ("rx90_eye_in_hand", "ur_yaml", "format 'ur_yaml' cannot represent this serial robot"),
])
def test_formats_that_cannot_represent_the_kinematics_are_named(results, tmp_path, name, fmt, match):
    with pytest.raises(FormatNotSupportedError, match=match):
        export(results[name].folder, fmt, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_unknown_format_and_missing_result_are_named(results, tmp_path):
    with pytest.raises(ConfigError, match="unknown export format 'step'"):
        export(results["rx90_eye_in_hand"].folder, "step", tmp_path / "x")
    from vision_calib.errors import DataError

    with pytest.raises(DataError, match="no calibrated_model.yaml in this result folder"):
        export(tmp_path, "dh", tmp_path / "x.csv")
    assert set(FORMATS) == {"urdf", "dh", "ur_yaml", "ros_tf"}
