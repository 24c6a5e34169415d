"""Test helper: a joint-set recording rewritten as a flange-pose recording (hand-eye path of ``process``)."""

import shutil
from pathlib import Path

import numpy as np
import yaml

from vision_calib import frames as F
from vision_calib.experiment.steps import scene_truth
from vision_calib.io.recording import read_recording
from vision_calib.rig import load_scene


def flange_pose_folder(rec_dir, dst, robot_std_mm: float = 0.0, robot_std_deg: float = 0.0, seed: int = 0,
                       declare_std: bool = False):
    """Copy the recording ``rec_dir`` (joints, simulated) to ``dst`` with flange poses instead of joints: the TRUE
    T_base_flange of each pose (``chain.flange(q, x_true)``, the arm alone, the truth the images were rendered
    with), perturbed by a robot pose error of std robot_std_mm per translation axis and robot_std_deg per
    rotation axis (``frames.perturb_pose``, seeded), same images, camera and target, no scene. declare_std:
    write those std as recording.yaml ``robot_pose_std`` (else absent: estimated by ``process``).
    Returns (dst Path, the source Recording, T_base_flange written (N, 4, 4))."""
    rec_dir, dst = Path(rec_dir), Path(dst)
    rec = read_recording(rec_dir)
    scene = load_scene(rec.scene_path)
    T = scene.setup.chain.flange(rec.poses, scene_truth(scene))
    rng = np.random.default_rng(seed)
    n = len(T)
    d = np.concatenate([rng.normal(scale=robot_std_mm * 1e-3, size=(n, 3)),
                        rng.normal(scale=np.radians(robot_std_deg), size=(n, 3))], axis=1)
    T = F.perturb_pose(T, d)
    shutil.copytree(rec_dir / "images", dst / "images")
    doc = yaml.safe_load((rec_dir / "recording.yaml").read_text())
    doc = {k: v for k, v in doc.items() if k not in ("scene", "scene_name")} | {"poses": "flange_pose"}
    if declare_std:
        doc["robot_pose_std"] = {"translation_mm": float(robot_std_mm), "rotation_deg": float(robot_std_deg)}
    (dst / "recording.yaml").write_text(yaml.safe_dump(doc))
    xyz, q = F.xyz_quat_from_T(T)
    (dst / "poses.csv").write_text("pose_id,x,y,z,qx,qy,qz,qw\n" + "".join(
        ",".join([pid] + [repr(float(v)) for v in (*a, *b)]) + "\n" for pid, a, b in zip(rec.pose_ids, xyz, q)))
    return dst, rec, T


def true_mounts(rec_dir) -> dict:
    """{name: (4, 4)} true mounting transforms of a simulated joint recording, named as the hand-eye report's
    ``transforms`` (eye_in_hand: T_flange_cam, T_cam_flange, T_base_target, T_target_base; fixed: T_cam_base,
    T_base_cam, T_flange_target, T_target_flange)."""
    rec = read_recording(rec_dir)
    scene = load_scene(rec.scene_path)
    chain = scene.setup.chain
    TL, TR = chain.nominal_transforms(scene_truth(scene))
    names = (chain.left, chain.right)
    out = {names[0]: TL, names[1]: TR}
    inv = {"T_target_base": "T_base_target", "T_flange_cam": "T_cam_flange", "T_cam_base": "T_base_cam",
           "T_flange_target": "T_target_flange"}
    out.update({inv[k]: F.inv_T(v) for k, v in list(out.items())})
    return out


def assert_mounts_within_std(transforms: dict, truth: dict, k: float = 4.0):
    """Every mount of a hand-eye report's ``transforms`` within k of its reported std of the truth, per component
    (``frames.pose_error`` convention: translation m, small rotation about the parent's axes). Returns the
    largest |z|."""
    zmax = 0.0
    for name, d in transforms.items():
        e = F.pose_error(truth[name], np.array(d["matrix"]))
        s = np.r_[d["std_xyz_m"], np.radians(d["std_rot_deg"])]
        z = e / s
        assert np.all(np.abs(z) < k), (name, z, e, s)
        zmax = max(zmax, float(np.abs(z).max()))
    return zmax


def measured_pose_file(path, scene_path, n: int = 30, seed: int = 8, folds: int = 3):
    """Write a ``process-poses`` file at ``path`` for the scene ``scene_path``: n random joint sets and their
    true T_cam_target perturbed by 0.1 mm / 0.3 mrad per axis (declared as the file's default sigma), seeded."""
    from vision_calib.experiment.steps import rngs
    from vision_calib.io.measured_poses_writer import write_measured_poses
    from vision_calib.rig import scene_poses

    scene = load_scene(scene_path)
    rp, rn, _ = rngs(seed)
    q = scene_poses(scene, rp, n)
    noise = np.concatenate([rn.normal(scale=1e-4, size=(n, 3)), rn.normal(scale=3e-4, size=(n, 3))], axis=1)
    T = F.perturb_pose(scene.setup.T_cam_target(q, scene_truth(scene)), noise)
    return write_measured_poses(path, scene_path, [f"p{i:02d}" for i in range(n)], q, T, "T_cam_target",
                                default_sigma=(1e-4, 3e-4), folds=folds)


def simulated_flange_recording(d, seed: int, n_poses: int, robot_std_mm: float, robot_std_deg: float,
                               flange_seed: int, scene: str = "scenes/rx90_eye_in_hand.yaml"):
    """A simulated eye-in-hand recording of ``scene`` (one frame per pose, no plots) under ``d``/rec, rewritten as a
    flange-pose recording ``d``/flange with a robot pose error (:func:`flange_pose_folder`, estimated by
    ``process``); returns the flange folder."""
    from vision_calib.experiment.simulate import run_simulation

    d = Path(d)
    run_simulation(scene, out_dir=d / "sim", seed=seed, n_poses=n_poses, frames=1, export_recording=d / "rec",
                   workers=2, plots=False, reference=False)
    folder, _, _ = flange_pose_folder(d / "rec", d / "flange", robot_std_mm=robot_std_mm, robot_std_deg=robot_std_deg,
                                      seed=flange_seed)
    return folder
