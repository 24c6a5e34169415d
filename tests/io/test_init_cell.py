"""`vision-calib init`: a self-contained folder from a shipped cell, the example recording or the user's URDF."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import yaml

from vision_calib.cli import main
from vision_calib.errors import ConfigError
from vision_calib.io.init_cell import KEY_COMMENTS, STARTERS, init_cell, list_starters
from vision_calib.rig import load_scene, scene_poses
from vision_calib.shipped import data_dir, scenes_dir

TWO_LEAVES = """<robot name="twoleaves">
  <link name="world"/><link name="a"/><link name="b"/><link name="c"/><link name="cam"/>
  <joint name="j1" type="revolute"><parent link="world"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j3" type="continuous"><parent link="b"/><child link="c"/><origin xyz="0.3 0 0"/><axis xyz="0 1 0"/></joint>
  <joint name="fixcam" type="fixed"><parent link="a"/><child link="cam"/><origin xyz="0.1 0 0"/></joint>
</robot>
"""


STARTERS_BY = {s.name: s.scene for s in STARTERS if s.scene}


@pytest.mark.parametrize("name", sorted(STARTERS_BY))
def test_cells_are_self_contained_and_load_like_the_shipped_scene(tmp_path, name):
    res = init_cell(tmp_path / "cell", name)
    entry = tmp_path / "cell" / "scene.yaml"
    assert res["entry"] == str(entry)
    text = entry.read_text()
    doc = yaml.safe_load(text)
    assert not str(doc["robot"]).startswith(("/", "..")) and (tmp_path / "cell" / doc["robot"]).is_file()
    if "target" in doc:
        assert doc["target"] == "target.yaml"
    for key in set(doc) & set(KEY_COMMENTS):  # every key a user edits carries a comment
        line = next(ln for ln in text.splitlines() if ln.startswith(f"{key}:"))
        assert "#" in line, line
    # the copy is the same cell: a user moving the folder anywhere gets the shipped scene's model and poses
    shutil.move(tmp_path / "cell", tmp_path / "moved")
    mine, shipped = load_scene(tmp_path / "moved" / "scene.yaml"), load_scene(scenes_dir() / f"{STARTERS_BY[name]}.yaml")
    assert mine.setup.params.names == shipped.setup.params.names
    np.testing.assert_array_equal(mine.setup.params.nominal, shipped.setup.params.nominal)
    np.testing.assert_array_equal(scene_poses(mine, np.random.default_rng(1), 3), scene_poses(shipped, np.random.default_rng(1), 3))


def test_example_folder_is_the_recording_and_processes(tmp_path):
    init_cell(tmp_path / "ex", "example")
    assert (tmp_path / "ex" / "recording.yaml").is_file() and (tmp_path / "ex" / "poses.csv").is_file()
    assert not any(p.is_symlink() for p in (tmp_path / "ex").rglob("*"))
    assert main(["process", str(tmp_path / "ex"), "--out", str(tmp_path / "r"), "--no-plots", "--json"]) == 0


def test_refuses_a_non_empty_folder_and_unknown_names(tmp_path, capsys):
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "mine.txt").write_text("keep me")
    with pytest.raises(ConfigError, match="not an empty folder"):
        init_cell(tmp_path / "busy", "rx90")
    assert sorted(p.name for p in (tmp_path / "busy").iterdir()) == ["mine.txt"]
    with pytest.raises(ConfigError, match=r"no such starting point.*ur5e"):
        init_cell(tmp_path / "new", "ur6")
    assert not (tmp_path / "new").exists()
    assert main(["init", str(tmp_path / "busy"), "--from", "rx90"]) == 2
    assert "not an empty folder" in capsys.readouterr().err
    assert main(["init", "--list"]) == 0
    listed = capsys.readouterr().out
    assert listed == list_starters() + "\n" and all(s.name in listed for s in STARTERS)


def test_urdf_cell_guesses_the_chain_and_takes_overrides(tmp_path, capsys):
    urdf = tmp_path / "twoleaves.urdf"
    urdf.write_text(TWO_LEAVES)
    assert main(["init", str(tmp_path / "c1"), "--urdf", str(urdf)]) == 0
    out = capsys.readouterr().out
    assert "base_link 'world' (the root link), tip_link 'c' (guessed)" in out and "cam (1 joints)" in out
    doc = yaml.safe_load((tmp_path / "c1" / "scene.yaml").read_text())
    assert doc["urdf"] == {"base_link": "world", "tip_link": "c"} and doc["robot"] == "robot/twoleaves.urdf"
    # 3 joints (the cell had 6): centre = middle of the limits (deg in the cell's units; continuous: 0), spread 20
    np.testing.assert_allclose(doc["poses"]["center"], [np.degrees(0.5), np.degrees(-0.5), 0.0], atol=0.06)
    assert doc["poses"]["spread"] == [20.0, 20.0, 20.0]
    sc = load_scene(tmp_path / "c1" / "scene.yaml")
    assert sc.setup.chain.n_joints == 3
    assert main(["init", str(tmp_path / "c2"), "--urdf", str(urdf), "--tip-link", "b"]) == 0
    assert yaml.safe_load((tmp_path / "c2" / "scene.yaml").read_text())["urdf"]["tip_link"] == "b"
    assert load_scene(tmp_path / "c2" / "scene.yaml").setup.chain.n_joints == 2
    assert main(["init", str(tmp_path / "c3"), "--urdf", str(urdf), "--tip-link", "nowhere"]) == 2
    assert "'nowhere' is not a link" in capsys.readouterr().err


def test_same_joint_count_keeps_the_cells_poses(tmp_path):
    """A UR-like URDF (6 joints) keeps the UR5e cell's joint sets (a pose the camera sees the board from)."""
    init_cell(tmp_path / "c", urdf=data_dir() / "scenes" / "robots" / "ur5e.urdf")
    doc = yaml.safe_load((tmp_path / "c" / "scene.yaml").read_text())
    assert doc["poses"]["center"] == yaml.safe_load((scenes_dir() / "ur5e_eye_in_hand.yaml").read_text())["poses"]["center"]
    assert len(scene_poses(load_scene(tmp_path / "c" / "scene.yaml"), np.random.default_rng(0), 5)) == 5


@pytest.mark.parametrize("file_name,link", [("evil: {a: 1} #x.urdf", "c"), ("new\nline: {b: 2}.urdf", "c"),
                                            ("quotes.urdf", "it's \"c\"")])
def test_hostile_names_give_a_scene_that_loads_with_its_own_keys(tmp_path, capsys, file_name, link):
    """A URDF file name or a link name holding YAML syntax, quotes or a line break: written through the YAML
    emitter, scene.yaml reads back with the shipped keys and the names as given, and loads as a scene."""
    xml_link = link.replace("&", "&amp;").replace('"', "&quot;")
    path = tmp_path / file_name
    path.write_text(TWO_LEAVES.replace('"c"', f'"{xml_link}"'))
    assert main(["init", str(tmp_path / "cell"), "--urdf", str(path)]) == 0
    entry = tmp_path / "cell" / "scene.yaml"
    doc = yaml.safe_load(entry.read_text())
    shipped = yaml.safe_load((scenes_dir() / "ur5e_eye_in_hand.yaml").read_text())
    assert set(doc) == set(shipped)
    assert doc["robot"] == f"robot/{file_name}" and (tmp_path / "cell" / doc["robot"]).is_file()
    assert doc["urdf"] == {"base_link": "world", "tip_link": link}
    chain = load_scene(entry).setup.chain  # the scene loads, with the user's robot
    assert chain.n_joints == 3 and chain.meta["tip_link"] == link
