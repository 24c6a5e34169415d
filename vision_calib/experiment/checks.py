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
estimated as the median ratio measured / predicted over the informative pairs.
"""

from __future__ import annotations

import numpy as np

from .. import frames as F
from ..errors import DataError
from ..rig import Measurements, Setup

#: relative length-scale error above which the measured motions are refused (wrong target size / fx / units)
SCALE_TOL = 0.05
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
    per_pose = np.full(len(T_meas), np.nan)
    for k in range(len(T_meas)):
        sel = (i == k) | (j == k)
        if sel.any():
            per_pose[k] = np.median(dang[sel])
    med = float(np.median(dang)) if dang.size else float("nan")
    lim = max(ANGLE_FLOOR_RAD, ANGLE_K * med) if np.isfinite(med) else np.inf
    bad = np.flatnonzero(per_pose > lim)
    labels = meas.labels or tuple(str(k) for k in range(len(T_meas)))
    return {"scale": scale, "n_scale_pairs": int(ratios.size), "angle_mismatch_median_deg": float(np.degrees(med)),
            "angle_mismatch_limit_deg": float(np.degrees(lim)), "median_rotation_deg": float(np.degrees(np.median(ap)))
            if ap.size else float("nan"),
            "inconsistent_poses": [{"pose_id": labels[k], "angle_mismatch_deg": float(np.degrees(per_pose[k]))}
                                   for k in bad]}


def motion_verdict(setup: Setup, meas: Measurements, where: str, scale_hint: str) -> tuple[dict, str | None]:
    """(:func:`motion_consistency` record, None) when the measured motions follow the commanded joints, else
    (record, the refusal naming ``where`` and the likely cause): a length scale off by more than SCALE_TOL, or
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
    s = out["scale"]
    if np.isfinite(s) and abs(s - 1) > SCALE_TOL:
        return out, (f"{where}: the measured motions are {s:.3g} x the commanded ones ({out['n_scale_pairs']} pose "
                     f"pairs): a wrong length scale -- check {scale_hint} and the length units")
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
    J = np.asarray(meas.joints, float).reshape(len(meas.joints), -1)
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


def _copy_chi2(meas: Measurements, i: int, j: int) -> float:
    d = F.pose_error(meas.T_cam_target[i], meas.T_cam_target[j])
    C = np.asarray(meas.cov[i], float) + np.asarray(meas.cov[j], float)
    return float(d @ np.linalg.pinv(C) @ d)


def drop_copies(meas: Measurements) -> tuple[Measurements, list[tuple[str, str]]]:
    """(the measurements with every *copy* removed, [(label, reason)] of the copies): a pose whose joints equal an
    earlier pose's (:data:`SAME_JOINTS_TOL`) and whose measured pose equals it within a small fraction of the noise
    (:data:`COPY_CHI2`) is one measurement under two ids (a copied row or image folder, with or without jitter); the
    fit would count it twice and report a std 1/sqrt(2) too small, and the held-out validation would predict it
    from its own copy. The first of each set is kept."""
    groups = same_joint_groups(meas)
    labels = meas.labels or tuple(str(k) for k in range(len(groups)))
    kept, copies = [], []
    members: dict = {}
    for i, g in enumerate(groups):
        orig = next((k for k in members.get(g, ()) if _copy_chi2(meas, k, i) < COPY_CHI2), None)
        if orig is None:
            kept.append(i)
            members.setdefault(g, []).append(i)
        else:
            copies.append((str(labels[i]), f"{COPY_REASON} {labels[orig]} (the same joints and measured pose, within "
                                           f"{np.sqrt(_copy_chi2(meas, orig, i)):.2g} sigma): one measurement under "
                                           "two ids, counted once"))
    if not copies:
        return meas, []
    return meas.subset(kept), copies


def duplicate_poses(meas: Measurements, rejected=()) -> list[str]:
    """Warnings naming (1) the copies :func:`drop_copies` removed (found among ``rejected`` [(label, reason)]) and
    (2) the poses of ``meas`` measured again at the same joints (genuine repeats: kept, each set in one held-out
    fold)."""
    out = []
    copies = [(lab, why) for lab, why in rejected if str(why).startswith(COPY_REASON)]
    if copies:
        shown = "; ".join(f"{lab} = {why[len(COPY_REASON) + 1:].split(' ', 1)[0]}" for lab, why in copies[:8])
        out.append(f"{len(copies)} pose{'s are copies' if len(copies) > 1 else ' is a copy'} of another pose (the same "
                   f"joints and measured pose, within a fraction of the noise: the same measurement under another "
                   f"id), counted once: {shown}" + ("; ..." if len(copies) > 8 else ""))
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
