"""URDF robots straight into ``process-poses``: the measured-pose file's ``scene:`` may be the scene itself,
holding only the keys process-poses reads (robot, mount, mounts, [urdf], [units], [identification], [name]);
any other key is an error naming it; the URDF's base and tip links default to its root and its one tip
(rig/urdf.py ``default_links``). The robot is a small 6R URDF written here."""

import json

import numpy as np
import pytest

from vision_calib import cli
from vision_calib import frames as F
from vision_calib.errors import ConfigError
from vision_calib.experiment.steps import scene_truth
from vision_calib.config import Section
from vision_calib.io.measured_poses_writer import write_measured_poses
from vision_calib.rig import load_scene
from vision_calib.rig.scene import scene_from_section
from vision_calib.rig.urdf import default_links

ST, SR = 1e-4, float(np.radians(0.02))  # 0.1 mm, 0.02 deg per component
#: (xyz m, rpy rad) of each revolute joint's origin, all about their z axis: an anthropomorphic 6R arm
JOINTS = [([0, 0, 0.30], [0, 0, 0]), ([0, 0.12, 0], [-np.pi / 2, 0, 0]), ([0.40, 0, 0], [0, 0, 0]),
          ([0.05, -0.35, 0], [np.pi / 2, 0, 0]), ([0, 0, 0], [-np.pi / 2, 0, 0]), ([0, 0.09, 0], [np.pi / 2, 0, 0])]
INLINE = {"robot": "arm.urdf", "mount": "eye_in_hand",
          "mounts": {"target_in_base": {"xyz": [0.6, 0.0, -0.1], "rpy": [180.0, 0.0, 0.0]},
                     "camera_in_flange": {"xyz": [0.0, 0.05, 0.08], "rpy": [0.0, 0.0, 90.0]}}}


def write_urdf(path, fingers=False):
    """A 6R arm base -> l1 .. l6 -> tool (fixed) [-> two prismatic fingers]; returns path."""
    links = ["base", *(f"l{i}" for i in range(1, 7)), "tool"] + (["finger_a", "finger_b"] if fingers else [])
    out = ['<?xml version="1.0"?>', '<robot name="arm6">'] + [f'  <link name="{lk}"/>' for lk in links]
    for i, (xyz, rpy) in enumerate(JOINTS, 1):
        out.append(f'  <joint name="j{i}" type="revolute"><parent link="{links[i - 1]}"/><child link="l{i}"/>'
                   f'<origin xyz="{" ".join(map(str, xyz))}" rpy="{" ".join(map(str, rpy))}"/><axis xyz="0 0 1"/>'
                   '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>')
    out.append('  <joint name="flange" type="fixed"><parent link="l6"/><child link="tool"/>'
               '<origin xyz="0 0 0.02" rpy="0 0 0"/></joint>')
    for f in ("a", "b") if fingers else ():
        out.append(f'  <joint name="f{f}" type="prismatic"><parent link="tool"/><child link="finger_{f}"/>'
                   '<axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>')
    path.write_text("\n".join(out + ["</robot>"]) + "\n")
    return path


def _file(tmp_path, scene, n=40, seed=3):
    """A measured-pose file of ``scene`` (inline mapping or path) with rows simulated from the scene's truth:
    (yaml path, x_true)."""
    write_urdf(tmp_path / "arm.urdf")
    sc = load_scene(scene) if not isinstance(scene, dict) else scene_from_section(Section(scene, tmp_path / "m.yaml",
                                                                                          "scene"))
    x_true = scene_truth(sc)
    rng = np.random.default_rng(seed)
    q = sc.setup.sample_poses(rng, n, check_view=False)
    d = np.concatenate([rng.normal(scale=ST, size=(n, 3)), rng.normal(scale=SR, size=(n, 3))], axis=1)
    T = F.perturb_pose(sc.setup.T_cam_target(q, x_true), d)
    p = write_measured_poses(tmp_path / "m.yaml", scene, [f"p{i:02d}" for i in range(n)], q, T, "T_cam_target",
                             units={"length": "mm", "angle": "deg"}, default_sigma=(ST, SR))
    return p, x_true


def test_default_links_root_and_single_tip(tmp_path):
    assert default_links(write_urdf(tmp_path / "a.urdf")) == ("base", "tool")
    with pytest.raises(ConfigError, match=r"b.urdf: no single tip link .*2 leaf links below 7 movable joints: "
                                          r"finger_a, finger_b\): give urdf: \{base_link, tip_link\}"):
        default_links(write_urdf(tmp_path / "b.urdf", fingers=True))


@pytest.mark.parametrize("how", ["inline", "file"])
def test_urdf_robot_processed_from_a_minimal_scene(tmp_path, capsys, how):
    """The URDF named in the measured-pose file itself (or in a scene file with only those keys): exit 0, the
    calibrated URDF written, the base parameters recovered within their std, held-out error down."""
    scene = dict(INLINE)
    if how == "file":
        import yaml

        (tmp_path / "scene.yaml").write_text(yaml.safe_dump(scene))
        scene = tmp_path / "scene.yaml"
    p, x_true = _file(tmp_path, scene)
    rc = cli.main(["process-poses", str(p), "--out", str(tmp_path / "out"), "--no-plots"])
    capsys.readouterr()
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rc == 0 and rep["source"]["scene"]["robot_kind"] == "urdf"
    assert (tmp_path / "out" / "calibrated_model.urdf").is_file()
    rows = [r for r in rep["parameters"] if r.get("std")]
    names = [r["name"] for r in rep["parameters"]]
    assert len(rows) == 30  # 4 per revolute joint + 6 (Everett, Driels & Mooring)
    z = np.array([(r["identified"] - x_true[names.index(r["name"])]) / r["std"] for r in rows])
    assert np.all(np.abs(z) < 4.5) and 0.4 < np.sqrt(np.mean(z**2)) < 1.8, z
    kf = rep["holdout"]["overall"]
    assert kf["n_poses"] == 40 and kf["after"]["position_rms_mm"] < 0.3 * kf["before"]["position_rms_mm"]


def test_inline_scene_keys_process_poses_does_not_read_are_named(tmp_path, capsys):
    write_urdf(tmp_path / "arm.urdf")
    scene = {**INLINE, "camera": {"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240},
             "truth": {"seed": 1}}
    p = write_measured_poses(tmp_path / "m.yaml", scene, ["a", "b", "c"], np.zeros((3, 6)),
                             np.broadcast_to(np.eye(4), (3, 4, 4)), "T_cam_target", default_sigma=(ST, SR), folds=2)
    rc = cli.main(["process-poses", str(p), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2
    assert "m.yaml: scene: camera, truth: not read by process-poses (a scene written here takes only name, robot" in err
    assert not (tmp_path / "out" / "report.json").exists()
