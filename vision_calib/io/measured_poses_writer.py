"""Writing measured-pose files (the format: :mod:`.measured_poses`, which reads them): a joint file (YAML + CSV of
joint readings and measured poses, :func:`write_measured_poses`) and a pose-pair file (YAML + measured-pose CSV +
flange-pose CSV, :func:`write_pose_pairs`). All writes atomic."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import frames as F
from ..config import ANGLE_UNITS, LENGTH_UNITS
from .measured_poses import COMPONENTS, FORMAT, POSE_COLS


def write_pose_pairs(yaml_path, ids, T_base_flange, T, mount: str, measured: str = "T_cam_target", units=None,
                     sigmas=None, default_sigma=None, noise_frame: str | None = None, robot_pose_std=None,
                     folds: int = 5, seed: int = 0) -> Path:
    """Write a pose-pair YAML, its measured-pose CSV (``<stem>.csv``) and its flange-pose CSV
    (``<stem>_flange.csv``). T_base_flange, T: (N, 4, 4) [m] (T: rows of ``measured``); units {length, angle} of
    the CSVs (default m, deg); sigmas (N, 6) per-component std [m, rad] or default_sigma (t m, r rad) or neither
    (noise estimated, per axis of ``noise_frame``); robot_pose_std (translation m, rotation rad) or None."""
    import yaml

    from ..serialize import write_text_atomic

    yaml_path = Path(yaml_path)
    units = units or {"length": "m", "angle": "deg"}
    Lf, Af = LENGTH_UNITS[units["length"]], ANGLE_UNITS[units["angle"]]

    def pose_lines(TT, extra_head=(), extra=None):
        xyz, quat = F.xyz_quat_from_T(np.asarray(TT, float))
        vals = np.column_stack([xyz / Lf, quat] + ([extra] if extra is not None else []))
        out = [",".join(["pose_id", *POSE_COLS, *extra_head])]
        return out + [",".join([str(pid)] + [repr(float(x)) for x in row]) for pid, row in zip(ids, vals)]

    unit = np.array([Lf] * 3 + [Af] * 3)
    head = [f"sigma_{c}" for c in COMPONENTS] if sigmas is not None else []
    csv_path, flange_path = yaml_path.with_suffix(".csv"), yaml_path.with_name(yaml_path.stem + "_flange.csv")
    write_text_atomic(csv_path, "\n".join(pose_lines(T, head, None if sigmas is None else
                                                       np.asarray(sigmas, float) / unit)) + "\n")
    write_text_atomic(flange_path, "\n".join(pose_lines(T_base_flange)) + "\n")
    doc = {"format": FORMAT, "flange_poses": flange_path.name, "mount": mount, "csv": csv_path.name,
           "units": dict(units), "measured": measured, "folds": int(folds), "seed": int(seed)}
    if default_sigma is not None:
        doc["default_sigma"] = {"t_mm": float(default_sigma[0]) * 1e3, "r_deg": float(np.degrees(default_sigma[1]))}
    if noise_frame is not None:
        doc["noise_frame"] = noise_frame
    if robot_pose_std is not None:
        doc["robot_pose_std"] = {"translation_mm": float(robot_pose_std[0]) * 1e3,
                                 "rotation_deg": float(np.degrees(robot_pose_std[1]))}
    write_text_atomic(yaml_path, yaml.safe_dump(doc, sort_keys=False))
    return yaml_path


def _scene_ref(scene_path, yaml_path: Path) -> str:
    """The ``scene`` entry of a measured-pose YAML: a relative ``scene_path`` as given (the reader takes it
    relative to the YAML's folder), an absolute one made relative to that folder (io.portable); no copy: a
    scene outside the folder and the shipped scenes stays refused on reading (config.confine)."""
    from .portable import relative_ref

    p = Path(scene_path)
    return p.as_posix() if not p.is_absolute() else relative_ref(p, yaml_path.parent)


def write_measured_poses(yaml_path, scene_path, ids, q, T, measured: str, units=None, sigmas=None, cov=None,
                         default_sigma=None, folds: int = 5, seed: int = 0) -> Path:
    """Write a measured-pose YAML + CSV (``<yaml stem>.csv``). q: (N, n) joints [rad]; T: (N, 4, 4) rows of
    ``measured`` [m] (position-only: translations used); units: {length, angle} of the CSV (default m,
    rad); one of sigmas (N, m) per-component std [m, rad], cov (N, m, m) SI, or default_sigma
    (t [m], r [rad]) written to the YAML. The scene is named relative to the YAML (:func:`_scene_ref`), or
    written in it when ``scene_path`` is a mapping (:data:`.measured_poses.INLINE_SCENE_KEYS`)."""
    import yaml

    from ..serialize import write_text_atomic

    yaml_path = Path(yaml_path)
    units = units or {"length": "m", "angle": "rad"}
    Lf, Af = LENGTH_UNITS[units["length"]], ANGLE_UNITS[units["angle"]]
    pos_only = measured.startswith("p_")
    m = 3 if pos_only else 6
    unit = np.array([Lf] * 3 + [Af] * 3)[:m]
    q, T = np.asarray(q, float), np.asarray(T, float)
    head = [f"q{j + 1}" for j in range(q.shape[1])]
    cols = [q / Af]
    xyz, quat = F.xyz_quat_from_T(T)
    head += list(POSE_COLS[:3] if pos_only else POSE_COLS)
    cols += [xyz / Lf] if pos_only else [xyz / Lf, quat]
    comps = COMPONENTS[:m]
    if sigmas is not None:
        head += [f"sigma_{c}" for c in comps]
        cols.append(np.asarray(sigmas, float) / unit)
    if cov is not None:
        C = np.asarray(cov, float) / np.outer(unit, unit)
        iu = np.triu_indices(m)
        head += [f"cov_{comps[i]}_{comps[j]}" for i, j in zip(*iu)]
        cols.append(C[:, iu[0], iu[1]])
    vals = np.column_stack(cols)
    lines = [",".join(["pose_id"] + head)]
    lines += [",".join([str(pid)] + [repr(float(x)) for x in row]) for pid, row in zip(ids, vals)]
    csv_path = yaml_path.with_suffix(".csv")
    write_text_atomic(csv_path, "\n".join(lines) + "\n")
    scene = dict(scene_path) if isinstance(scene_path, dict) else _scene_ref(scene_path, yaml_path)
    doc = {"format": FORMAT, "scene": scene, "csv": csv_path.name, "units": dict(units),
           "measured": measured, "folds": int(folds), "seed": int(seed)}
    if default_sigma is not None:
        doc["default_sigma"] = {"t_mm": float(default_sigma[0]) * 1e3} | (
            {} if pos_only else {"r_deg": float(np.degrees(default_sigma[1]))})
    write_text_atomic(yaml_path, yaml.safe_dump(doc, sort_keys=False))
    return yaml_path


__all__ = ["write_measured_poses", "write_pose_pairs"]
