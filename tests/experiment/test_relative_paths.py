"""Result and exported folders move whole (issue 19 item 4): every path an output file stores is relative to
that file, and the small files it needs (scene, robot, target) are copied in, so a folder moved elsewhere
still loads (calibrated model) and processes (exported recording, without --allow-path) with the same numbers;
no written text holds the absolute path of where it was written."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from vision_calib.cli import main
from vision_calib.io.measured_poses import read_measured_poses
from vision_calib.io.measured_poses_writer import write_measured_poses
from vision_calib.io.model_export import load_calibrated_model
from vision_calib.rig import SCENES_DIR, load_scene

RX90 = SCENES_DIR / "rx90_eye_in_hand.yaml"


def _user_scene(d: Path) -> Path:
    """The shipped rx90 scene as a user's own: scene, robot and target files in d (outside the shipped folders)."""
    raw = yaml.safe_load(RX90.read_text())
    (d / "robots").mkdir(parents=True)
    (d / "boards").mkdir()
    shutil.copy(RX90.parent / raw["robot"], d / "robots" / "my_arm.yaml")
    shutil.copy(RX90.parent / raw["target"], d / "boards" / "my_board.yaml")
    raw.update(robot="robots/my_arm.yaml", target="boards/my_board.yaml", name="my_cell")
    (d / "my_cell.yaml").write_text(yaml.safe_dump(raw, sort_keys=False))
    return d / "my_cell.yaml"


def _texts(folder: Path):
    for p in sorted(folder.rglob("*")):
        if p.is_file() and p.suffix.lower() in (".json", ".yaml", ".txt", ".csv", ".urdf"):
            yield p, p.read_text()


def _no_written_path(folders, *roots):
    """No text file under folders names any of roots (their absolute and resolved forms)."""
    forms = {str(r) for r in roots} | {str(Path(r).resolve()) for r in roots}
    for folder in folders:
        for p, text in _texts(folder):
            for f in forms:
                assert f not in text, f"{p} holds the absolute path {f}"


def _identified(folder: Path) -> dict:
    return {p["name"]: p["identified"] for p in json.loads((folder / "report.json").read_text())["parameters"]}


def _check_model(folder: Path):
    robot = load_calibrated_model(folder / "calibrated_model.yaml")
    ident = _identified(folder)
    got = robot.params.values()
    assert set(ident) <= set(got)
    np.testing.assert_allclose([got[n] for n in ident], [ident[n] for n in ident], rtol=0, atol=1e-12)


def test_simulate_and_process_folders_move_whole(tmp_path):
    work, user = tmp_path / "work", tmp_path / "user"
    scene = _user_scene(user)
    assert main(["simulate", str(scene), "--poses", "12", "--frames", "1", "--seed", "3", "--workers", "1",
                 "--json", "--no-plots", "--out", str(work / "sim"), "--export-recording", str(work / "rec")]) == 0
    rec_doc = yaml.safe_load((work / "rec" / "recording.yaml").read_text())
    assert not Path(rec_doc["scene"]).is_absolute() and not rec_doc["scene"].startswith("..")
    assert not Path(yaml.safe_load((work / "sim" / "calibrated_model.yaml").read_text())["robot"]).is_absolute()

    # move the results and the recording far away, and the user's scene files out of reach
    far = tmp_path / "elsewhere" / "deeper"
    far.mkdir(parents=True)
    shutil.move(str(work / "sim"), str(far / "sim"))
    shutil.move(str(work / "rec"), str(far / "rec"))
    shutil.move(str(user), str(tmp_path / "gone"))
    _check_model(far / "sim")
    # the moved recording processes without --allow-path and gives the simulation's parameters
    assert main(["process", str(far / "rec"), "--out", str(work / "proc"), "--json", "--no-plots"]) == 0
    sim, proc = _identified(far / "sim"), _identified(work / "proc")
    for n, v in sim.items():
        assert abs(proc[n] - v) <= 1e-9 * max(1.0, abs(v)), n
    shutil.move(str(work / "proc"), str(far / "proc"))
    _check_model(far / "proc")
    _no_written_path([far], tmp_path, work, user)


def test_the_copied_scene_is_the_scene(tmp_path):
    """copy_scene_bundle's copy loads to the same robot, mount, camera, target, truth, free parameters and
    identification settings as the original, from a folder that names no file outside it."""
    from vision_calib.io.portable import copy_scene_bundle
    from vision_calib.targets import load_target

    orig = load_scene(_user_scene(tmp_path / "user"))
    copy = load_scene(copy_scene_bundle(orig, tmp_path / "bundle"))
    assert copy.path.parent == tmp_path / "bundle" and copy.name == orig.name == "my_cell"
    a, b = orig.setup, copy.setup
    assert (a.kind, a.mount, a.params.names, a.camera) == (b.kind, b.mount, b.params.names, b.camera)
    np.testing.assert_array_equal(a.params.nominal, b.params.nominal)
    np.testing.assert_array_equal(a.params.free, b.params.free)
    assert load_target(copy.target_path) == load_target(orig.target_path)
    assert (copy.truth, copy.identification, copy.measurement) == (orig.truth, orig.identification, orig.measurement)
    for p in (tmp_path / "bundle").rglob("*.yaml"):  # all inside the bundle, none named absolutely
        assert str(tmp_path) not in p.read_text()


def test_measured_pose_file_names_its_scene_relatively_and_moves(tmp_path):
    """A measured-pose file written next to its scene names it relatively: the folder moves whole."""
    scene = load_scene(_user_scene(tmp_path / "mp"))
    q = np.random.default_rng(0).normal(scale=0.3, size=(6, 6))
    T = scene.setup.T_cam_target(q, scene.setup.params.nominal)
    p = write_measured_poses(tmp_path / "mp" / "m.yaml", scene.path, [f"p{i}" for i in range(6)], q, T,
                             "T_cam_target", default_sigma=(1e-4, 3e-4), folds=2)
    assert yaml.safe_load(p.read_text())["scene"] == "my_cell.yaml"
    shutil.move(str(tmp_path / "mp"), str(tmp_path / "moved"))
    mp = read_measured_poses(tmp_path / "moved" / "m.yaml")
    assert mp.scene.name == "my_cell" and mp.scene.path.parent == tmp_path / "moved"
    np.testing.assert_allclose(mp.T_meas, T, rtol=0, atol=1e-12)
    _no_written_path([tmp_path / "moved"], tmp_path / "mp")


if __name__ == "__main__":
    pytest.main([__file__, "-q"])
