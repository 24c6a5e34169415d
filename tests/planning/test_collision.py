"""The planner's collision model and checker (planning.bodies, planning.collision): the numpy broad phase bounds FCL's
distances from below and equals them for capsules, a pose touching the table is refused, a URDF's collision
elements are used when present."""

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("fcl")

from vision_calib.frames import make_T, so3_exp  # noqa: E402
from vision_calib.planning.bodies import build_model, segment_distance  # noqa: E402
from vision_calib.planning.collision import CollisionChecker  # noqa: E402
from vision_calib.rig import SCENES_DIR, load_scene  # noqa: E402
from vision_calib.rig.cell import Obstacle  # noqa: E402

UR5E = SCENES_DIR / "ur5e_eye_in_hand.yaml"
TABLE_Z = -0.0921


def _brute(p1, q1, p2, q2, k=400):
    t = np.linspace(0, 1, k)
    a = p1 + t[:, None] * (q1 - p1)
    b = p2 + t[:, None] * (q2 - p2)
    return np.min(np.linalg.norm(a[:, None] - b[None], axis=2))


def test_segment_distance_matches_a_dense_search_and_degenerate_cases():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(200, 4, 3))
    d = segment_distance(P[:, 0], P[:, 1], P[:, 2], P[:, 3])
    ref = np.array([_brute(*p) for p in P])
    assert np.all(d <= ref + 1e-12) and np.allclose(d, ref, atol=2e-2)
    z = np.zeros(3)
    assert segment_distance(z, z, np.array([1.0, 0, 0]), np.array([1.0, 0, 0])) == pytest.approx(1.0)  # two points
    assert segment_distance(np.array([0.5, 1.0, 0]), np.array([0.5, 1.0, 0]), z, np.array([1.0, 0, 0])) == \
        pytest.approx(1.0)  # a point and a segment
    assert segment_distance(z, np.array([1.0, 0, 0]), np.array([2.0, 1, 0]), np.array([2.0, 1, 0])) == \
        pytest.approx(np.sqrt(2))  # a segment and a point beyond its end
    assert segment_distance(z, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([1, 1.0, 0])) == \
        pytest.approx(1.0)  # parallel


def test_plane_heights_of_each_shape():
    from vision_calib.planning.collision import plane_heights

    n, p0 = np.array([0, 0, 1.0]), np.zeros(3)
    T = make_T(so3_exp(np.array([np.pi / 2, 0, 0])), [0, 0, 1.0])  # z axis turned horizontal
    assert plane_heights("sphere", (0.1,), T, n, p0) == pytest.approx(0.9)
    assert plane_heights("capsule", (0.1, 0.4), T, n, p0) == pytest.approx(0.9)
    assert plane_heights("cylinder", (0.1, 0.4), T, n, p0) == pytest.approx(0.9)
    assert plane_heights("capsule", (0.1, 0.4), make_T(None, [0, 0, 1.0]), n, p0) == pytest.approx(0.7)
    assert plane_heights("box", (0.2, 0.4, 0.6), T, n, p0) == pytest.approx(0.8)  # y edge (0.4) now vertical
    T45 = make_T(so3_exp(np.array([np.pi / 4, 0, 0])), [0, 0, 1.0])
    assert plane_heights("cylinder", (0.1, 0.4), T45, n, p0) == pytest.approx(1 - 0.2 * np.sqrt(0.5) - 0.1 * np.sqrt(0.5))


def _cell(**planning):
    sc = load_scene(UR5E)
    obs = (Obstacle("plane", "table", make_T(None, [0, 0, TABLE_Z])),
           Obstacle("box", "fixture", make_T(so3_exp(np.array([0, 0, 0.4])), [0.55, 0.3, 0.15]), (0.12, 0.12, 0.5)),
           Obstacle("cylinder", "post", make_T(None, [0.2, 0.45, 0.3]), (0.03, 0.9)))
    return replace(sc, obstacles=obs, planning=replace(sc.planning, **planning))


def test_broad_phase_bounds_fcl_from_below_and_is_exact_for_capsules():
    sc = _cell()
    setup = sc.setup
    model = build_model(sc, setup)
    ck = CollisionChecker(model, 0.02)
    q = setup.generic_poses(np.random.default_rng(1), 40)
    F = setup.link_frames(q)
    lo, ls = ck.lower_bounds(F)
    fcl = ck.fcl
    req = fcl.DistanceRequest()
    for n in range(len(q)):
        ck.place(F[n], range(len(model.bodies)))
        for k, (i, j) in enumerate(model.obstacle_pairs):
            if model.obstacles[j].plane:  # exact heights (plane_heights), checked below
                continue
            d = fcl.distance(ck.robot_objs[i], ck.obst_objs[j], req, fcl.DistanceResult())
            if d > 0:  # separated: the bound holds, and is the distance when both hulls are the shapes
                assert lo[n, k] <= d + 1e-6
                if model.bodies[i].exact and model.obstacles[j].exact:
                    assert lo[n, k] == pytest.approx(d, abs=1e-4)
        for k, (i, j) in enumerate(model.self_pairs):
            d = fcl.distance(ck.robot_objs[i], ck.robot_objs[j], req, fcl.DistanceResult())
            if d > 0:
                assert ls[n, k] == pytest.approx(d, abs=1e-5)  # capsules and spheres only: exact


def test_a_pose_below_the_table_or_into_a_box_is_refused_and_named():
    sc = _cell()
    setup = sc.setup
    ck = CollisionChecker(build_model(sc, setup), sc.planning.clearance_m)
    home = np.radians([0, -90, 90, -90, -90, 0])
    low = home + np.radians([0, 60, 40, 0, 0, 0])  # shoulder and elbow down: the wrist goes below the table
    ok, why = ck.screen(setup.link_frames(np.array([home, low])))
    assert ok.tolist() == [True, False]
    assert why[1][1] == "table" and why[1][2] < 0.02
    c = ck.clearances(setup.link_frames(home[None]))[0]
    assert c["clearance_m"] >= 0.02 and c["obstacle_m"] >= 0.02 and c["self_m"] >= 0.02 and len(c["closest"]) == 2
    # the screen's decision agrees with the exact clearance on random poses
    q = setup.sample_poses(np.random.default_rng(3), 300, check_view=False)
    F = setup.link_frames(q)
    ok, _ = ck.screen(F)
    exact = np.array([c["clearance_m"] for c in ck.clearances(F[:60])])
    assert np.array_equal(ok[:60], exact >= sc.planning.clearance_m - 1e-6)


def test_structural_neighbours_are_left_out_and_named():
    sc = _cell()
    model = build_model(sc, sc.setup)
    left = {tuple(sorted(p[:2])) for p in model.disabled}
    assert ("base_link", "upper_arm_link") in left  # they share the shoulder point
    d = model.to_dict()
    assert d["source"].startswith("primitives") and {"table", "fixture", "post", "target board"} <= {
        o["name"] for o in d["obstacles"]}
    assert all(x["why"] for x in d["self_pairs_left_out"])


URDF = """<?xml version="1.0"?>
<robot name="two">
  <link name="base"><collision><origin xyz="0 0 0.05"/><geometry><cylinder radius="0.08" length="0.1"/></geometry></collision></link>
  <link name="l1"><collision><origin xyz="0 0 0.2"/><geometry><box size="0.08 0.08 0.4"/></geometry></collision></link>
  <link name="l2"><collision><origin xyz="0.15 0 0"/><geometry><box size="0.3 0.06 0.06"/></geometry></collision>
                  <collision><geometry><mesh filename="package://nowhere/x.stl"/></geometry></collision></link>
  <link name="tip"><collision><geometry><sphere radius="0.03"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.4"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="fix" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.3 0 0"/></joint>
</robot>
"""


def _two_link_scene(tmp_path, urdf: str, obstacles: str):
    """The scene of the two-joint URDF ``urdf`` with an eye-in-hand camera and ``obstacles`` (YAML list)."""
    (tmp_path / "two.urdf").write_text(urdf)
    (tmp_path / "s.yaml").write_text(f"""
robot: two.urdf
urdf: {{base_link: base, tip_link: tip}}
mount: eye_in_hand
units: {{length: m, angle: deg}}
mounts:
  target_in_base: {{xyz: [0.5, 0, 0], rpy: [180, 0, 0]}}
  camera_in_flange: {{xyz: [0.05, 0, 0]}}
camera: {{width: 640, height: 480, fx: 600, fy: 600, cx: 320, cy: 240}}
target: {SCENES_DIR.parent}/targets/charuco_a5.yaml
poses: {{center: [0, 30], spread: [20, 20]}}
obstacles: {obstacles}
""")
    return load_scene(tmp_path / "s.yaml")


BLOCK = "{kind: box, name: block, size: [0.1, 0.3, 0.1], xyz: [0.15, 0, 0.3]}"


def test_urdf_collision_elements_are_used_when_present(tmp_path):
    sc = _two_link_scene(tmp_path, URDF, f"[{{kind: plane, xyz: [0, 0, -0.01]}}, {BLOCK}]")
    model = build_model(sc, sc.setup)
    assert model.source.startswith("URDF collision elements")
    shapes = {b.name: b.shape for b in model.bodies}
    assert shapes["base"] == "cylinder" and shapes["l1"] == "box" and shapes["tip"] == "sphere"
    assert any("mesh" in w and "checked: " in w for w in model.warnings)  # l2's mesh: its primitive capsule, named
    ck = CollisionChecker(model, 0.02)
    q = np.radians([[0, 0], [0, 60]])  # l2 level above the block; l2 swung down through it
    n0 = ck.n_fcl
    ok, why = ck.screen(sc.setup.link_frames(q))
    assert ok[0] and not ok[1] and why[1][1] == "block"
    assert ck.n_fcl > n0  # boxes: decided by FCL (their hulls are not exact)


@pytest.mark.parametrize("old, new, needle", [
    ('<origin xyz="0 0 0.2"/><geometry><box', '<origin xyz="a b c"/><geometry><box', "link 'l1' <collision>: origin xyz"),
    ('<sphere radius="0.03"/>', '<sphere radius="0"/>', "link 'tip' <collision>: sphere radius"),
    ('<box size="0.08 0.08 0.4"/>', '<box size="0.08 nan 0.4"/>', "link 'l1' <collision>: box size"),
    ('<cylinder radius="0.08" length="0.1"/>', '<cylinder radius="0.08"/>', "link 'base' <collision>: cylinder length"),
    ('<origin xyz="0 0 0.2"/><geometry><box', '<origin xyz="0 0 0.2" rpy="0 90 0"/><geometry><box',
     "degrees read as radians"),
])
def test_bad_urdf_collision_numbers_are_named_errors(tmp_path, old, new, needle):
    from vision_calib.errors import ConfigError
    from vision_calib.planning.bodies import urdf_collisions

    assert old in URDF
    (tmp_path / "two.urdf").write_text(URDF.replace(old, new, 1))
    with pytest.raises(ConfigError, match=needle.replace("(", r"\(")):
        urdf_collisions(tmp_path / "two.urdf", ("base", "l1", "l2"))


def test_links_without_collision_elements_get_capsules_and_a_warning(tmp_path):
    """A URDF with collision geometry on some links only: the others are not left unchecked without a word."""
    urdf = URDF.replace('<link name="l1"><collision><origin xyz="0 0 0.2"/><geometry><box size="0.08 0.08 0.4"/>'
                        '</geometry></collision></link>', '<link name="l1"/>')
    assert urdf != URDF
    sc = _two_link_scene(tmp_path, urdf, f"[{BLOCK}]")
    model = build_model(sc, sc.setup)
    shapes = {b.name: b.shape for b in model.bodies}
    assert shapes["l1"] == "capsule"  # its primitive, not nothing
    w = [x for x in model.warnings if "no collision element" in x]
    assert w and "l1" in w[0] and "checked: " in " ".join(model.warnings)
    ck = CollisionChecker(model, 0.02)
    ok, why = ck.screen(sc.setup.link_frames(np.radians([[0.0, 60.0]])))
    assert not ok[0] and why[0][1] == "block"  # l2 swung down through the block: still found
