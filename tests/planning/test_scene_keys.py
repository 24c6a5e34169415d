"""The planner's scene keys (rig.cell: obstacles, planning) and the pose-file source of a scene (rig.pose_file:
``poses: {kind: file, path: ...}``): typed SI values, strict keys, named errors."""

import numpy as np
import pytest

from vision_calib.errors import ConfigError, DataError
from vision_calib.rig import SCENES_DIR, load_scene, scene_poses

ROOT = SCENES_DIR.parent


def _scene(tmp_path, base: str, extra: str = "", drop: tuple = ()) -> str:
    lines = (SCENES_DIR / base).read_text().replace("robot: robots/", f"robot: {SCENES_DIR}/robots/").replace(
        "target: ../targets/", f"target: {ROOT}/targets/").splitlines()
    text = "\n".join(ln for ln in lines if not ln.startswith(drop)) if drop else "\n".join(lines)
    p = tmp_path / "s.yaml"
    p.write_text(text + "\n" + extra)
    return str(p)


def test_shipped_cell_is_typed_in_si():
    sc = load_scene(SCENES_DIR / "ur5e_cell.yaml")
    assert [o.name for o in sc.obstacles] == ["table", "fixture", "lamp"]
    table, box, lamp = sc.obstacles
    assert table.kind == "plane" and table.T_base_obj[2, 3] == pytest.approx(-0.0921)
    assert box.dims_m == pytest.approx((0.12, 0.12, 0.55)) and lamp.dims_m == pytest.approx((0.03, 0.9))
    p = sc.planning
    assert p.clearance_m == 0.02 and p.distance_m == (0.25, 0.9) and p.max_incidence_rad == pytest.approx(np.radians(45))
    assert p.max_joint_speed_rad_s == pytest.approx(np.radians(60)) and p.link_radii_m is None


def test_units_of_the_scene_apply(tmp_path):
    path = _scene(tmp_path, "ur5e_eye_in_hand.yaml", "planning: {clearance: 30, link_radii: [80, 75, 60, 50, 45, 45], "
                  "move_step: 0.05}\nobstacles: [{kind: sphere, radius: 100, xyz: [0, 0, 900]}]\n")
    text = open(path).read().replace("units: {length: m, angle: deg}", "units: {length: mm, angle: rad}")
    open(path, "w").write(text)
    sc = load_scene(path)
    assert sc.planning.clearance_m == pytest.approx(0.03) and sc.planning.link_radii_m[0] == pytest.approx(0.08)
    assert sc.planning.move_step_rad == pytest.approx(0.05) and sc.obstacles[0].dims_m == pytest.approx((0.1,))
    assert sc.obstacles[0].T_base_obj[2, 3] == pytest.approx(0.9)


@pytest.mark.parametrize("base,extra,needle", [
    ("ur5e_eye_in_hand.yaml", "obstacles: [{kind: box, size: [1, 1, 1], colour: red}]", r"obstacles\[0\]\.colour"),
    ("ur5e_eye_in_hand.yaml", "obstacles: [{kind: cone}]", r"obstacles\[0\]\.kind"),
    ("ur5e_eye_in_hand.yaml", "obstacles: [{kind: plane}, {kind: box, size: [1, -1, 1]}]", r"obstacles\[1\]\.size"),
    ("ur5e_eye_in_hand.yaml", "obstacles: [{kind: cylinder, radius: 0.1}]", r"obstacles\[0\]\.length"),
    ("ur5e_eye_in_hand.yaml", "obstacles: [{kind: plane, name: t}, {kind: plane, name: t}]", r"obstacles\[1\]\.name"),
    ("ur5e_eye_in_hand.yaml", "obstacles: {kind: plane}", "obstacles: expected a list"),
    ("ur5e_eye_in_hand.yaml", "planning: {clearence: 0.01}", "planning.clearence.*did you mean 'clearance'"),
    ("ur5e_eye_in_hand.yaml", "planning: {link_radii: [0.1, 0.1]}", "planning.link_radii"),
    ("ur5e_eye_in_hand.yaml", "planning: {distance: [1.0, 0.5]}", "planning.distance"),
    ("ur5e_eye_in_hand.yaml", "planning: {max_incidence: 95}", "planning.max_incidence"),
    ("h4_vision.yaml", "obstacles: [{kind: plane}]", "obstacles: the h4 robot kind has no collision model"),
    ("h4_vision.yaml", "planning: {tool_radius: 0.05}", "planning.tool_radius: the h4 robot kind has no collision"),
    ("ur5e_eye_in_hand.yaml", "validation: {kind: file, path: s.yaml}", "validation.kind"),
])
def test_bad_keys_are_named(tmp_path, base, extra, needle):
    with pytest.raises(ConfigError, match=needle):
        load_scene(_scene(tmp_path, base, extra, drop=("validation:",) if extra.startswith("validation") else ()))


def _pose_scene(tmp_path, csv: str, poses: str, base="ur5e_eye_in_hand.yaml", recording_units=None):
    (tmp_path / "plan").mkdir(exist_ok=True)
    (tmp_path / "plan" / "poses.csv").write_text(csv)
    if recording_units:
        (tmp_path / "plan" / "recording.yaml").write_text(f"units: {{angle: {recording_units}}}\n")
    return _scene(tmp_path, base, f"poses: {poses}\n", drop=("poses:", "  kind:", "  count:", "  center:", "  spread:"))


def test_poses_from_a_file(tmp_path):
    csv = "pose_id,q1,q2,q3,q4,q5,q6\na,0,-90,90,-90,-90,0\nb,10,-80,80,-90,-90,20\n"
    sc = load_scene(_pose_scene(tmp_path, csv, "{kind: file, path: plan/poses.csv}"))  # the scene's deg
    q = scene_poses(sc, np.random.default_rng(0))
    assert np.allclose(np.degrees(q[1]), [10, -80, 80, -90, -90, 20])
    assert len(scene_poses(sc, np.random.default_rng(0), 1)) == 1
    with pytest.raises(ConfigError, match="3 poses asked, the pose file"):
        scene_poses(sc, np.random.default_rng(0), 3)
    rad = csv.replace("0,-90,90,-90,-90,0", "0,-1.5708,1.5708,-1.5708,-1.5708,0").replace(
        "10,-80,80,-90,-90,20", "0.1,-1.4,1.4,-1.5708,-1.5708,0.3")
    sc = load_scene(_pose_scene(tmp_path, rad, "{kind: file, path: plan/poses.csv}", recording_units="rad"))
    assert scene_poses(sc, np.random.default_rng(0))[1, 0] == pytest.approx(0.1)  # recording.yaml's rad
    assert "recording.yaml" in sc.poses.units_from
    sc = load_scene(_pose_scene(tmp_path, csv, "{kind: file, path: plan/poses.csv, units: {angle: deg}}",
                                recording_units="rad"))
    assert scene_poses(sc, np.random.default_rng(0))[1, 0] == pytest.approx(np.radians(10))  # the scene's key wins


@pytest.mark.parametrize("csv,poses,err,needle", [
    ("pose_id,q1,q2\na,0,0\n", "{kind: file, path: plan/poses.csv}", DataError, "header: missing column"),
    ("pose_id,q1,q2,q3,q4,q5,q6\na,0,0,0,0,0,x\n", "{kind: file, path: plan/poses.csv}", DataError, "pose 'a'"),
    ("pose_id,q1,q2,q3,q4,q5,q6\na,0,0,400,0,0,0\n", "{kind: file, path: plan/poses.csv}", DataError, "pose 'a'"),
    ("pose_id,q1,q2,q3,q4,q5,q6\n", "{kind: file, path: nowhere.csv}", ConfigError, "poses.path: file not found"),
    ("pose_id,q1,q2,q3,q4,q5,q6\n", "{kind: file, path: /etc/hostname}", ConfigError, "outside the folder"),
    ("pose_id,q1,q2,q3,q4,q5,q6\n", "{kind: file, path: plan/poses.csv, center: [0]}", ConfigError, "poses.center"),
    ("pose_id,q1,q2,q3,q4,q5,q6\n", "{kind: file, path: plan/poses.csv, configurations: x}", ConfigError,
     "poses.configurations"),
])
def test_bad_pose_files_are_named(tmp_path, csv, poses, err, needle):
    with pytest.raises(err, match=needle):
        sc = load_scene(_pose_scene(tmp_path, csv, poses))
        scene_poses(sc, np.random.default_rng(0))


def test_h4_pose_file_holds_joints_mapped_by_the_forward_model(tmp_path):
    h4 = load_scene(SCENES_DIR / "h4_vision.yaml").setup
    X = h4.robot.pose_grid()[:5]
    q = h4.joints(X, h4.params.nominal)
    csv = "pose_id,q1,q2,q3,q4\n" + "".join(f"p{i}," + ",".join(repr(float(v)) for v in r) + "\n"
                                            for i, r in enumerate(q))
    sc = load_scene(_pose_scene(tmp_path, csv, "{kind: file, path: plan/poses.csv}", "h4_vision.yaml", "rad"))
    assert np.allclose(scene_poses(sc, np.random.default_rng(0)), X, atol=1e-9)
