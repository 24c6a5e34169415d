"""Hostile URDF files (kinematics/urdf_file.py; issue 28): a joint closing a cycle, an origin with 4 numbers and a
joint without a parent are named errors; mesh filenames pointing anywhere (/etc/passwd, ../../../../etc/shadow,
file://, package://x/../..) are never stat()ed nor opened -- reading the URDF, identifying the robot and exporting
the calibrated URDF copy the XML text only (every filesystem entry point of this process is watched here)."""

from __future__ import annotations

import builtins
import io
import os
from pathlib import Path

import numpy as np
import pytest

from vision_calib import frames as F
from vision_calib.cli import main
from vision_calib.config import Section
from vision_calib.errors import ConfigError
from vision_calib.experiment.steps import scene_truth
from vision_calib.io.measured_poses import write_measured_poses
from vision_calib.kinematics.urdf_file import read_urdf
from vision_calib.rig.scene import scene_from_section

ST, SR = 1e-4, float(np.radians(0.02))
JOINTS = [([0, 0, 0.30], [0, 0, 0]), ([0, 0.12, 0], [-np.pi / 2, 0, 0]), ([0.40, 0, 0], [0, 0, 0]),
          ([0.05, -0.35, 0], [np.pi / 2, 0, 0]), ([0, 0, 0], [-np.pi / 2, 0, 0]), ([0, 0.09, 0], [np.pi / 2, 0, 0])]
HOSTILE = ("/etc/passwd", "../../../../etc/shadow", "file:///etc/passwd", "package://x/../../../../etc/passwd",
           "/nonexistent_vc_mesh/arm.stl", "package://vc_robot/meshes/../../../../nonexistent_vc_mesh.dae")
MARKERS = ("passwd", "shadow", "nonexistent_vc_mesh", "package:", "file:")


def urdf_text(meshes=HOSTILE, extra="", flange_xyz="0 0 0.02", j3_parent=True) -> str:
    links = ["base_link", *(f"l{i}" for i in range(1, 7)), "tool0"]
    out = ['<?xml version="1.0"?>', '<robot name="arm6">']
    for k, lk in enumerate(links):
        m = meshes[k % len(meshes)] if meshes else None
        geo = f'<geometry><mesh filename="{m}" scale="1 1 1"/></geometry>' if m else ""
        out.append(f'  <link name="{lk}"><visual>{geo}</visual><collision>{geo}</collision></link>' if m
                   else f'  <link name="{lk}"/>')
    for i, (xyz, rpy) in enumerate(JOINTS, 1):
        par = f'<parent link="{links[i - 1]}"/>' if j3_parent or i != 3 else ""
        out.append(f'  <joint name="j{i}" type="revolute">{par}<child link="l{i}"/>'
                   f'<origin xyz="{" ".join(map(str, xyz))}" rpy="{" ".join(map(str, rpy))}"/><axis xyz="0 0 1"/>'
                   '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>')
    out.append(f'  <joint name="flange" type="fixed"><parent link="l6"/><child link="tool0"/>'
               f'<origin xyz="{flange_xyz}" rpy="0 0 0"/></joint>')
    return "\n".join(out + [extra, "</robot>"]) + "\n"


@pytest.mark.parametrize("kw,msg", [
    ({"extra": '<joint name="loop" type="fixed"><parent link="tool0"/><child link="base_link"/></joint>'},
     r"arm.urdf: the links must form one tree with one root link, found 0 root links \(none: the joints .* form a loop\)"),
    ({"flange_xyz": "0 0 0.02 1"}, r"arm.urdf: joint 'flange': origin xyz='0 0 0.02 1' must hold exactly 3 numbers, got 4"),
    ({"j3_parent": False}, r"arm.urdf: joint 'j3': needs <parent link=...>"),
])
def test_hostile_structure_is_named(tmp_path, kw, msg):
    (tmp_path / "arm.urdf").write_text(urdf_text(**kw))
    with pytest.raises(ConfigError, match=msg):
        read_urdf(tmp_path / "arm.urdf")


class Touches:
    """Every path this process stats, opens or lists while active, when it carries one of MARKERS."""

    def __init__(self, monkeypatch):
        self.seen = []
        for mod, name in ((os, "stat"), (os, "lstat"), (os, "open"), (os, "listdir"), (os, "scandir"),
                          (os, "access"), (builtins, "open"), (io, "open")):
            real = getattr(mod, name)
            monkeypatch.setattr(mod, name, self._wrap(real, name))

    def _wrap(self, real, name):
        def f(path=".", *a, **k):
            text = os.fsdecode(path) if isinstance(path, (str, bytes, os.PathLike)) else ""
            if any(m in text for m in MARKERS):
                self.seen.append((name, text))
            return real(path, *a, **k)
        return f


def test_mesh_paths_are_never_touched_by_reading_identifying_or_exporting(tmp_path, monkeypatch, capsys):
    d = tmp_path / "cell"
    d.mkdir()
    (d / "arm.urdf").write_text(urdf_text())
    scene = {"robot": "arm.urdf", "mount": "eye_in_hand",
             "mounts": {"target_in_base": {"xyz": [0.6, 0.0, -0.1], "rpy": [180.0, 0.0, 0.0]},
                        "camera_in_flange": {"xyz": [0.0, 0.05, 0.08], "rpy": [0.0, 0.0, 90.0]}}}
    sc = scene_from_section(Section(scene, d / "m.yaml", "scene"))
    rng = np.random.default_rng(3)
    q = sc.setup.sample_poses(rng, 30, check_view=False)
    dd = np.concatenate([rng.normal(scale=ST, size=(30, 3)), rng.normal(scale=SR, size=(30, 3))], axis=1)
    T = F.perturb_pose(sc.setup.T_cam_target(q, scene_truth(sc)), dd)
    p = write_measured_poses(d / "m.yaml", scene, [f"p{i:02d}" for i in range(30)], q, T, "T_cam_target",
                             units={"length": "mm", "angle": "deg"}, default_sigma=(ST, SR))
    touches = Touches(monkeypatch)
    code = main(["process-poses", str(p), "--out", str(tmp_path / "out"), "--no-plots"])
    code_init = main(["init", str(tmp_path / "new_cell"), "--urdf", str(d / "arm.urdf")])
    monkeypatch.undo()
    assert code == 0 and code_init == 0, capsys.readouterr().err
    assert touches.seen == []
    text = (tmp_path / "out" / "calibrated_model.urdf").read_text()
    assert all(text.count(f'filename="{m}"') == 2 * sum(1 for k in range(8) if HOSTILE[k % len(HOSTILE)] == m)
               for m in HOSTILE)  # the mesh elements copied as text, unchanged
    assert Path(tmp_path / "new_cell" / "scene.yaml").is_file()


def test_the_watch_sees_what_it_should(tmp_path, monkeypatch):
    """The watch above is not blind: opening or stat()ing a marked path is recorded."""
    touches = Touches(monkeypatch)
    for f in (lambda: os.stat("/nonexistent_vc_mesh"), lambda: open("/etc/passwd").close(),
              lambda: Path("/nonexistent_vc_mesh/x").exists()):
        try:
            f()
        except OSError:
            pass
    monkeypatch.undo()
    assert [n for n, _ in touches.seen] == ["stat", "open", "stat"]
