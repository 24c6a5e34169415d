"""Test helper: a joint-set recording rewritten as a flange-pose recording (hand-eye path of ``process``)."""

import shutil
from pathlib import Path

import yaml

from vision_calib import frames as F
from vision_calib.io.recording import read_recording
from vision_calib.rig import load_scene


def flange_pose_folder(rec_dir, dst):
    """Copy the recording ``rec_dir`` (joints) to ``dst`` with flange poses instead of joints: T_base_flange
    from the scene's nominal forward kinematics (what a robot controller reports), same images, camera and
    target, no scene. Returns (dst Path, the source Recording, T_base_flange (N, 4, 4))."""
    rec_dir, dst = Path(rec_dir), Path(dst)
    rec = read_recording(rec_dir)
    setup = load_scene(rec.scene_path).setup
    T = setup.chain.forward(rec.poses, setup.params.nominal)
    shutil.copytree(rec_dir / "images", dst / "images")
    doc = yaml.safe_load((rec_dir / "recording.yaml").read_text())
    doc = {k: v for k, v in doc.items() if k not in ("scene", "scene_name")} | {"poses": "flange_pose"}
    (dst / "recording.yaml").write_text(yaml.safe_dump(doc))
    xyz, q = F.xyz_quat_from_T(T)
    (dst / "poses.csv").write_text("pose_id,x,y,z,qx,qy,qz,qw\n" + "".join(
        ",".join([pid] + [repr(float(v)) for v in (*a, *b)]) + "\n" for pid, a, b in zip(rec.pose_ids, xyz, q)))
    return dst, rec, T
