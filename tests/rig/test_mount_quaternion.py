"""Mounts read from YAML accept xyz + quat [qx, qy, qz, qw] (scalar last) as well as xyz + rpy."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vision_calib.errors import ConfigError
from vision_calib.rig import SCENES_DIR, load_scene

ROOT = SCENES_DIR.parent
RPY_DEG = [180.0, 0.0, 90.0]
CAM_RPY_DEG = [10.0, -20.0, 90.0]


def _quat(rpy_deg):
    # R = Rz(yaw) Ry(pitch) Rx(roll): scipy's extrinsic "xyz" with [roll, pitch, yaw]
    return Rotation.from_euler("xyz", rpy_deg, degrees=True).as_quat().tolist()


def _scene(tmp_path, target_mount: str, camera_mount: str, name="s.yaml") -> str:
    text = (SCENES_DIR / "rx90_eye_in_hand.yaml").read_text()
    text = text.replace("robot: robots/", f"robot: {SCENES_DIR}/robots/").replace(
        "target: ../targets/", f"target: {ROOT}/targets/")
    text = text.replace("target_in_base: {xyz: [-0.0386, -0.0375, -0.6611], rpy: [180.0, 0.0, 90.0]}",
                        f"target_in_base: {{xyz: [-0.0386, -0.0375, -0.6611], {target_mount}}}")
    text = text.replace("camera_in_flange: {xyz: [0.0, 0.05, 0.08], rpy: [0.0, 0.0, 90.0]}",
                        f"camera_in_flange: {{xyz: [0.0, 0.05, 0.08], {camera_mount}}}")
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def _chain_T(scene):
    ch = scene.setup.chain
    q = np.zeros((1, ch.n_joints)) + 0.3
    return ch.forward(q, ch.params.nominal)[0]


def test_scene_mount_as_rpy_and_as_quat_give_the_same_transform(tmp_path):
    a = load_scene(_scene(tmp_path, f"rpy: {RPY_DEG}", f"rpy: {CAM_RPY_DEG}", "a.yaml"))
    b = load_scene(_scene(tmp_path, f"quat: {_quat(RPY_DEG)}", f"quat: {_quat(CAM_RPY_DEG)}", "b.yaml"))
    np.testing.assert_allclose(_chain_T(b), _chain_T(a), atol=1e-12)
    np.testing.assert_allclose(b.setup.params.nominal, a.setup.params.nominal, atol=1e-12)


@pytest.mark.parametrize("mount,needle", [
    ("quat: [0.0, 0.0, 0.7, 0.7]", r"s\.yaml: mounts\.target_in_base\.quat: expected a unit quaternion"),
    ("quat: [0, 0, 0, 1], rpy: [0, 0, 0]", r"mounts\.target_in_base\.quat: give either rpy or quat"),
    ("quat: [0, 0, 1]", r"mounts\.target_in_base\.quat"),
])
def test_bad_quaternion_is_refused_naming_file_and_key(tmp_path, mount, needle):
    with pytest.raises(ConfigError, match=needle):
        load_scene(_scene(tmp_path, mount, f"rpy: {CAM_RPY_DEG}"))

