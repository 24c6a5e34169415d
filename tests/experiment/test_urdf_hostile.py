"""Hostile URDF files (kinematics/urdf_file.py; issue 28): a joint closing a cycle, an origin with 4 numbers and a
joint without a parent are named errors; mesh filenames pointing anywhere (/etc/passwd, ../../../../etc/shadow,
file://, package://x/../..) are never stat()ed nor opened -- reading the URDF, identifying the robot and exporting
the calibrated URDF copy the XML text only (every filesystem entry point of this process is watched here)."""

from __future__ import annotations

import builtins
import io
import os
from pathlib import Path

import pytest

from urdf_arm import measured_pose_cell
from urdf_arm import urdf_text as arm_urdf

from vision_calib.cli import main
from vision_calib.errors import ConfigError
from vision_calib.kinematics.urdf_file import read_urdf

HOSTILE = ("/etc/passwd", "../../../../etc/shadow", "file:///etc/passwd", "package://x/../../../../etc/passwd",
           "/nonexistent_vc_mesh/arm.stl", "package://vc_robot/meshes/../../../../nonexistent_vc_mesh.dae")
MARKERS = ("passwd", "shadow", "nonexistent_vc_mesh", "package:", "file:")


def urdf_text(meshes=HOSTILE, **kw) -> str:
    return arm_urdf(meshes=meshes, **kw)


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
    p = measured_pose_cell(d, HOSTILE)
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


def test_right_angles_rounded_in_the_urdf_identify_as_exact_ones(tmp_path):
    """A URDF whose right angles are written 1.5707963 (CAD exports round pi / 2): the same identifiable base
    set as with exact right angles (no nearly dependent column in it), and process-poses converges in every
    held-out fold (before: the base took j2.y, j2.ry, ... and every fold hit the evaluation limit)."""
    import json

    import numpy as np

    bases = {}
    for right in (float(np.pi / 2), 1.5707963):
        d = tmp_path / f"r{right}"
        p = measured_pose_cell(d / "cell", right=right)
        assert main(["process-poses", str(p), "--out", str(d / "out"), "--no-plots"]) == 0
        rep = json.loads((d / "out" / "report.json").read_text())
        assert all(f.get("converged", True) for f in rep["holdout"]["per_fold"]), rep["holdout"]["per_fold"]
        bases[right] = rep["identifiability"]["base_parameters"]
    assert len(set(map(tuple, bases.values()))) == 1, bases
