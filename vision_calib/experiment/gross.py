"""Gross input errors after an identification from measured data: failures, not warnings (issue 21).

Two tests, run by ``process`` and ``process-poses`` after :func:`steps.identify_measurements`:

**A fit far beyond its noise model.** chi2/dof is the squared ratio of the residuals to the noise the
measurement covariance predicts. A right model gives about 1; the covariance model's own error keeps it
within ``identify.adequacy.IMAGE_COV_SCALE`` (0.55-1.3); a user's sigmas off by 3x in std give 10, and
unmodelled robot errors that calibration is for give a few to a hundred (measured, 40 UR5e poses at
0.1 mm / 0.02 deg: a 2 mrad periodic transmission error on every joint 5.5, a 10 mrad one 113; the H4
model-31 truth fitted with model 12 at image precision 5.1). Input errors give 1e4 and more (a reversed
``measured:`` direction 2.1e4, swapped x/y columns 1.6e5 on 205 RX-90 poses). Above :data:`GROSS_CHI2_DOF`
= 1e3 (residuals 32 times the stated noise: a covariance wrong by 30x in std, or model errors ten times the
largest measured above) the fit is a failure; the alternatives the caller can build from its raw input
(the other pose direction, swapped columns, scalar-first quaternions, a joint's sign reversed, two joint columns
swapped) are refitted and the message says first which one fits.

**Moves no calibration correction can be** (:func:`convention_moves`): the identified model is compared
with the nominal one, not only by the size of the step: an angle (joint offset, twist, a mount's rotation
as a whole) more than :data:`CONVENTION_ANGLE_RAD` = 30 deg from its nominal, wrapped to +-180 deg (encoder
zeros are mastered to a fraction of a degree, CAD mounts to a few; the plausibility warning of
``steps.plausibility_warnings`` starts at 11.5 deg), or a length of more than :data:`SIGN_FLOOR_M` that
changes sign with at least half its size, each well determined by the data (>= 3 std: weakly determined
moves stay warnings). Those are a sign, direction or convention error in the input (a joint whose sign is
reversed gives an equivalent model with an offset of 180 deg and a mount turned over, at the same
residuals): a failure naming the joint or mount; each joint's readings negated in turn are refitted to
find the one that explains it.

**Motions that do not follow the joints** (``checks.motion_verdict``, the check ``process`` applies before
its fit, given here by ``process-poses``): rotations between poses that do not follow the commanded joints
(a joint's sign or unit, the joint order) or a length scale off by more than 5 %. It is a failure by itself
(even when the fit absorbed it), and the same check runs on every alternative reading: a reading fits only
when its motions follow its joints. It cannot see a reversed ``measured:`` direction (inverting every pose
keeps each relative motion's angle and |pitch|): the refits above find that one.
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from ..rig import Measurements

#: chi2/dof above which a fit is a gross input error (module docstring: measured model errors <= 113)
GROSS_CHI2_DOF = 1e3
#: an angle this far from its nominal (wrapped) is a convention error, not a correction
CONVENTION_ANGLE_RAD = float(np.radians(30.0))
#: a length at least this long whose sign flips (with half its size or more) is a convention error
SIGN_FLOOR_M = 0.01
#: a move counts only when the data determine it: |move| >= MOVE_SIGMAS x std
MOVE_SIGMAS = 3.0
#: refits of the alternatives use at most this many poses (evenly spread) and function evaluations
REFIT_POSES = 60
REFIT_NFEV = 200
#: an alternative "fits" when its chi2/dof is below the gross limit and this many times below the original
FIT_GAIN = 100.0

_JOINT = re.compile(r"^(theta|alpha|beta|a|d|l)(\d+)$|^q0_(\d+)$|^j(\d+)(?:\.(r?[xyz]))?$")


def _wrap(a):
    return (np.asarray(a, float) + np.pi) % (2 * np.pi) - np.pi


def describe(name: str) -> str:
    """What a parameter name stands for: 'theta2' -> 'joint 2 zero offset', 'T_target_base' -> 'mount T_target_base'."""
    m = _JOINT.match(name)
    if m:
        kind, j, j0, ju, comp = m.groups()
        if j0:
            return f"joint {j0} zero offset"
        if ju:
            return f"joint {ju} frame" + (f" ({comp})" if comp else "")
        return {"theta": f"joint {j} zero offset", "alpha": f"joint {j} axis twist", "beta": f"joint {j} axis tilt",
                "a": f"joint {j} link length", "d": f"joint {j} offset along its axis",
                "l": f"joint {j} extra offset"}[kind]
    stem = name.split(".")[0]
    return f"mount {stem}" if re.match(r"^(T|[A-Z]\w*_T)_\w+$", stem) else name


def convention_moves(params, result) -> list[dict]:
    """Well-determined moves of ``result`` (identified (n,), std (n,), free (n,)) from ``params.nominal`` that no
    calibration correction can be (module docstring): [{names, what, text}]. Rotation-vector triplets
    (``<frame>.rx/.ry/.rz``, about the nominal) count as one rotation of that frame."""
    x, std, free = np.asarray(result.identified, float), np.asarray(result.std, float), np.asarray(result.free, bool)
    nom, names, kinds = np.asarray(params.nominal, float), list(params.names), list(params.kinds)
    out, done = [], set()
    for i in np.flatnonzero(free):
        name = names[i]
        if name in done:
            continue
        dev = x[i] - nom[i]
        if kinds[i] == "angle" and name.endswith((".rx", ".ry", ".rz")):
            stem = name[:-3]
            idx = [names.index(stem + s) for s in (".rx", ".ry", ".rz") if stem + s in names]
            done.update(names[k] for k in idx)
            idx = [k for k in idx if free[k]]
            rv = x[idx] - nom[idx]
            ang = float(np.linalg.norm(rv))
            ang = 2 * np.pi - ang if ang > np.pi else ang
            sd = float(np.sqrt(np.sum(std[idx] ** 2)))
            if ang > CONVENTION_ANGLE_RAD and (np.isfinite(sd) and ang >= MOVE_SIGMAS * sd):
                comps = ", ".join(f"{names[k].rsplit('.', 1)[1]} {np.degrees(x[k] - nom[k]):+.1f}" for k in idx)
                what = describe(stem)
                out.append({"names": [names[k] for k in idx], "what": what,
                            "text": f"{what} rotated by {np.degrees(ang):.1f} deg ({comps} deg)"})
            continue
        determined = np.isfinite(std[i]) and abs(dev) >= MOVE_SIGMAS * std[i]
        if not determined:
            continue
        if kinds[i] == "angle":
            w = float(_wrap(dev))
            if abs(w) > CONVENTION_ANGLE_RAD:
                what = describe(name)
                out.append({"names": [name], "what": what, "text": f"{name} ({what}) moved by {np.degrees(w):+.1f} deg"})
        elif kinds[i] == "length" and abs(nom[i]) >= SIGN_FLOOR_M and np.sign(x[i]) == -np.sign(nom[i]) \
                and abs(x[i]) >= 0.5 * abs(nom[i]):
            what = describe(name)
            out.append({"names": [name], "what": what,
                        "text": f"{name} ({what}) changed sign: {nom[i] * 1e3:.1f} -> {x[i] * 1e3:.1f} mm"})
    return out


def _refit(setup, meas: Measurements, residual: str, params):
    """Plain LSE of ``params``' free set (at most REFIT_POSES evenly spread poses, REFIT_NFEV evaluations);
    (chi2/dof, result) or (nan, None) when the alternative cannot be fitted (e.g. non-finite values)."""
    from ..errors import VisionCalibError
    from ..identify import solve_lse

    n = len(meas.T_cam_target)
    if n > REFIT_POSES:
        meas = meas.subset(np.unique(np.linspace(0, n - 1, REFIT_POSES).round().astype(int)))
    try:
        with np.errstate(all="ignore"):
            res = solve_lse(setup.problem(meas, residual, params=params), max_nfev=REFIT_NFEV)
    except (VisionCalibError, np.linalg.LinAlgError, ValueError):
        return float("nan"), None
    return float(res.chi2_dof), res


def joint_sign_candidates(meas: Measurements) -> dict:
    """{label: measurements with joint j's readings negated} for every joint j (1-based labels)."""
    out = {}
    for j in range(np.shape(meas.joints)[1]):
        q = np.array(meas.joints, float)
        q[:, j] *= -1
        poses = np.array(meas.poses, float)
        if poses.shape == q.shape:
            poses[:, j] *= -1
        out[f"joint {j + 1}'s readings negated (its sign reversed in the input)"] = replace(meas, poses=poses, joints=q)
    return out


def joint_swap_candidates(meas: Measurements) -> dict:
    """{label: measurements with joints i and j's columns swapped} for every pair i < j (1-based labels): two
    columns of poses.csv in the wrong order."""
    out = {}
    n = np.shape(meas.joints)[1]
    for i in range(n):
        for j in range(i + 1, n):
            q = np.array(meas.joints, float)
            q[:, [i, j]] = q[:, [j, i]]
            poses = np.array(meas.poses, float)
            if poses.shape == q.shape:
                poses[:, [i, j]] = poses[:, [j, i]]
            out[f"joints {i + 1} and {j + 1} swapped (their columns in the wrong order in the input)"] = \
                replace(meas, poses=poses, joints=q)
    return out


def _fmt(v: float) -> str:
    return "not fitted" if not np.isfinite(v) else f"{v:.3g}"


def gross_failure(setup, meas: Measurements, ident, residual: str, where: str, alternatives: dict | None = None,
                  untested: str = "", motion_refusal: str | None = None, motion_check=None) -> dict | None:
    """None when the fit of ``ident`` (``steps.Identified`` of ``meas``) is neither far beyond its noise model
    nor moved to where no correction can be (module docstring), and ``motion_refusal`` is None; else {kind:
    "gross misfit" | "convention error" | "inconsistent motions", chi2_dof, moves: [text], motion_check: refusal
    or None, tests: [{candidate, chi2_dof, fits, fits_with_moves, motions_follow_joints}], message}.
    ``alternatives``: {what: Measurements} the caller builds from its raw input (e.g. the other pose direction);
    joint sign reversals are always tried. ``untested``: the causes the caller cannot test (named in the
    message). ``motion_refusal``: the refusal of the caller's motion-consistency check on ``meas``
    (``checks.motion_verdict``: rotations that do not follow the joints, a wrong length scale), a failure by
    itself; ``motion_check(Measurements) -> refusal | None``: that check, run on every candidate reading, which
    then fits only when its motions follow its joints too."""
    res, params = ident.result, ident.params
    chi2 = float(res.chi2_dof)
    moves = convention_moves(params, res)
    gross = np.isfinite(chi2) and chi2 > GROSS_CHI2_DOF
    if not gross and not moves and not motion_refusal:
        return None
    cands = dict(alternatives or {})
    cands.update(joint_sign_candidates(meas))
    cands.update(joint_swap_candidates(meas))
    tests, plain = [], []  # plain: the readings that fit without a convention move (whatever their motions)
    for what, alt in cands.items():
        c, r = _refit(setup, alt, residual, params)
        if gross:
            fits = bool(np.isfinite(c) and c < GROSS_CHI2_DOF and c * FIT_GAIN < chi2)
        else:  # a convention move or inconsistent motions at a good fit: the alternative must fit as well
            fits = bool(np.isfinite(c) and c <= 1.5 * chi2 + 1.0)
        moved = [m["text"] for m in convention_moves(params, r)] if fits else []
        follow = None if motion_check is None or not fits else motion_check(alt) is None
        tests.append({"candidate": what, "chi2_dof": c if np.isfinite(c) else None,
                      "fits": fits and not moved and follow is not False,
                      "fits_with_moves": moved if follow is not False else [], "motions_follow_joints": follow})
        if fits and not moved:
            plain.append(what)
    # an equivalent model reached by another reading (e.g. two parallel joints negated) fits too, but only the
    # right reading brings the model back to the nominal one: those are the hits; the others are named after
    hits = [t for t in tests if t["fits"]] or [t for t in tests if t["fits_with_moves"]]
    shown = hits or [t for t in tests if not t["candidate"].startswith(("joint ", "joints "))] or tests
    if not hits:  # readings that fit the poses but not their motions are named too
        shown += [t for t in tests if t["motions_follow_joints"] is False and t["candidate"] in plain and t not in shown]

    def line(t):
        c = _fmt(np.nan if t["chi2_dof"] is None else t["chi2_dof"])
        if t["fits"]:
            return f"{t['candidate']}: chi2/dof {c} -- this fits"
        if t["fits_with_moves"]:
            return f"{t['candidate']}: chi2/dof {c} -- fits, but moves {t['fits_with_moves'][0]}"
        if t["motions_follow_joints"] is False:
            return f"{t['candidate']}: chi2/dof {c} -- fits the poses, but its motions do not follow the joints"
        return f"{t['candidate']}: chi2/dof {c}"

    tested = "; ".join(line(t) for t in shown)
    n_joint = sum(t["candidate"].startswith("joint ") for t in tests)
    n_swap = sum(t["candidate"].startswith("joints ") for t in tests)
    if not hits and n_joint and len(shown) < len(tests):
        tested += f"; each of the {n_joint} joints' readings negated and each of the {n_swap} pairs swapped: no fit"
    also = f"; {motion_refusal}" if motion_refusal else ""
    if gross:
        kind = "gross misfit"
        head = (f"{where}: the fit is far beyond the noise model: chi2/dof {chi2:.3g} (residuals {np.sqrt(chi2):.0f} "
                f"times the stated noise; covariance errors and unmodelled robot errors stay below "
                f"{GROSS_CHI2_DOF:g}): a gross error in the input, not a calibration")
        if moves:
            head += f" (the fit moved {', '.join(m['text'] for m in moves[:3])})"
        head += also
    elif moves:
        kind = "convention error"
        head = (f"{where}: the identified model differs from the nominal one by more than any calibration correction: "
                f"{', '.join(m['text'] for m in moves[:6])}: a sign, direction or convention error in the input "
                f"(joint direction, joint zero, mount orientation or frame convention), not a calibration{also}")
    else:
        kind = "inconsistent motions"
        head = (f"{where}: {motion_refusal} (the fit itself reaches chi2/dof {_fmt(chi2)}: the model absorbed it), "
                "not a calibration")
    if hits:  # the reading that fits is the diagnosis: say it first
        head = (f"{where}: {hits[0]['candidate']}: that reading of the input fits (chi2/dof "
                f"{_fmt(np.nan if hits[0]['chi2_dof'] is None else hits[0]['chi2_dof'])}"
                + (", its motions follow its joints" if hits[0]["motions_follow_joints"] else "") + "). "
                + head[len(where) + 2:])
    msg = (f"{head}. Likely causes" + (", each checked for motion consistency and" if motion_check is not None
                                       else ",") + f" refitted on {min(len(meas.T_cam_target), REFIT_POSES)} poses: {tested}"
           + ("" if hits else " (none fits)") + (f". Not tested here: {untested}" if untested else ""))
    return {"kind": kind, "chi2_dof": chi2 if np.isfinite(chi2) else None, "limit_chi2_dof": GROSS_CHI2_DOF,
            "moves": [m["text"] for m in moves], "motion_check": motion_refusal, "tests": tests, "message": msg}


__all__ = ["gross_failure", "convention_moves", "joint_sign_candidates", "joint_swap_candidates", "describe", "GROSS_CHI2_DOF",
           "CONVENTION_ANGLE_RAD"]
