"""Checks on measured data before identification: is the pose set rich enough, and do the measured
motions agree with the commanded ones?

**Pose-set richness.** The rank of the identification Jacobian on the user's poses is compared with
the kind's structural rank (the same parameters over many generic poses, ``Setup.generic_poses``). A
deficit means the poses, not the model, lose parameters (e.g. a zero pose spread): refused with the
lost parameters named, unless the caller accepts fixing them.

**Motion consistency (screw invariants).** For two poses i, j the measured relative motion
``M_ij = T_i^-1 T_j`` (T = measured T_cam_target) and the one predicted by the nominal model from
the joint readings, ``P_ij``, are conjugates of the same robot motion whatever the camera and target
mounts (``T_cam_target = A · F(q) · B`` gives ``M_ij = B^-1 F_i^-1 F_j B``; eye-in-hand the same with
``F_i F_j^-1``). Their rotation angles agree, and so does the translation along the screw axis
(the pitch; the translation norm for pure translations). Nominal-model errors change them by a
fraction of a degree / a millimetre; a joint-unit error, a wrong target size or focal length, or a
pose whose images belong to another pose changes them grossly. The scale of the lengths is
estimated as the median ratio measured / predicted over the informative pairs. Short screws (pitches of
a few cm) change by several percent with the robot's own geometric errors: the scale is refused beyond
the quadrature sum of SCALE_TOL and SCALE_SPREAD_K times the spread of that median over robots drawn within
:data:`NOMINAL_ERROR_M` / :data:`NOMINAL_ERROR_RAD` per parameter of the nominal model, for the same pose
pairs (``scale_spread``; on the thesis tripod scene, 20 poses: ratios 0.945-1.025 over 12 such robots
with noise-free poses, where a fixed 5 % refused 2 of them).
"""

from __future__ import annotations

import numpy as np

from .. import frames as F
from ..errors import DataError, VisionCalibError
from ..rig import Measurements, Setup

#: relative length-scale error above which the measured motions are refused (wrong target size / fx / units),
#: added in quadrature to SCALE_SPREAD_K x the spread the robot's own errors give the statistic (``scale_spread``)
SCALE_TOL = 0.05
SCALE_SPREAD_K = 3.0
#: how far a robot may be from its nominal model, per free parameter (the shipped scenes draw their true robots
#: with these): the geometric errors the scale test allows for
NOMINAL_ERROR_M = 0.002
NOMINAL_ERROR_RAD = np.radians(0.2)
#: robots drawn for ``scale_spread`` (a fixed seed: the test gives the same answer for the same data)
SPREAD_DRAWS = 16
#: pairs must move this much to inform the scale: pitch or pure translation [m], rotation [rad]
MIN_TRANSLATION_M = 0.01
MIN_ROTATION_RAD = np.radians(5.0)
PURE_TRANSLATION_RAD = np.radians(0.5)
#: a pose whose median angle mismatch exceeds max(ANGLE_FLOOR, ANGLE_K x the global median) is inconsistent
ANGLE_FLOOR_RAD = np.radians(1.0)
ANGLE_K = 5.0


def screw_invariants(T_rel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(angle (N,) rad, pitch (N,) m = translation along the rotation axis, translation norm (N,) m)
    of relative motions T_rel (N, 4, 4)."""
    rv = F.xyz_rotvec_from_T(T_rel)[..., 3:]
    ang = np.linalg.norm(rv, axis=-1)
    axis = rv / np.maximum(ang, 1e-12)[..., None]
    t = T_rel[..., :3, 3]
    return ang, np.abs(np.sum(t * axis, axis=-1)), np.linalg.norm(t, axis=-1)


def _pairs(n: int, max_pairs: int = 4000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    i, j = np.triu_indices(n, 1)
    if len(i) > max_pairs:
        k = np.random.default_rng(seed).choice(len(i), max_pairs, replace=False)
        i, j = i[k], j[k]
    return i, j


def motion_consistency(setup: Setup, meas: Measurements) -> dict:
    """Compare measured and predicted (nominal model, joint readings) relative motions of all pose pairs.
    Returns {scale, n_scale_pairs, angle_mismatch_median_deg, per-pose angle mismatch (deg) and the
    labels of inconsistent poses}."""
    T_pred = setup.predict_from_joints(meas.joints, setup.params.nominal)
    T_meas = meas.T_cam_target
    i, j = _pairs(len(T_meas))
    am, pm, nm = screw_invariants(np.linalg.inv(T_meas[i]) @ T_meas[j])
    ap, pp, npred = screw_invariants(np.linalg.inv(T_pred[i]) @ T_pred[j])
    dang = np.abs(am - ap)
    pure = (ap < PURE_TRANSLATION_RAD) & (npred > MIN_TRANSLATION_M)
    screw = (ap > MIN_ROTATION_RAD) & (pp > MIN_TRANSLATION_M)
    ratios = np.concatenate([nm[pure] / npred[pure], pm[screw] / pp[screw]])
    scale = float(np.median(ratios)) if ratios.size >= 3 else float("nan")
    spread = scale_spread(setup, meas.joints, i, j, pure, screw, npred, pp) if np.isfinite(scale) else float("nan")
    per_pose = np.full(len(T_meas), np.nan)
    for k in range(len(T_meas)):
        sel = (i == k) | (j == k)
        if sel.any():
            per_pose[k] = np.median(dang[sel])
    med = float(np.median(dang)) if dang.size else float("nan")
    lim = max(ANGLE_FLOOR_RAD, ANGLE_K * med) if np.isfinite(med) else np.inf
    bad = np.flatnonzero(per_pose > lim)
    labels = meas.labels or tuple(str(k) for k in range(len(T_meas)))
    return {"scale": scale, "n_scale_pairs": int(ratios.size), "scale_spread": spread,
            "scale_tolerance": float(np.hypot(SCALE_TOL, SCALE_SPREAD_K * spread)) if np.isfinite(spread) else SCALE_TOL,
            "angle_mismatch_median_deg": float(np.degrees(med)),
            "angle_mismatch_limit_deg": float(np.degrees(lim)), "median_rotation_deg": float(np.degrees(np.median(ap)))
            if ap.size else float("nan"),
            "inconsistent_poses": [{"pose_id": labels[k], "angle_mismatch_deg": float(np.degrees(per_pose[k]))}
                                   for k in bad]}


def scale_spread(setup: Setup, joints, i, j, pure, screw, n_nom, p_nom) -> float:
    """RMS deviation from 1 of the scale statistic (median ratio of pure-translation norms and pitches, pairs i, j
    with the masks ``pure`` / ``screw``) between robots drawn within NOMINAL_ERROR_M / NOMINAL_ERROR_RAD per free
    parameter and the nominal model (n_nom, p_nom: the nominal's norms and pitches): what the robot's own
    geometric errors do to it. 0 when no robot can be drawn (no free length or angle)."""
    ps = setup.params
    kinds = np.asarray(ps.kinds)
    sig = np.where(kinds == "length", NOMINAL_ERROR_M, np.where(kinds == "angle", NOMINAL_ERROR_RAD, 0.0)) * ps.free
    if not np.any(sig > 0):
        return 0.0
    rng = np.random.default_rng(0)
    dev = []
    for _ in range(SPREAD_DRAWS):
        try:
            T = setup.predict_from_joints(joints, ps.nominal + sig * rng.standard_normal(len(sig)))
        except VisionCalibError:  # a drawn robot that cannot reach these joints (H4): another draw
            continue
        _, p, n = screw_invariants(np.linalg.inv(T[i]) @ T[j])
        r = np.concatenate([n[pure] / n_nom[pure], p[screw] / p_nom[screw]])
        if np.all(np.isfinite(r)):
            dev.append(np.median(r) - 1.0)
    return float(np.sqrt(np.mean(np.square(dev)))) if dev else 0.0


def motion_verdict(setup: Setup, meas: Measurements, where: str, scale_hint: str) -> tuple[dict, str | None]:
    """(:func:`motion_consistency` record, None) when the measured motions follow the commanded joints, else
    (record, the refusal naming ``where`` and the likely cause): a length scale off by more than its tolerance
    (``scale_tolerance``: SCALE_TOL and SCALE_SPREAD_K x ``scale_spread`` in quadrature), or
    rotations that do not follow the joints at all. ``scale_hint``: the keys that set the length scale (e.g. the
    target's square size, fx). Fewer than 3 poses: ({}, None). Blind to a whole pose set inverted (the other
    ``measured:`` direction): a relative motion and its inverse have the same angle and |pitch|."""
    if len(meas.T_cam_target) < 3:
        return {}, None
    out = motion_consistency(setup, meas)
    med_rot = out["median_rotation_deg"]
    if out["angle_mismatch_median_deg"] > max(2.0, 0.1 * med_rot):
        return out, (
            f"{where}: the measured rotations between poses do not follow the commanded joints (median mismatch "
            f"{out['angle_mismatch_median_deg']:.3g} deg for a median commanded rotation of {med_rot:.3g} deg): "
            "joint values in the wrong angle unit, a joint order different from the robot's, or the wrong robot model")
    s, tol = out["scale"], out["scale_tolerance"]
    if np.isfinite(s) and abs(s - 1) > tol:
        return out, (f"{where}: the measured motions are {s:.3g} x the commanded ones ({out['n_scale_pairs']} pose "
                     f"pairs; a robot within {NOMINAL_ERROR_M * 1e3:g} mm / {np.degrees(NOMINAL_ERROR_RAD):g} deg of "
                     f"its nominal model stays within {tol:.3g} of 1 here): a wrong length scale -- check "
                     f"{scale_hint} and the length units")
    return out, None


def check_motion(setup: Setup, meas: Measurements, where: str, scale_hint: str) -> dict:
    """:func:`motion_verdict`, its refusal raised as a DataError; returns the record."""
    out, refusal = motion_verdict(setup, meas, where, scale_hint)
    if refusal:
        raise DataError(refusal)
    return out


#: joint readings that differ by at most this on every joint [rad, or m for a prismatic joint] are "the same
#: joints" (an encoder count of a 20-bit encoder is 6e-6 rad; a re-commanded pose reads within a few counts)
SAME_JOINTS_TOL = 1e-4
#: a pose at the same joints as an earlier one whose measured pose differs from it by less than this Mahalanobis^2
#: (difference whitened by the sum of both covariances) is a *copy* of it, not a second measurement: two independent
#: measurements differ by about sqrt(2) x their noise (chi-square, 6 dof; below 0.01 with probability 2e-8,
#: 3 dof: 6e-5), a copied row or image folder (even with rounding or 1e-6 jitter) by nothing
COPY_CHI2 = 0.01
#: the start of the rejection reason of a copy (:func:`drop_copies`; :func:`duplicate_poses` finds them by it)
COPY_REASON = "a copy of pose"


def same_joint_groups(meas: Measurements, tol: float = SAME_JOINTS_TOL) -> np.ndarray:
    """(N,) int: one group number per pose, shared by the poses whose joint readings all agree within ``tol``
    (transitively): repeated measurements of one robot pose. The held-out folds keep a group together
    (``holdout.fold_indices``): a repeat in the training set would flatter its twin's held-out error."""
    return close_groups(np.asarray(meas.joints, float).reshape(len(meas.joints), -1), tol)


def close_groups(J: np.ndarray, tol: float) -> np.ndarray:
    """(N,) int: one group number per row of J (N, d), shared by the rows that agree within ``tol`` on every
    column (transitively), numbered in the order of their first row."""
    n = len(J)
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    if n and J.shape[1]:
        order = np.argsort(J[:, 0], kind="stable")
        first = J[order, 0]
        for a in range(n):
            b = a + 1
            while b < n and first[b] - first[a] <= tol:
                i, j = order[a], order[b]
                if np.max(np.abs(J[i] - J[j])) <= tol:
                    parent[root(max(i, j))] = root(min(i, j))
                b += 1
    roots = [root(i) for i in range(n)]
    ids = {r: k for k, r in enumerate(dict.fromkeys(roots))}
    return np.array([ids[r] for r in roots], int)


def first_of_copies(groups, gap) -> tuple[list[int], list[tuple[int, int, str]]]:
    """(indices kept, [(copy, its original, gap text)]) of N items in ``groups`` (N,) (the same robot pose): item i
    is a copy of an earlier kept item k of its group when ``gap(k, i)`` returns a text (how close they are), else
    None; the first of each set is kept. The rule of :func:`drop_copies` (joints) and :func:`pair_copies` (flange
    poses)."""
    kept, copies, members = [], [], {}
    for i, g in enumerate(groups):
        hit = next(((k, w) for k in members.get(g, ()) if (w := gap(k, i)) is not None), None)
        if hit is None:
            kept.append(i)
            members.setdefault(g, []).append(i)
        else:
            copies.append((i, hit[0], hit[1]))
    return kept, copies


def pose_chi2(Ta, Tb, Ca, Cb) -> float:
    """Mahalanobis^2 of the difference of two measured poses (4, 4) whitened by the sum of their covariances
    (6, 6) [m, rad]."""
    d = F.pose_error(Ta, Tb)
    return float(d @ np.linalg.pinv(np.asarray(Ca, float) + np.asarray(Cb, float)) @ d)


def drop_copies(meas: Measurements) -> tuple[Measurements, list[tuple[str, str]]]:
    """(the measurements with every *copy* removed, [(label, reason)] of the copies): a pose whose joints equal an
    earlier pose's (:data:`SAME_JOINTS_TOL`) and whose measured pose equals it within a small fraction of the noise
    (:data:`COPY_CHI2`) is one measurement under two ids (a copied row or image folder, with or without jitter); the
    fit would count it twice and report a std 1/sqrt(2) too small, and the held-out validation would predict it
    from its own copy. The first of each set is kept."""
    groups = same_joint_groups(meas)
    labels = meas.labels or tuple(str(k) for k in range(len(groups)))
    T, C = meas.T_cam_target, meas.cov

    def gap(k, i):
        c2 = pose_chi2(T[k], T[i], C[k], C[i])
        return f"{np.sqrt(c2):.2g} sigma" if c2 < COPY_CHI2 else None

    kept, found = first_of_copies(groups, gap)
    if not found:
        return meas, []
    return meas.subset(kept), [(str(labels[i]), f"{COPY_REASON} {labels[k]} (the same joints and measured pose, "
                                                f"within {w}): one measurement under two ids, counted once")
                               for i, k, w in found]


def copies_warning(rejected, same: str) -> list[str]:
    """[one warning naming the copies among ``rejected`` [(label, reason)]] (reasons starting with
    :data:`COPY_REASON`), or []; same: what the copies share besides the measured pose ("joints", "flange pose")."""
    copies = [(lab, why) for lab, why in rejected if str(why).startswith(COPY_REASON)]
    if not copies:
        return []
    shown = "; ".join(f"{lab} = {why[len(COPY_REASON) + 1:].split(' ', 1)[0]}" for lab, why in copies[:8])
    return [f"{len(copies)} pose{'s are copies' if len(copies) > 1 else ' is a copy'} of another pose (the same "
            f"{same} and measured pose, within a fraction of the noise: the same measurement under another "
            f"id), counted once: {shown}" + ("; ..." if len(copies) > 8 else "")]


def duplicate_poses(meas: Measurements, rejected=()) -> list[str]:
    """Warnings naming (1) the copies :func:`drop_copies` removed (found among ``rejected`` [(label, reason)]) and
    (2) the poses of ``meas`` measured again at the same joints (genuine repeats: kept, each set in one held-out
    fold)."""
    out = copies_warning(rejected, "joints")
    groups = same_joint_groups(meas)
    labels = meas.labels or tuple(str(k) for k in range(len(groups)))
    sets = [[str(labels[i]) for i in np.flatnonzero(groups == g)] for g in np.unique(groups)]
    sets = [s for s in sets if len(s) > 1]
    if sets:
        shown = "; ".join(", ".join(s) for s in sets[:5]) + ("; ..." if len(sets) > 5 else "")
        out.append(f"{sum(len(s) - 1 for s in sets)} poses were measured again at the same joints as another "
                   f"(within {SAME_JOINTS_TOL:g} rad): kept as repeated measurements, each set in one held-out fold: "
                   f"{shown}")
    return out


def drop_degenerate(meas: Measurements) -> tuple[Measurements, list]:
    """(measurements without the poses whose covariance is not positive definite, [(label, reason)]): a
    pose whose frames are all identical (duplicated image files) has zero scatter and no noise estimate."""
    bad = []
    tr = np.trace(meas.cov, axis1=1, axis2=2)
    floor = 1e-6 * np.median(tr) if len(tr) else 0.0  # a million times below the others: no noise estimate
    for k, c in enumerate(meas.cov):
        try:
            np.linalg.cholesky(c)
            if not tr[k] > floor:
                bad.append(k)
        except np.linalg.LinAlgError:
            bad.append(k)
    if not bad:
        return meas, []
    labels = meas.labels or tuple(str(k) for k in range(len(meas.cov)))
    keep = [k for k in range(len(meas.cov)) if k not in bad]
    return meas.subset(keep), [(labels[k], "pose covariance not positive definite: its frames show no scatter "
                                           "(identical images, e.g. duplicated or linked files)") for k in bad]


def drop_inconsistent(meas: Measurements, motion: dict, where: str,
                      max_fraction: float = 0.3) -> tuple[Measurements, list[tuple[str, str]]]:
    """(measurements without the poses :func:`motion_consistency` found inconsistent, [(label, reason)]).
    DataError when more than ``max_fraction`` of the poses are (then the data or the model is wrong)."""
    bad = {p["pose_id"]: p["angle_mismatch_deg"] for p in motion.get("inconsistent_poses", [])}
    if not bad:
        return meas, []
    if len(bad) > max_fraction * len(meas.labels):
        raise DataError(f"{where}: {len(bad)} of {len(meas.labels)} poses move inconsistently with their joints "
                        f"(first: {next(iter(bad))}): the joint readings or the robot model are wrong")
    keep = [k for k, lab in enumerate(meas.labels) if lab not in bad]
    lim = motion["angle_mismatch_limit_deg"]
    return meas.subset(keep), [(lab, f"its measured motion relative to the other poses does not follow its joints "
                                     f"(median rotation mismatch {a:.3g} deg > {lim:.3g} deg): images of another "
                                     "pose, or a wrong joint reading") for lab, a in bad.items()]


def screen_measurements(setup: Setup, meas: Measurements, where: str,
                        scale_hint: str) -> tuple[Measurements, list[tuple[str, str]], dict]:
    """The checks before identifying measured data, in order: poses without a noise estimate dropped
    (:func:`drop_degenerate`), the motion consistency refused or accepted (:func:`check_motion`), poses whose
    motion does not follow their joints dropped (:func:`drop_inconsistent`).
    Returns (kept measurements, rejected [(label, reason)], the motion-check record)."""
    meas, degenerate = drop_degenerate(meas)
    motion = check_motion(setup, meas, where, scale_hint)
    meas, inconsistent = drop_inconsistent(meas, motion, where)
    return meas, degenerate + inconsistent, motion


# ------------------------------------------------------------------ hand-eye (flange poses known, no joints)
#: two flange poses within this translation [m] and rotation [rad] (every component) are the same robot pose
SAME_FLANGE_M = 1e-4
SAME_FLANGE_RAD = 1e-4
#: without a covariance, two measured poses at the same flange pose within this [m], [rad] on every component are
#: one measurement (a copy): a camera or tracker measures a pose to 1e-5 m and 1e-4 rad at best, so two genuine
#: measurements differ by more; a copied row (printed to 6 decimals, or with 1e-6 jitter) by less
COPY_M = 1e-5
COPY_RAD = 1e-5
#: the relative rotations between the distinct flange poses must turn at least this much [deg, RMS over the pairs
#: of poses] about a second axis: below it the closed form's rotation system has rank < 2 at this resolution
MIN_AXIS_SPREAD_DEG = 1.0
#: the start of the error of a pose set without enough distinct motions (:func:`handeye_motions`)
DEGENERATE_MOTION = "degenerate motion"


def flange_groups(T_base_flange: np.ndarray) -> np.ndarray:
    """(N,) int: one group number per flange pose (N, 4, 4) [m], shared by the poses within :data:`SAME_FLANGE_M`
    and :data:`SAME_FLANGE_RAD` of one another (:func:`close_groups`): the same robot pose."""
    T = np.asarray(T_base_flange, float)
    return close_groups(np.concatenate([T[:, :3, 3] / SAME_FLANGE_M, T[:, :3, :3].reshape(len(T), 9)
                                        / SAME_FLANGE_RAD], axis=1), 1.0)


def pair_copies(T_base_flange, T_cam_target, cov, labels) -> tuple[list[int], list[tuple[str, str]]]:
    """(indices kept, [(label, reason)] of the copies) of hand-eye pose pairs (flange poses, measured poses (N, 4, 4)
    [m], their covariance (N, 6, 6) or None): a pair at the same flange pose as an earlier one (:func:`flange_groups`)
    whose measured pose equals it within :data:`COPY_CHI2` (covariance given) or :data:`COPY_M` /
    :data:`COPY_RAD` (none) is one measurement under two ids (the same rule as :func:`drop_copies`): counted once,
    else the std come out 1/sqrt(2) too small. The first of each set is kept."""
    M = np.asarray(T_cam_target, float)

    def gap(k, i) -> str | None:  # how close pair i is to pair k when it is a copy of it, else None
        if cov is not None:
            c2 = pose_chi2(M[k], M[i], cov[k], cov[i])
            return f"{np.sqrt(c2):.2g} sigma" if c2 < COPY_CHI2 else None
        d = np.abs(F.pose_error(M[k], M[i]))
        if d[:3].max() <= COPY_M and d[3:].max() <= COPY_RAD:
            return f"{d[:3].max() * 1e3:.2g} mm, {np.degrees(d[3:].max()):.2g} deg"
        return None

    kept, found = first_of_copies(flange_groups(T_base_flange), gap)
    return kept, [(str(labels[i]), f"{COPY_REASON} {labels[k]} (the same flange pose and measured pose, within {w}): "
                                   "one measurement under two ids, counted once") for i, k, w in found]


def handeye_motions(T_base_flange, mount: str, labels, where: str) -> dict:
    """The motion check of a hand-eye set before any fit: the distinct flange poses (:func:`flange_groups`: repeats
    and copies count once), the relative rotations ``G_i^-1 G_j`` between them (``M_k = A G_k B``,
    ``identify.handeye_problem.mount_G``), and the closed form's rank: the number of directions in which those
    rotation vectors turn at least :data:`MIN_AXIS_SPREAD_DEG` RMS (eigenvalues of their scatter). Fewer than 3
    distinct poses, or a rank below 2 (translations only; rotations about one axis) leave the mounts undetermined:
    a DataError starting with :data:`DEGENERATE_MOTION` naming what is missing. Returns {n_pairs, distinct_poses,
    largest_rotation_deg, rotation_rms_deg (3,) per direction, largest first, axis_spread_deg, rank}."""
    from scipy.spatial.transform import Rotation

    from ..identify.handeye_problem import mount_G

    F_ = np.asarray(T_base_flange, float)
    groups = flange_groups(F_)
    first = [int(np.flatnonzero(groups == g)[0]) for g in range(int(groups.max()) + 1)] if len(groups) else []
    need = ("a hand-eye calibration needs at least 3 distinct flange poses whose motions rotate about two "
            "non-parallel axes (tilt the flange about a second axis)")
    n = len(first)
    if n < 3:
        sets = [[str(labels[i]) for i in np.flatnonzero(groups == g)] for g in range(n)]
        shown = "; ".join(f"{', '.join(s[:4])}{', ...' if len(s) > 4 else ''} ({len(s)} pairs)" for s in sets)
        raise DataError(f"{where}: {DEGENERATE_MOTION}: the {len(F_)} pose pairs hold {n} distinct flange "
                        f"pose{'s' if n != 1 else ''} ({shown}: within {SAME_FLANGE_M * 1e3:g} mm and "
                        f"{SAME_FLANGE_RAD:g} rad); {need}")
    R = mount_G(F_[first], mount)[:, :3, :3]
    i, j = _pairs(n)
    rv = Rotation.from_matrix(np.swapaxes(R[i], -1, -2) @ R[j]).as_rotvec()
    w, V = np.linalg.eigh(rv.T @ rv / len(rv))
    rms = np.degrees(np.sqrt(np.maximum(w[::-1], 0.0)))
    rank = int(np.sum(rms >= MIN_AXIS_SPREAD_DEG))
    out = {"n_pairs": int(len(F_)), "distinct_poses": n, "largest_rotation_deg": float(np.degrees(
        np.linalg.norm(rv, axis=1).max())), "rotation_rms_deg": [float(v) for v in rms],
        "axis_spread_deg": float(rms[1]), "rank": rank, "min_axis_spread_deg": MIN_AXIS_SPREAD_DEG}
    if rank >= 2:
        return out
    if rank == 0:
        what = (f"the {n} distinct flange poses differ by translations only (the largest rotation between two of "
                f"them {out['largest_rotation_deg']:.3g} deg, RMS {rms[0]:.3g} deg)")
    else:
        frame = "flange" if mount == "fixed" else "base"
        what = (f"every motion between the {n} distinct flange poses rotates about one axis ({np.round(V[:, 2], 3)} "
                f"in the {frame} frame): the rotation about any other axis is {rms[1]:.3g} deg RMS over "
                f"{len(rv)} pairs of poses")
    raise DataError(f"{where}: {DEGENERATE_MOTION}: {what}, below {MIN_AXIS_SPREAD_DEG:g} deg: the closed form's "
                    f"rotation system has rank {rank} of the 2 it needs, so the mounts' rotation and their translation "
                    f"along the rotation axis are not determined; {need}")
