"""Test helper: a 6R arm as URDF text and a measured-pose cell on it (the hostile-URDF tests and the fuzz suite)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: per-axis noise of the simulated measured poses [m, rad]
ST, SR = 1e-4, float(np.radians(0.02))
_H = float(np.pi / 2)


def joints(right: float = _H) -> list:
    """(xyz [m], rpy [rad]) of the six revolute joints, their right angles written as ``right``."""
    return [([0, 0, 0.30], [0, 0, 0]), ([0, 0.12, 0], [-right, 0, 0]), ([0.40, 0, 0], [0, 0, 0]),
            ([0.05, -0.35, 0], [right, 0, 0]), ([0, 0, 0], [-right, 0, 0]), ([0, 0.09, 0], [right, 0, 0])]


JOINTS = joints()


def urdf_text(meshes=(), extra="", flange_xyz="0 0 0.02", j3_parent=True, right: float = _H) -> str:
    """A 6R arm base_link -> l1..l6 -> tool0 (fixed flange joint at ``flange_xyz``), each link with
    <mesh filename=...> visual and collision geometry taken in turn from ``meshes`` (none: bare links); ``extra``
    XML appended inside <robot>; ``j3_parent`` False drops joint j3's parent; ``right``: how its right angles
    are written (CAD exports round pi / 2)."""
    links = ["base_link", *(f"l{i}" for i in range(1, 7)), "tool0"]
    out = ['<?xml version="1.0"?>', '<robot name="arm6">']
    for k, lk in enumerate(links):
        m = meshes[k % len(meshes)] if meshes else None
        geo = f'<geometry><mesh filename="{m}" scale="1 1 1"/></geometry>' if m else ""
        out.append(f'  <link name="{lk}"><visual>{geo}</visual><collision>{geo}</collision></link>' if m
                   else f'  <link name="{lk}"/>')
    for i, (xyz, rpy) in enumerate(joints(right), 1):
        par = f'<parent link="{links[i - 1]}"/>' if j3_parent or i != 3 else ""
        out.append(f'  <joint name="j{i}" type="revolute">{par}<child link="l{i}"/>'
                   f'<origin xyz="{" ".join(map(str, xyz))}" rpy="{" ".join(map(str, rpy))}"/><axis xyz="0 0 1"/>'
                   '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>')
    out.append(f'  <joint name="flange" type="fixed"><parent link="l6"/><child link="tool0"/>'
               f'<origin xyz="{flange_xyz}" rpy="0 0 0"/></joint>')
    return "\n".join(out + [extra, "</robot>"]) + "\n"


def measured_pose_cell(d: Path, meshes=(), n: int = 30, right: float = _H) -> Path:
    """Write ``d``/arm.urdf (:func:`urdf_text` with ``meshes`` and ``right``) and ``d``/m.yaml: a process-poses file of n
    eye-in-hand poses of that arm (seeded joints, true T_cam_target perturbed by ST / SR per axis). Returns the
    m.yaml path."""
    from vision_calib import frames as F
    from vision_calib.config import Section
    from vision_calib.experiment.steps import scene_truth
    from vision_calib.io.measured_poses_writer import write_measured_poses
    from vision_calib.rig.scene import scene_from_section

    d.mkdir(parents=True, exist_ok=True)
    (d / "arm.urdf").write_text(urdf_text(meshes=meshes, right=right))
    scene = {"robot": "arm.urdf", "mount": "eye_in_hand",
             "mounts": {"target_in_base": {"xyz": [0.6, 0.0, -0.1], "rpy": [180.0, 0.0, 0.0]},
                        "camera_in_flange": {"xyz": [0.0, 0.05, 0.08], "rpy": [0.0, 0.0, 90.0]}}}
    sc = scene_from_section(Section(scene, d / "m.yaml", "scene"))
    rng = np.random.default_rng(3)
    q = sc.setup.sample_poses(rng, n, check_view=False)
    dd = np.concatenate([rng.normal(scale=ST, size=(n, 3)), rng.normal(scale=SR, size=(n, 3))], axis=1)
    T = F.perturb_pose(sc.setup.T_cam_target(q, scene_truth(sc)), dd)
    return write_measured_poses(d / "m.yaml", scene, [f"p{i:02d}" for i in range(n)], q, T, "T_cam_target",
                                units={"length": "mm", "angle": "deg"}, default_sigma=(ST, SR))
