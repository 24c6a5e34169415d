"""Measured poses without images: joint readings + measured target/camera poses (or positions) from
any pose logger, for ``vision-calib process-poses`` (format: ``vision-calib docs measured_poses``).

Two files: a YAML description and a CSV with one row per robot pose::

    # measured_poses.yaml
    format: vision_calib.measured_poses/1
    scene: ../scenes/rx90_eye_in_hand.yaml   # robot + mounts + free parameters (relative to this file),
                                             # or the scene itself, with only the keys read here:
                                             # {robot: arm.urdf, mount: eye_in_hand, mounts: {..}, [urdf: {..}],
                                             #  [units], [identification], [name]}   (INLINE_SCENE_KEYS)
    csv: measured_poses.csv                  # default: this file's name with .csv
    units: {length: mm, angle: deg}          # REQUIRED: of the CSV (joints, positions, sigmas, covariances)
    measured: T_cam_target                   # T_cam_target | T_target_cam | p_cam_target | p_target_cam
    default_sigma: {t_mm: 0.1, r_deg: 0.02}  # REQUIRED when the CSV has no sigma/covariance columns
    folds: 5                                 # k-fold held-out validation (>= 2)
    seed: 0                                  # of the fold split

    # measured_poses.csv (columns matched by header name, any order)
    pose_id,q1,..,qn,x,y,z,qx,qy,qz,qw[,sigma columns]   # full pose, quaternion scalar last
    pose_id,q1,..,qn,x,y,z[,sigma columns]               # position only (measured: p_*)

Pose pairs (hand-eye without images: flange poses known, the robot model plays no part)::

    format: vision_calib.measured_poses/1
    flange_poses: pairs_flange.csv           # pose_id,x,y,z,qx,qy,qz,qw: T_base_flange (units.length, quaternion
                                             # scalar last), as a flange-pose recording's poses.csv; instead of scene
    mount: eye_in_hand                       # eye_in_hand (camera on the flange) | fixed (target on the flange)
    csv: pairs.csv                           # pose_id,x,y,z,qx,qy,qz,qw[,noise columns]: the measured T_cam_target
    units: {length: m, angle: deg}
    measured: T_cam_target                   # T_cam_target | T_target_cam (full poses only)
    default_sigma: {t_mm: .., r_deg: ..}     # optional here: without it and without noise columns the std per axis
    noise_frame: target                      # of the measured poses is estimated, per axis of this frame
                                             # (target | camera; default target: a tag's tilt and depth)
    robot_pose_std: {translation_mm: 0.1, rotation_deg: 0.01}   # optional: given; absent: estimated
    folds: 5
    seed: 0

:func:`read_measured_poses` gives a :class:`PosePairs` for such a file. Writing either kind of file:
:mod:`.measured_poses_writer`.

``T_a_b`` is the pose of frame b in frame a, ``p_a_b`` the position of frame b's origin in frame a.
Noise columns (one group): ``sigma_x,sigma_y,sigma_z[,sigma_rx,sigma_ry,sigma_rz]`` or
``sigma_t[,sigma_r]`` (isotropic) or the upper triangle ``cov_<i>_<j>`` of the covariance over
``x,y,z[,rx,ry,rz]``, all in the file's units. The pose noise convention is
``frames.pose_error``: translation error and small rotation (rotation vector of R_meas R_true^T) of
the named transform, both in its reference frame a. The reader maps rows and covariances to
``Measurements`` (T_cam_target, covariance in the camera frame) exactly (``frames.inverse_error_map``).
"""

from __future__ import annotations

import csv
import difflib
import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .. import frames as F
from ..config import ANGLE_UNITS, LENGTH_UNITS, Section, angle_key, length_key, load_yaml, read_text
from ..errors import DataError

if TYPE_CHECKING:  # annotations only
    from ..rig import Measurements, Scene

FORMAT = "vision_calib.measured_poses/1"
YAML_KEYS = ("format", "scene", "csv", "units", "measured", "default_sigma", "folds", "seed", "flange_poses", "mount",
             "noise_frame", "robot_pose_std")
#: the keys of a pose-pair file (``flange_poses`` instead of ``scene``), refused in a joint file
PAIR_KEYS = ("flange_poses", "mount", "noise_frame", "robot_pose_std")
PAIR_MOUNTS = ("eye_in_hand", "fixed")
#: frames of the estimated per-axis noise of pose pairs (``identify.handeye_fit.NOISE_FRAMES``)
NOISE_FRAMES = ("target", "camera")
#: a median measured distance below this [m] is metres declared as millimetres (a camera sees its target from afar)
MIN_MEDIAN_DISTANCE_M = 0.01
#: the keys of a scene written inside the file (``scene:`` a mapping): those process-poses reads
INLINE_SCENE_KEYS = ("name", "robot", "mount", "units", "mounts", "urdf", "identification")
MEASURED = ("T_cam_target", "T_target_cam", "p_cam_target", "p_target_cam")
POSE_COLS = ("x", "y", "z", "qx", "qy", "qz", "qw")
COMPONENTS = ("x", "y", "z", "rx", "ry", "rz")
#: measured sizes this many times larger/smaller than the nominal model's: a unit error
PLAUSIBLE_FACTOR = 5.0
#: plausible std of a measured pose component, SI: 1 nm - 1 m, 1 nrad - 1 rad (outside: a unit or typing
#: error; 1e-300 would underflow to a zero variance, 1e300 overflow)
SIGMA_RANGE = {"length": (1e-9, 1.0), "angle": (1e-9, 1.0)}


@dataclass(frozen=True)
class MeasuredPoses:
    """A validated measured-pose file. ``q``: (N, n) joint readings [rad]. ``T_meas``: (N, 4, 4) the
    rows as given (``measured``; position-only rows get an identity rotation) [m]. ``cov``: (N, m, m)
    noise of the rows in the file's direction, SI (m = 6 full pose, 3 position). ``measurements``:
    ``rig.Measurements`` (T_cam_target + camera-frame covariance) for the setup's problem.
    ``residual``: "position" for position-only rows, else the scene's."""

    path: Path
    csv_path: Path
    scene: Scene
    measured: str
    residual: str
    ids: tuple
    q: np.ndarray
    T_meas: np.ndarray
    cov: np.ndarray
    measurements: Measurements
    sigma_source: str
    units: dict
    folds: int
    seed: int

    @property
    def position_only(self) -> bool:
        return self.measured.startswith("p_")


@dataclass(frozen=True)
class PosePairs:
    """A validated pose-pair file (flange poses + measured poses, no robot model). ``T_base_flange`` (N, 4, 4) [m];
    ``T_cam_target`` (N, 4, 4) the measured poses in the camera convention [m] (``T_meas``: the rows as given,
    ``measured``); ``cov`` (N, 6, 6) their covariance in the camera convention [m, rad], or None: estimated per
    axis of ``noise_frame`` by the fit; ``robot_std``: (translation m, rotation rad) given, or None (estimated)."""

    path: Path
    csv_path: Path
    flange_path: Path
    mount: str
    measured: str
    ids: tuple
    T_base_flange: np.ndarray
    T_meas: np.ndarray
    T_cam_target: np.ndarray
    cov: np.ndarray | None
    sigma_source: str
    noise_frame: str | None
    robot_std: tuple | None
    units: dict
    folds: int
    seed: int


def _suggest(name: str, known) -> str:
    close = difflib.get_close_matches(name, list(known), n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def _only(sec: Section, known) -> Section:
    for k in sec.keys():
        if k not in known:
            raise sec.error(str(k), f"unknown key (known: {', '.join(known)}){_suggest(str(k), known)}")
    return sec


def _header(csv_path: Path, header: list[str], n_joints: int, position_only: bool) -> tuple[dict, str]:
    """{column: index} and the noise group ('sigma' | 'iso' | 'cov' | 'none') of a CSV header."""
    comps = COMPONENTS[:3] if position_only else COMPONENTS
    pose = ("x", "y", "z") if position_only else POSE_COLS
    groups = {"sigma": [f"sigma_{c}" for c in comps], "iso": ["sigma_t"] + ([] if position_only else ["sigma_r"]),
              "cov": [f"cov_{a}_{b}" for i, a in enumerate(comps) for b in comps[i:]]}
    joints = [f"q{j + 1}" for j in range(n_joints)]
    known = ["pose_id", *joints, *pose, *(c for g in groups.values() for c in g)]
    cols = {}
    for i, h in enumerate(header):
        if h in cols:
            raise DataError(f"{csv_path}: line 1: column {h!r} appears twice")
        if re.fullmatch(r"q\d+", h) and h not in joints:
            raise DataError(f"{csv_path}: line 1: column {h!r}: the scene's robot has {n_joints} joints "
                            f"(q1..q{n_joints}), the CSV has more joint columns")
        if h not in known:
            extra = " (measured: p_* is position only)" if position_only and h in POSE_COLS else ""
            raise DataError(f"{csv_path}: line 1: unknown column {h!r}{extra}{_suggest(h, known)}")
        cols[h] = i
    for need in ["pose_id", *joints, *pose]:
        if need not in cols:
            qs = f"{joints[0]}..{joints[-1]}, " if joints else ""
            raise DataError(f"{csv_path}: line 1: missing column {need!r} (need pose_id, {qs}{','.join(pose)})")
    present = [g for g, names in groups.items() if any(c in cols for c in names)]
    if len(present) > 1:
        raise DataError(f"{csv_path}: line 1: noise columns of two kinds ({' and '.join(present)}): give one")
    if present:
        miss = [c for c in groups[present[0]] if c not in cols]
        if miss:
            raise DataError(f"{csv_path}: line 1: missing noise column(s) {', '.join(miss)}")
    return cols, (present[0] if present else "none")


def _rows(csv_path: Path, n_joints: int, position_only: bool):
    """(ids, values {column: (N,) float in file units}, noise group, CSV line of each row) of the CSV."""
    text = read_text(csv_path, DataError)  # the one decoder: a named error on a non-UTF-8 byte, a BOM dropped
    rows = [(ln, r) for ln, r in enumerate(csv.reader(io.StringIO(text, newline="")), start=1)
            if r and any(c.strip() for c in r)]
    if len(rows) < 2:
        raise DataError(f"{csv_path}: no pose rows")
    header = [h.strip() for h in rows[0][1]]
    cols, group = _header(csv_path, header, n_joints, position_only)
    ids, vals = [], []
    for ln, r in rows[1:]:
        if len(r) != len(header):
            raise DataError(f"{csv_path}: line {ln}: {len(r)} values, expected {len(header)} ({','.join(header)})")
        pid = r[cols["pose_id"]].strip()
        v = []
        for name, i in cols.items():
            if name == "pose_id":
                continue
            try:
                x = float(r[i])
            except ValueError:
                raise DataError(f"{csv_path}: line {ln} (pose {pid!r}): column {name}: not a number ({r[i]!r})") from None
            if not np.isfinite(x):
                raise DataError(f"{csv_path}: line {ln} (pose {pid!r}): column {name}: NaN or infinite value")
            v.append(x)
        ids.append(pid)
        vals.append(v)
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise DataError(f"{csv_path}: duplicate pose ids {dup}")
    arr = np.array(vals, float)
    names = [c for c in cols if c != "pose_id"]
    return ids, {c: arr[:, k] for k, c in enumerate(names)}, group, [ln for ln, _ in rows[1:]]


def _sigma_range(csv_path, ids, lines, what: str, sd: np.ndarray, k_comp: int, unit_name: str, f: float) -> None:
    """DataError naming the file, line, pose id and column of a std (N,) SI outside SIGMA_RANGE (before any
    squaring: no overflow or underflow warning)."""
    lo, hi = SIGMA_RANGE["length" if k_comp < 3 else "angle"]
    bad = np.flatnonzero(~((sd >= lo) & (sd <= hi)))
    if bad.size:
        k = bad[0]
        raise DataError(f"{csv_path}: line {lines[k]} (pose {ids[k]!r}): {what}: std {sd[k] / f:.4g} {unit_name} is "
                        f"outside the plausible {lo / f:.3g}-{hi / f:.3g} {unit_name} (units in the YAML?)")


def _covariances(csv_path, ids, lines, v, group, m, Lf, Af, default, units) -> tuple[np.ndarray, str]:
    """(N, m, m) SI covariances of the rows from the noise columns (or the YAML default sigmas); every std
    within SIGMA_RANGE and every covariance positive definite, else DataError naming the row."""
    n = len(ids)
    unit = np.array([Lf] * 3 + [Af] * 3)[:m]
    uname = [units["length"]] * 3 + [units["angle"]] * 3
    comps = COMPONENTS[:m]
    if group == "none":
        s = np.array([default[0]] * 3 + [default[1]] * 3)[:m]
        return np.broadcast_to(np.diag(s**2), (n, m, m)).copy(), "default_sigma (measured_poses yaml)"
    if group == "cov":
        C = np.zeros((n, m, m))
        for i in range(m):
            name = f"cov_{comps[i]}_{comps[i]}"
            d = v[name]
            bad = np.flatnonzero(~(d > 0))
            if bad.size:
                k = bad[0]
                raise DataError(f"{csv_path}: line {lines[k]} (pose {ids[k]!r}): column {name}: a variance must be "
                                f"> 0, got {d[k]}")
            _sigma_range(csv_path, ids, lines, f"column {name}", np.sqrt(d) * unit[i], i, uname[i], unit[i])
        for i in range(m):
            for j in range(i, m):
                C[:, i, j] = C[:, j, i] = v[f"cov_{comps[i]}_{comps[j]}"] * unit[i] * unit[j]
        sd = np.sqrt(np.einsum("nii->ni", C))
        ev = np.linalg.eigvalsh(C / sd[:, :, None] / sd[:, None, :])[:, 0]  # of the correlation: unit-free
        bad = np.flatnonzero(~(ev > 1e-12))
        if bad.size:
            k = bad[0]
            raise DataError(f"{csv_path}: line {lines[k]} (pose {ids[k]!r}): cov_* columns: covariance is not "
                            "positive definite")
        return C, "csv cov_* columns"
    names = [f"sigma_{c}" for c in comps] if group == "sigma" else (["sigma_t"] * 3 + ["sigma_r"] * 3)[:m]
    for i, c in enumerate(names):
        bad = np.flatnonzero(~(v[c] > 0))
        if bad.size:
            k = bad[0]
            raise DataError(f"{csv_path}: line {lines[k]} (pose {ids[k]!r}): column {c}: sigma must be > 0, "
                            f"got {v[c][k]}")
        _sigma_range(csv_path, ids, lines, f"column {c}", v[c] * unit[i], i, uname[i], unit[i])
    S = np.column_stack([v[c] for c in names]) * unit
    return np.einsum("ni,ij->nij", S**2, np.eye(m)), f"csv {'sigma_*' if group == 'sigma' else 'sigma_t/sigma_r'} columns"


def _poses(csv_path, ids, lines, v, position_only: bool, Lf: float) -> np.ndarray:
    """(N, 4, 4) rows as transforms [m] (identity rotation for position-only rows)."""
    xyz = np.column_stack([v["x"], v["y"], v["z"]]) * Lf
    if position_only:
        return F.make_T(np.broadcast_to(np.eye(3), (len(ids), 3, 3)), xyz)
    quat = np.column_stack([v[c] for c in ("qx", "qy", "qz", "qw")])
    nq = np.linalg.norm(quat, axis=1)
    bad = np.flatnonzero(np.abs(nq - 1) > 1e-3)
    if bad.size:
        k = bad[0]
        raise DataError(f"{csv_path}: line {lines[k]} (pose {ids[k]!r}): columns qx,qy,qz,qw: quaternion norm "
                        f"{nq[k]:.6g} is not 1")
    return F.T_from_xyz_quat(xyz, quat / nq[:, None])


def chain_direction(setup) -> str:
    """The transform the setup's chain measures (its pose/position residuals live there)."""
    return "T_target_cam" if setup.mount == "eye_in_hand" else "T_cam_target"


def to_camera_convention(setup, measured: str, T, cov):
    """(T_cam_target (N, 4, 4), cov (N, 6, 6) camera frame) of rows ``T`` (N, 4, 4) of ``measured`` with
    covariances ``cov`` (N, m, m) in that direction. Position-only rows (m = 3) must be of the chain's
    own direction; their rotation gets a placeholder variance the position residual never reads."""
    T, cov = np.asarray(T, float), np.asarray(cov, float)
    if cov.shape[-1] == 3:
        full = np.zeros(cov.shape[:-2] + (6, 6))
        full[:, :3, :3] = cov
        full[:, 3:, 3:] = np.eye(3) * np.trace(cov, axis1=1, axis2=2)[:, None, None] / 3
        cov, measured = full, "T" + measured[1:]
    if measured == "T_cam_target":
        return T, cov
    G = F.inverse_error_map(T)
    return F.inv_T(T), G @ cov @ np.swapaxes(G, -1, -2)


def misreadings(mp: MeasuredPoses) -> dict:
    """{what: rig.Measurements} of the file's rows read as the usual mistakes would have written them: the
    other pose direction (full poses), two position columns swapped, a scalar-first quaternion; for the
    gross-error test (``experiment.gross``: which reading fits)."""
    from ..rig import Measurements

    setup, T, cov = mp.scene.setup, np.array(mp.T_meas, float), np.array(mp.cov, float)
    out = {}

    def add(what, measured, TT, CC):
        T_ct, cov_ct = to_camera_convention(setup, measured, TT, CC)
        out[what] = Measurements(mp.q, mp.q, T_ct, cov_ct, mp.ids)

    if not mp.position_only:
        other = {"T_cam_target": "T_target_cam", "T_target_cam": "T_cam_target"}[mp.measured]
        add(f"the rows read as {other} (measured: direction reversed)", other, T, cov)
    for a, b in ((0, 1), (0, 2), (1, 2)):
        perm = [0, 1, 2] + list(range(3, cov.shape[-1]))
        perm[a], perm[b] = b, a
        TT = T.copy()
        TT[:, [a, b], 3] = T[:, [b, a], 3]
        add(f"columns {'xyz'[a]} and {'xyz'[b]} swapped", mp.measured, TT, cov[:, perm][:, :, perm])
    if not mp.position_only:
        xyz, quat = F.xyz_quat_from_T(T)  # as read: (qx, qy, qz, qw) columns; scalar-first means (w, x, y, z)
        add("the quaternion written scalar first (qw,qx,qy,qz)", mp.measured,
            F.T_from_xyz_quat(xyz, quat[:, [1, 2, 3, 0]]), cov)
    return out


def _check_plausible(csv_path, setup, measured, q, T, units: dict) -> None:
    """DataError when the measured positions are many times larger/smaller than what the nominal model
    predicts for the same joints (a length unit error, e.g. mm declared as m)."""
    T_pred = setup.T_cam_target(q, setup.params.nominal)
    if measured[2:] == "target_cam":
        T_pred = F.inv_T(T_pred)
    meas = float(np.sqrt(np.mean(np.sum(T[:, :3, 3] ** 2, axis=1))))
    pred = float(np.sqrt(np.mean(np.sum(T_pred[:, :3, 3] ** 2, axis=1))))
    ratio = meas / max(pred, 1e-9)
    if not (1 / PLAUSIBLE_FACTOR <= ratio <= PLAUSIBLE_FACTOR):
        raise DataError(
            f"{csv_path}: columns x,y,z: the measured positions are {ratio:.3g} times the size the nominal model "
            f"predicts for these joints (RMS {meas:.4g} m vs {pred:.4g} m, read with units.length: "
            f"{units['length']}): wrong length unit in the YAML, or wrong scene/mounts?")


def _settings(top: Section):
    """(scene Path or inline scene Section, csv Path, Lf, Af, units, measured, default sigmas or None, folds, seed)."""
    _only(top, YAML_KEYS)
    fmt = top.get("format", str)
    if fmt != FORMAT:
        raise top.error("format", f"expected {FORMAT!r}, got {fmt!r}")
    for k in PAIR_KEYS:
        if k in top:
            raise top.error(k, "belongs to a pose-pair file (flange_poses instead of scene: vision-calib docs "
                               "measured_poses)")
    scene_path = top.section("scene") if isinstance(top.data.get("scene"), dict) else top.path_value("scene")
    csv_path = top.path_value("csv", None) or top.file.with_suffix(".csv")
    us = _only(top.section("units"), ("length", "angle"))
    units = {"length": us.get("length", str, choices=LENGTH_UNITS), "angle": us.get("angle", str, choices=ANGLE_UNITS)}
    measured = top.get("measured", str, choices=MEASURED)
    default = None
    if "default_sigma" in top:
        ds = _only(top.section("default_sigma"), ("t_m", "t_mm", "t_cm", "r_rad", "r_deg"))
        t = length_key(ds, "t")
        r = 0.0 if measured.startswith("p_") else angle_key(ds, "r")
        rkeys = [str(k) for k in ds.keys() if str(k).startswith("r_")]
        if measured.startswith("p_") and rkeys:
            raise ds.error(rkeys[0], "position-only measurements (measured: p_*) have no rotation sigma")
        if t <= 0 or (r <= 0 and not measured.startswith("p_")):
            raise ds.error(None, "sigmas must be > 0")
        for val, kind in ((t, "length"), (r, "angle")):
            lo, hi = SIGMA_RANGE[kind]
            if (val or lo) < lo or val > hi:
                raise ds.error(None, f"a {kind} std of {val:.4g} (SI) is outside the plausible {lo:g}-{hi:g}")
        default = (t, r)
    folds = top.get("folds", int, 5)
    if folds < 2:
        raise top.error("folds", f"expected an integer >= 2, got {folds}")
    seed = top.nonnegative("seed", int, 0)
    return (scene_path, csv_path, LENGTH_UNITS[units["length"]], ANGLE_UNITS[units["angle"]], units, measured,
            default, folds, seed)


def _load_scene(ref):
    """The scene of the ``scene`` entry: a scene file (its simulation keys allowed, unused here), or a mapping
    written in the file, which may hold only :data:`INLINE_SCENE_KEYS` (ConfigError naming every other key)."""
    from ..rig import load_scene
    from ..rig.scene import scene_from_section

    if not isinstance(ref, Section):
        return load_scene(ref)
    unused = [str(k) for k in ref.keys() if str(k) not in INLINE_SCENE_KEYS]
    if unused:
        hint = _suggest(unused[0], INLINE_SCENE_KEYS)
        raise ref.error(None, f"{', '.join(unused)}: not read by process-poses (a scene written here takes only "
                              f"{', '.join(INLINE_SCENE_KEYS)}; camera, target and simulation settings belong in a "
                              f"scene file){hint}")
    return scene_from_section(ref)


def read_measured_poses(path) -> MeasuredPoses | PosePairs:
    """Read and validate a measured-pose YAML + CSV (see the module docstring): a :class:`MeasuredPoses` (joints,
    ``scene``), or a :class:`PosePairs` for a file naming ``flange_poses``. ConfigError for the YAML, DataError for
    the CSV, each naming the file and the key / line / pose / column."""
    from ..rig import Measurements
    from ..rig.base import ChainMeasured

    path = Path(path)
    top = Section(load_yaml(path), path)
    if "flange_poses" in top:
        return _read_pose_pairs(top)
    scene_path, csv_path, Lf, Af, units, measured, default, folds, seed = _settings(top)
    scene = _load_scene(scene_path)
    setup = scene.setup
    if not isinstance(setup, ChainMeasured):
        raise top.error("scene", f"measured-pose files need a robot commanded by joint sets (serial, URDF); "
                                 f"{scene.path} is a {setup.kind} robot")
    pos_only = measured.startswith("p_")
    if pos_only and measured != "p" + chain_direction(setup)[1:]:
        raise top.error("measured", f"a {setup.mount} camera measures {'p' + chain_direction(setup)[1:]} "
                                    f"(position-only rows cannot be inverted without their rotation)")
    residual = "position" if pos_only else scene.identification.residual
    setup.check_residual(residual)
    ids, v, group, lines = _rows(csv_path, setup.n_joints, pos_only)
    if group == "none" and default is None:
        raise top.error("default_sigma", f"required: {csv_path.name} has no sigma_*/cov_* columns (no silent "
                                         "default noise)")
    if group != "none" and default is not None:
        raise top.error("default_sigma", f"{csv_path.name} has its own noise columns: remove one of the two")
    q = np.column_stack([v[f"q{j + 1}"] for j in range(setup.n_joints)]) * Af
    setup.check_joints(q, str(csv_path), ids)
    T = _poses(csv_path, ids, lines, v, pos_only, Lf)
    cov, src = _covariances(csv_path, ids, lines, v, group, 3 if pos_only else 6, Lf, Af, default, units)
    _check_plausible(csv_path, setup, measured, q, T, units)
    if len(ids) < folds:
        raise top.error("folds", f"{folds} folds need at least {folds} poses, {csv_path.name} has {len(ids)}")
    T_ct, cov_ct = to_camera_convention(setup, measured, T, cov)
    meas = Measurements(q, q, T_ct, cov_ct, tuple(ids))
    return MeasuredPoses(path, csv_path, scene, measured, residual, tuple(ids), q, T, cov, meas, src, units, folds,
                         seed)


def _pair_settings(top: Section):
    """(flange csv, csv, Lf, Af, units, measured, mount, default sigmas or None, noise_frame or None, robot std or
    None, folds, seed) of a pose-pair file."""
    _only(top, YAML_KEYS)
    fmt = top.get("format", str)
    if fmt != FORMAT:
        raise top.error("format", f"expected {FORMAT!r}, got {fmt!r}")
    if "scene" in top:
        raise top.error("scene", "a pose-pair file (flange_poses) needs no robot model: give scene or flange_poses, "
                                 "not both")
    flange = top.path_value("flange_poses")
    csv_path = top.path_value("csv", None) or top.file.with_suffix(".csv")
    mount = top.get("mount", str, choices=PAIR_MOUNTS)
    us = _only(top.section("units"), ("length", "angle"))
    units = {"length": us.get("length", str, choices=LENGTH_UNITS), "angle": us.get("angle", str, choices=ANGLE_UNITS)}
    measured = top.get("measured", str, choices=MEASURED)
    if measured.startswith("p_"):
        raise top.error("measured", "pose pairs need full poses (T_cam_target or T_target_cam): a hand-eye fit needs "
                                    "the rotations")
    default = None
    if "default_sigma" in top:
        ds = _only(top.section("default_sigma"), ("t_m", "t_mm", "t_cm", "r_rad", "r_deg"))
        default = (length_key(ds, "t"), angle_key(ds, "r"))
        for val, kind in zip(default, ("length", "angle")):
            lo, hi = SIGMA_RANGE[kind]
            if not lo <= val <= hi:
                raise ds.error(None, f"a {kind} std of {val:.4g} (SI) is outside the plausible {lo:g}-{hi:g}")
    frame = top.get("noise_frame", str, None, choices=NOISE_FRAMES)
    robot = None
    if "robot_pose_std" in top:
        rs = _only(top.section("robot_pose_std"), ("translation_mm", "rotation_deg"))
        robot = (rs.number("translation_mm", float, min=0.0, max=100.0, unit="mm") * 1e-3,
                 float(np.radians(rs.number("rotation_deg", float, min=0.0, max=10.0, unit="deg"))))
    folds = top.get("folds", int, 5)
    if folds < 2:
        raise top.error("folds", f"expected an integer >= 2, got {folds}")
    return (flange, csv_path, LENGTH_UNITS[units["length"]], ANGLE_UNITS[units["angle"]], units, measured, mount,
            default, frame, robot, folds, top.nonnegative("seed", int, 0))


def _read_pose_pairs(top: Section) -> PosePairs:
    """The :class:`PosePairs` of a pose-pair YAML (module docstring): its two CSVs joined by pose id."""
    from .recording import read_flange_csv

    flange, csv_path, Lf, Af, units, measured, mount, default, frame, robot, folds, seed = _pair_settings(top)
    ids, v, group, lines = _rows(csv_path, 0, False)
    if group == "none" and default is None:
        src, frame = f"estimated per axis ({frame or 'target'} frame)", frame or "target"
    elif group != "none" and default is not None:
        raise top.error("default_sigma", f"{csv_path.name} has its own noise columns: remove one of the two")
    elif frame is not None:
        raise top.error("noise_frame", "applies when the measured poses' noise is estimated (no default_sigma, no "
                                       "noise columns)")
    else:
        src = None
    T = _poses(csv_path, ids, lines, v, False, Lf)
    cov = None
    if src is None:
        cov, src = _covariances(csv_path, ids, lines, v, group, 6, Lf, Af, default, units)
    fids, Tf = read_flange_csv(flange, Lf)
    index = {pid: k for k, pid in enumerate(fids)}
    missing = [pid for pid in ids if pid not in index]
    if missing:
        raise DataError(f"{flange}: no flange pose for pose id(s) {', '.join(map(repr, missing[:10]))} of "
                        f"{csv_path.name}")
    extra = [pid for pid in fids if pid not in set(ids)]
    if extra:
        raise DataError(f"{csv_path}: no measured pose for pose id(s) {', '.join(map(repr, extra[:10]))} of "
                        f"{flange.name}")
    Tf = Tf[[index[pid] for pid in ids]]
    d = float(np.median(np.linalg.norm(T[:, :3, 3], axis=1)))
    if d < MIN_MEDIAN_DISTANCE_M:
        raise DataError(f"{csv_path}: columns x,y,z: the measured distances are {d * 1e3:.3g} mm (median, read with "
                        f"units.length: {units['length']}): metres declared as millimetres?")
    if len(ids) < max(folds, 3):
        raise top.error("folds", f"{folds} folds need at least {max(folds, 3)} pose pairs, {csv_path.name} has "
                                 f"{len(ids)}")
    T_ct, cov_ct = (to_camera_convention(None, measured, T, cov) if cov is not None else
                    (T if measured == "T_cam_target" else F.inv_T(T), None))
    return PosePairs(top.file, csv_path, flange, mount, measured, tuple(ids), Tf, T, T_ct, cov_ct, src, frame, robot,
                     units, folds, seed)


__all__ = ["FORMAT", "MEASURED", "INLINE_SCENE_KEYS", "MeasuredPoses", "PosePairs", "read_measured_poses",
           "to_camera_convention", "chain_direction", "misreadings"]
