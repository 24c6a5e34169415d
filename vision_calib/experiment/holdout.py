"""Held-out accuracy of every identification (``process``, ``simulate``, ``process-poses``) and the decision that
protects the robot: no calibrated model that does not predict held-out poses better than the nominal one.

k-fold over poses (seeded permutation; default :data:`DEFAULT_FOLDS`): for each fold the SAME base parameter set
as the whole-data identification is identified on the other folds (the poses the whole-data fit flagged as
outliers are in no training set, but are predicted in their own fold), and each held-out pose is predicted by the
nominal model ("before") and by its fold's model ("after"). Errors are those of the chain's measured transform
(eye-in-hand: T_target_cam; fixed camera / H4: T_cam_target) in its reference frame, always as a pose (or
position) residual whatever residual the identification used: at the measured frame's origin ("target") and, with
``tcp`` (x, y, z in the flange frame, m), at that tool point. They include the measurement noise.

Per set: mean / RMS / 95th percentile / max of the position [mm] and rotation [deg] error norms, one per pose.
The change of RMS (after - before) has a 95 % interval from a paired bootstrap over the poses (flagged outliers
left out). Beside them the *predicted* accuracy of the whole-data model: the parameter covariance propagated to
each measured pose's target origin and tool point (median and 95th percentile of the position std norm [mm]), and
the predicted held-out RMS (fold covariance k/(k-1) x the whole-data one, plus the measurement covariance) with
the ratio observed / predicted (about 1 when the reported std are right).

Beside the nominal model, the plain alternative of a robot calibration: each fold's training poses fitted with
the robot at its nominal geometry and only the mounting transforms free (``mounts_only``). A fit that predicts
the measured poses better than the nominal model can still write a robot worse than the nominal one (the mounts
absorb most of the nominal model's error; the robot's parameters then absorb what the model misses): the
calibrated robot must not predict held-out poses worse than the mounts-only fit.

Decision (``decision.ok`` False -> the verdict fails, exit 3, no calibrated model): a fold whose training poses
cannot be identified (an identification error, not converged, or fewer equations than parameters); a held-out
RMS (position or rotation) significantly worse after than before (the interval above 0); or neither
significantly better (both intervals reaching 0); significantly worse than the mounts-only fit, when the base
set has both mount and robot parameters (neither significantly better nor worse than it: a warning, the
verdict's, as the folds' smaller training sets may be what lacks).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from ..errors import VisionCalibError
from ..identify.identifiability import IdentifiabilityReport
from ..rig import Measurements, Setup

#: default number of folds (fewer when there are fewer poses)
DEFAULT_FOLDS = 5
#: bootstrap draws of the RMS change's interval, and its level
BOOTSTRAP_DRAWS = 2000
INTERVAL_LEVEL = 0.95
#: relative step of the central differences of the tool point w.r.t. the parameters (scaled by the kind's scale)
FD_STEP = 1e-4


def fold_indices(n: int, folds: int, seed: int, groups=None) -> list[np.ndarray]:
    """k sorted index arrays partitioning range(n) (seeded permutation, sizes differing by at most 1).
    groups: (n,) a group number per index (``checks.same_joint_groups``: poses measured at the same joints); the
    members of a group always share a fold (a repeat in the training set would flatter its twin's held-out error):
    the groups in the order the permutation first meets them, each into the fold with the fewest indices so far.
    Without groups, or with n distinct ones, the split is the ungrouped one (the same folds for the same seed)."""
    perm = np.random.default_rng(int(seed)).permutation(n)
    if groups is None or len(set(np.asarray(groups).tolist())) == n:
        return [np.sort(p) for p in np.array_split(perm, folds)]
    groups = np.asarray(groups)
    parts: list[list[int]] = [[] for _ in range(folds)]
    for g in dict.fromkeys(groups[perm].tolist()):
        f = min(range(folds), key=lambda k: len(parts[k]))
        parts[f] += np.flatnonzero(groups == g).tolist()
    return [np.sort(np.array(p, int)) for p in parts]


def error_stats(dp_mm: np.ndarray, dr_deg: np.ndarray | None) -> dict:
    """n_poses and mean / RMS / p95 / max of per-pose position [mm] (and rotation [deg]) error norms."""
    def block(v, key, unit):
        return {f"{key}_mean_{unit}": float(np.mean(v)), f"{key}_rms_{unit}": float(np.sqrt(np.mean(v**2))),
                f"{key}_p95_{unit}": float(np.percentile(v, 95)), f"{key}_max_{unit}": float(np.max(v))}

    out = {"n_poses": int(len(dp_mm)), **block(dp_mm, "position", "mm")}
    if dr_deg is not None:
        out |= block(dr_deg, "rotation", "deg")
    return out


def _chain_T(setup: Setup, poses, x) -> np.ndarray:
    """(N, 4, 4) the chain's measured transform (T_target_cam eye-in-hand, else T_cam_target) at x."""
    T = setup.T_cam_target(poses, x)
    return np.linalg.inv(T) if getattr(setup, "mount", None) == "eye_in_hand" else T


def _tool_in_right(setup: Setup, x, tcp) -> np.ndarray | None:
    """The tool point (flange frame) in the chain's right frame (camera eye-in-hand, target fixed), (4,)."""
    chain = getattr(setup, "chain", None)
    if tcp is None or chain is None or not hasattr(chain, "nominal_transforms"):
        return None
    _, T_flange_right = chain.nominal_transforms(x)
    return np.linalg.solve(T_flange_right, np.r_[np.asarray(tcp, float), 1.0])


def tool_point_supported(setup: Setup) -> bool:
    """Whether ``tcp`` (a point of the flange frame) has a meaning for this setup (a serial chain's flange)."""
    return _tool_in_right(setup, setup.params.nominal, (0.0, 0.0, 0.0)) is not None


def _tool_errors_mm(setup_model: Setup, meas: Measurements, idx, x, tcp) -> np.ndarray | None:
    """(k,) position error norms [mm] at the tool point: measured chain transform vs the model's, both carrying
    the tool point through the model's right mount at x."""
    p = _tool_in_right(setup_model, x, tcp)
    if p is None:
        return None
    sub = meas.subset(idx)
    T_meas = sub.T_cam_target if getattr(setup_model, "mount", None) != "eye_in_hand" else np.linalg.inv(sub.T_cam_target)
    T_mod = _chain_T(setup_model, sub.poses, x)
    return np.linalg.norm((T_meas @ p)[:, :3] - (T_mod @ p)[:, :3], axis=1) * 1e3


def _eval_kind(setup: Setup) -> str:
    return "pose" if "pose" in setup.residuals else "position"


def _norms(r: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    dp = np.linalg.norm(r[:, :3], axis=1) * 1e3
    return dp, (np.degrees(np.linalg.norm(r[:, 3:6], axis=1)) if r.shape[1] >= 6 else None)


def rms_change_interval(before: np.ndarray, after: np.ndarray, rng: np.random.Generator) -> list[float]:
    """95 % paired-bootstrap interval of RMS(after) - RMS(before) over the poses (same unit as the inputs)."""
    return _interval(before, after, rng)


def _interval(before: np.ndarray, after: np.ndarray, rng: np.random.Generator) -> list[float]:
    """95 % paired-bootstrap interval of RMS(after) - RMS(before) over the poses (same unit as the inputs)."""
    n = len(before)
    idx = rng.integers(0, n, size=(BOOTSTRAP_DRAWS, n))
    d = np.sqrt(np.mean(after[idx] ** 2, axis=1)) - np.sqrt(np.mean(before[idx] ** 2, axis=1))
    a = (1 - INTERVAL_LEVEL) / 2
    return [float(np.quantile(d, a)), float(np.quantile(d, 1 - a))]


def predicted_accuracy(setup: Setup, meas: Measurements, x, free_names: Sequence[str], cov: np.ndarray,
                       tcp=None) -> dict:
    """The parameter covariance ``cov`` (n_free, n_free, of ``free_names``) propagated to every measured pose:
    position std norm [mm] of the chain transform's origin ("target") and of the tool point, median and 95th
    percentile; with ``per_pose`` position variances [m^2] (for the held-out prediction)."""
    ps = setup.params
    cols = [ps.names.index(n) for n in free_names]
    x = np.asarray(x, float)
    scale = np.asarray(getattr(ps, "scale", np.ones(len(ps.names))), float)
    p_tool = _tool_in_right(setup, x, tcp)
    pts = [np.array([0.0, 0.0, 0.0, 1.0])] + ([p_tool] if p_tool is not None else [])
    J = np.zeros((len(pts), len(meas.poses), 3, len(cols)))
    for k, c in enumerate(cols):
        h = FD_STEP * (scale[c] if np.isfinite(scale[c]) and scale[c] > 0 else 1.0)
        xp, xm = x.copy(), x.copy()
        xp[c] += h
        xm[c] -= h
        Tp, Tm = _chain_T(setup, meas.poses, xp), _chain_T(setup, meas.poses, xm)
        for i, p in enumerate(pts):
            pp = p if i == 0 else _tool_in_right(setup, xp, tcp)
            pm = p if i == 0 else _tool_in_right(setup, xm, tcp)
            J[i, :, :, k] = ((Tp @ pp)[:, :3] - (Tm @ pm)[:, :3]) / (2 * h)
    var = np.einsum("tnik,kl,tnil->tn", J, cov, J)  # trace of J cov J^T per point and pose [m^2]
    out = {"workspace": f"the {len(meas.poses)} measured poses"}
    for i, name in enumerate(("target", "tool")[: len(pts)]):
        s = np.sqrt(np.maximum(var[i], 0.0)) * 1e3
        out[name] = {"position_median_mm": float(np.median(s)), "position_p95_mm": float(np.percentile(s, 95)),
                     "position_max_mm": float(np.max(s))}
    out["per_pose_var_m2"] = var[0]
    return out


def holdout_validation(setup: Setup, meas: Measurements, method: str, residual: str | None,
                       analysis: IdentifiabilityReport, folds: int | None, seed: int, outliers: Sequence[str] = (),
                       tcp=None, result=None, fitted_setup: Setup | None = None) -> dict:
    """k-fold held-out accuracy of ``meas`` (module docstring). ``setup``: the nominal setup ("before");
    ``analysis``: the whole data's IdentifiabilityReport (its base parameters are identified in every fold);
    ``outliers``: labels the whole-data fit flagged; ``result`` / ``fitted_setup``: the whole-data identification
    (for the predicted accuracy). Returns the report's ``holdout`` block (with ``decision``): :func:`holdout_folds`
    then :meth:`HeldOut.block`."""
    return holdout_folds(setup, meas, method, residual, analysis, folds, seed, outliers, tcp, result,
                         fitted_setup).block()


def holdout_folds(setup: Setup, meas: Measurements, method: str, residual: str | None,
                  analysis: IdentifiabilityReport, folds: int | None, seed: int, outliers: Sequence[str] = (),
                  tcp=None, result=None, fitted_setup: Setup | None = None) -> "HeldOut":
    """The folds of :func:`holdout_validation` fitted and their held-out poses predicted (same arguments); the
    mounts-only baseline, the intervals, the predicted accuracy and the decision are left to :meth:`HeldOut.block`
    (the cause test reads :meth:`HeldOut.figures` of both hypotheses, the block only of the one it chooses)."""
    from .steps import identify_measurements

    labels = [str(lab) for lab in (meas.labels if len(meas.labels) else range(len(meas.poses)))]
    flagged = {str(o) for o in outliers}
    unknown = flagged - set(labels)
    if unknown:
        raise ValueError(f"held-out validation: outliers {sorted(unknown)} are not poses of the data")
    n = len(labels)
    from .checks import same_joint_groups

    groups = same_joint_groups(meas)  # repeats at the same joints share a fold
    k = int(min(folds or DEFAULT_FOLDS, len(set(groups.tolist()))))
    kind = _eval_kind(setup)
    fitted_setup = fitted_setup or setup
    base = set(analysis.base_parameters)  # (a prepared setup may have more: the H4's measured tilts)
    params = setup.params.only_free([nm for nm in setup.params.names if nm in base])
    h = HeldOut(setup, meas, method, residual, labels, flagged, n, k, kind, int(seed), tcp, result, fitted_setup)
    parts = fold_indices(n, k, seed, groups) if k >= 2 else []
    # each fold's least squares starts from the whole data's fit (its free parameters): the same minimum, fewer steps
    start = None if result is None else {nm: float(v) for nm, v, fr in zip(result.names, result.identified, result.free)
                                         if fr and np.isfinite(v)}
    for f, test in enumerate(parts):
        train = np.array(sorted(i for j, p in enumerate(parts) if j != f for i in p if labels[i] not in flagged), int)
        rec = {"fold": f + 1, "n_train": int(len(train)), "n_test": int(len(test)),
               "n_outliers_held_out": int(sum(labels[i] in flagged for i in test))}
        try:
            ident = identify_measurements(setup, meas.subset(train), method, residual, analysis, robust=False,
                                          context=f"held-out validation, fold {f + 1} of {k}", cross_check=False,
                                          diagnostics=False, start=start)  # only the fold's parameters are used
        except VisionCalibError as exc:
            h.fails.append(f"fold {f + 1} ({len(train)} training poses): {exc}")
            h.per_fold.append({**rec, "converged": False, "error": str(exc)})
            continue
        res, fsetup = ident.result, ident.setup
        rec |= {"converged": bool(res.converged), "n_identified": int(np.sum(res.free))}
        if not res.converged:
            h.fails.append(f"fold {f + 1} ({len(train)} training poses): the identification did not converge "
                           f"({res.message})")
        elif res.dof <= 0:
            h.fails.append(f"fold {f + 1} ({len(train)} training poses): {int(np.sum(res.free))} parameters from "
                           f"{int(np.sum(res.free)) + int(res.dof)} equations, no redundancy")
        before = setup.problem(meas.subset(test), kind, params=params).residual(setup.params.nominal)
        held_out = fsetup.problem(meas.subset(test), kind, params=fsetup.params)
        after = held_out.residual(res.identified)
        h.mount_fits.append((fsetup, ident.params, meas.subset(train), held_out))
        h.rb.append(before)
        h.ra.append(after)
        h.idx_all.append(test)
        t_b = _tool_errors_mm(setup, meas, test, setup.params.nominal, tcp)
        t_a = _tool_errors_mm(fsetup, meas, test, res.identified, tcp)
        if t_b is not None:
            h.tb.append(t_b)
            h.ta.append(t_a)
        h.per_fold.append({**rec, "before": error_stats(*_norms(before)), "after": error_stats(*_norms(after))})
    return h


class HeldOut:
    """The folds of :func:`holdout_folds`: per fold the record, the held-out residuals before (nominal) / after
    (the fold's fit) (n_test, m), the tool point errors [mm], and what the fold's mounts-only fit needs (fold setup,
    base parameter set, training measurements, held-out problem); the identification failures."""

    def __init__(self, setup, meas, method, residual, labels, flagged, n, k, kind, seed, tcp, result, fitted_setup):
        self.setup, self.meas, self.method, self.residual = setup, meas, method, residual
        self.labels, self.flagged, self.n, self.k, self.kind, self.seed = labels, flagged, n, k, kind, seed
        self.tcp, self.result, self.fitted_setup = tcp, result, fitted_setup
        self.per_fold, self.fails, self.mount_fits = [], [], []
        self.rb, self.ra, self.tb, self.ta, self.idx_all = [], [], [], [], []
        self._block = None

    def figures(self) -> dict:
        """The block's ``residual_kind``, ``residual_of`` and ``overall`` (all held-out poses, before / after; absent
        when no fold was identified): what the cause test compares, without the mounts-only fits."""
        out = {"residual_kind": self.kind, "residual_of": self._residual_of()}
        if self.idx_all:
            out["overall"] = {"n_poses": int(sum(len(i) for i in self.idx_all)),
                              "before": error_stats(*_norms(np.concatenate(self.rb))),
                              "after": error_stats(*_norms(np.concatenate(self.ra)))}
        return out

    def _residual_of(self) -> str:
        return "T_target_cam" if getattr(self.setup, "mount", None) == "eye_in_hand" else "T_cam_target"

    def block(self) -> dict:
        """The report's ``holdout`` block of :func:`holdout_validation` (computed once)."""
        if self._block is None:
            self._block = self._build()
        return self._block

    def _build(self) -> dict:
        meas, labels, flagged, k, seed, tcp = self.meas, self.labels, self.flagged, self.k, self.seed, self.tcp
        kind, result, fitted_setup, fails = self.kind, self.result, self.fitted_setup, self.fails
        rm = []
        for fsetup, params, train, held_out in self.mount_fits:
            mounts = _mounts_only(fsetup, params, train, self.method, self.residual)
            if mounts is not None:
                rm.append(held_out.residual(mounts))
        rb, ra, tb, ta, idx_all = self.rb, self.ra, self.tb, self.ta, self.idx_all
        out = {"folds": k, "seed": int(seed), "residual_kind": kind, "residual_of": self._residual_of(),
               "outliers": [lab for lab in labels if lab in flagged], "per_fold": self.per_fold,
               "tcp_m": None if tcp is None or not tb else [float(v) for v in tcp]}
        if not idx_all:
            out["decision"] = {"ok": False, "reason": "no fold could be identified: " + "; ".join(fails)
                               if fails else f"{self.n} poses cannot be split into 2 folds"}
            return out
        idx = np.concatenate(idx_all)
        rb, ra = np.concatenate(rb), np.concatenate(ra)
        keep = np.array([labels[i] not in flagged for i in idx])
        bp, br = _norms(rb)
        ap, ar = _norms(ra)
        out["overall"] = {"n_poses": int(len(idx)), "before": error_stats(bp, br), "after": error_stats(ap, ar)}
        out["without_outliers"] = None if keep.all() else {
            "n_poses": int(keep.sum()), "excluded": [labels[i] for i in sorted(idx[~keep])],
            "before": error_stats(bp[keep], None if br is None else br[keep]),
            "after": error_stats(ap[keep], None if ar is None else ar[keep])}
        rng = np.random.default_rng([int(seed), 26])
        inter = {"level": INTERVAL_LEVEL, "draws": BOOTSTRAP_DRAWS, "over": int(keep.sum()),
                 "position_rms_change_mm": _interval(bp[keep], ap[keep], rng)}
        if br is not None:
            inter["rotation_rms_change_deg"] = _interval(br[keep], ar[keep], rng)
        out["interval"] = inter
        if rm and len(rm) == len(idx_all):  # every fold had the baseline: the robot's share of the calibration
            mp, mr = _norms(np.concatenate(rm))
            rng_m = np.random.default_rng([int(seed), 27])  # its own stream: the other intervals stay as they were
            out["mounts_only"] = {
                "after": error_stats(mp, mr), "position_rms_change_mm": _interval(mp[keep], ap[keep], rng_m),
                **({"rotation_rms_change_deg": _interval(mr[keep], ar[keep], rng_m)} if mr is not None else {}),
                "how": "each fold's training poses fitted again with the robot at its nominal geometry and only the "
                       "mounting transforms free (Setup.is_mount_parameter): the calibrated model predicting the "
                       "held-out poses significantly worse than that is refused, neither better nor worse is a "
                       "warning (change = calibrated - mounts only, 95 % paired-bootstrap interval)"}
        if tb:
            tb, ta = np.concatenate(tb), np.concatenate(ta)
            out["tool"] = {"before": error_stats(tb, None), "after": error_stats(ta, None),
                           "position_rms_change_mm": _interval(tb[keep], ta[keep], rng)}
        if result is not None and np.all(np.isfinite(result.covariance)):
            free = [nm for nm, f in zip(result.names, result.free) if f]
            pred = predicted_accuracy(fitted_setup, meas, result.identified, free, result.covariance, tcp)
            pb = fitted_setup.problem(meas, kind, params=fitted_setup.params)
            meas_var = np.trace(pb.obs_cov[:, :3, :3], axis1=1, axis2=2)
            fold_var = pred.pop("per_pose_var_m2") * k / max(k - 1, 1)
            rms_pred = float(np.sqrt(np.mean((fold_var + meas_var)[idx][keep]))) * 1e3
            obs = float(np.sqrt(np.mean(ap[keep] ** 2)))
            pred["heldout_position_rms_mm"] = rms_pred
            pred["ratio_observed_to_predicted"] = obs / rms_pred if rms_pred > 0 else None
            out["predicted"] = pred
        out["decision"] = holdout_decision(out, fails)
        return out


def _mounts_only(fsetup: Setup, params, train: Measurements, method: str, residual: str | None):
    """The plain alternative of a robot calibration on a fold's training poses: the robot at its nominal geometry,
    only the mount parameters of the base set ``params`` free; the full parameter vector (n,) of that fit, or
    None when the base set has no mount or no robot parameter, or the fit fails."""
    from .steps import solve

    free = list(params.free_names)
    mounts = [n for n in free if fsetup.is_mount_parameter(n)]
    if not mounts or len(mounts) == len(free):
        return None
    try:
        res = solve(fsetup.problem(train, residual, params=fsetup.params.only_free(mounts)), method)
    except VisionCalibError:
        return None
    return res.identified if res.converged and np.all(np.isfinite(res.identified)) else None


def holdout_decision(h: dict, fails: list[str]) -> dict:
    """{ok, reason} of a ``holdout`` block ``h`` (its overall errors, intervals and ``mounts_only``) and the
    folds' identification failures ``fails``: see the module docstring."""
    if fails:
        return {"ok": False, "reason": "the k-fold training sets cannot identify the free parameters: "
                                       + "; ".join(fails[:3])}
    inter, b, a = h["interval"], h["overall"]["before"], h["overall"]["after"]
    changes = [("position", "mm", inter["position_rms_change_mm"])]
    if "rotation_rms_change_deg" in inter:
        changes.append(("rotation", "deg", inter["rotation_rms_change_deg"]))
    figs = "; ".join(f"{q} RMS {b[f'{q}_rms_{u}']:.4g} -> {a[f'{q}_rms_{u}']:.4g} {u} (change {lo:+.3g}..{hi:+.3g} "
                     f"{u}, {int(inter['level'] * 100)} % interval)" for q, u, (lo, hi) in changes)
    worse = [q for q, _, (lo, _) in changes if lo > 0]
    better = [q for q, _, (_, hi) in changes if hi < 0]
    if worse:
        return {"ok": False, "reason": f"the calibrated model predicts held-out poses worse than the nominal one in "
                                       f"{' and '.join(worse)}: {figs}"}
    if not better:
        return {"ok": False, "reason": f"the calibrated model does not predict held-out poses better than the "
                                       f"nominal one: {figs}"}
    m = h.get("mounts_only")
    if m is not None:  # the robot's own parameters must earn their place against calibrating the mounts alone
        mch = [(q, u, m[f"{q}_rms_change_{u}"]) for q, u, _ in changes if f"{q}_rms_change_{u}" in m]
        mfig = "; ".join(f"{q} RMS {m['after'][f'{q}_rms_{u}']:.4g} (mounts only) -> {a[f'{q}_rms_{u}']:.4g} {u} "
                         f"(calibrated; change {lo:+.3g}..{hi:+.3g} {u})" for q, u, (lo, hi) in mch)
        m_worse = [q for q, _, (lo, _) in mch if lo > 0]
        m_better = [q for q, _, (_, hi) in mch if hi < 0]
        todo = ("the robot's parameters may absorb an error the model does not represent (a mount, the camera "
                "model, per-chain geometry): record more poses spread over the workspace, more frames per pose, "
                "or calibrate the mounts only with the robot at its nominal geometry")
        if m_worse:
            return {"ok": False, "reason": f"the calibrated robot predicts held-out poses worse in "
                                           f"{' and '.join(m_worse)} than the nominal robot with only its mounts "
                                           f"calibrated: {mfig}; {todo}"}
        figs += f"; against the mounts-only calibration: {mfig}"
        if not m_better:  # no evidence either way: the folds' smaller training sets may be what lacks (a warning)
            return {"ok": True, "reason": f"held-out poses predicted better in {' and '.join(better)}: {figs}",
                    "warning": "the calibrated robot does not predict held-out poses significantly better than the "
                               "nominal robot with only its mounts calibrated (" + mfig + "): these poses do not show "
                               "the robot's own parameters help; " + todo}
    return {"ok": True, "reason": f"held-out poses predicted better in {' and '.join(better)}: {figs}"}


def with_holdout_warning(result, h: dict | None):
    """``result`` (an IdentificationResult) with the held-out decision's warning appended to its warnings (the
    verdict then says "warning"), or as it is when there is none."""
    w = None if h is None else h["decision"].get("warning")
    return result if not w else replace(result, warnings=tuple(result.warnings) + (w,))


def flagged_labels(meas: Measurements, rejected) -> list[str]:
    """Labels of the poses of ``meas`` among ``rejected`` [(label, reason)] (the identification's rejected poses:
    those removed before it, e.g. by the motion check, are not in ``meas`` and have nothing to predict)."""
    have = {str(lab) for lab in meas.labels}
    return [str(r[0]) for r in rejected if str(r[0]) in have]


def holdout_failure(h: dict | None) -> dict | None:
    """The report's ``failure`` for a held-out decision that is not ok (None when it is, or there is none)."""
    if h is None or h["decision"]["ok"]:
        return None
    return {"kind": "held-out validation", "message": "no calibrated model written: " + h["decision"]["reason"]}


def _fmt(b: dict, a: dict) -> str:
    def one(key, unit, nd):
        return (f"{key} mean {b[f'{key}_mean_{unit}']:.{nd}f} -> {a[f'{key}_mean_{unit}']:.{nd}f}, "
                f"RMS {b[f'{key}_rms_{unit}']:.{nd}f} -> {a[f'{key}_rms_{unit}']:.{nd}f}, "
                f"95 % {b[f'{key}_p95_{unit}']:.{nd}f} -> {a[f'{key}_p95_{unit}']:.{nd}f}, "
                f"max {b[f'{key}_max_{unit}']:.{nd}f} -> {a[f'{key}_max_{unit}']:.{nd}f} {unit}")

    return one("position", "mm", 3) + ("; " + one("rotation", "deg", 4) if "rotation_rms_deg" in b else "")


def holdout_lines(h: dict | None) -> list[str]:
    """Summary lines of :func:`holdout_validation`."""
    if h is None:
        return ["held-out validation skipped: the fit failed (see the verdict)"]
    out = h.get("outliers") or []
    lines = [f"held-out {h['folds']}-fold validation (seed {h['seed']}, errors of {h['residual_of']}"
             + (f"; the {len(out)} flagged outlier poses are in no training set" if out else "") + "):"]
    if "overall" in h:
        o = h["overall"]
        lines.append(f"  at the target, all {o['n_poses']} poses"
                     + (f" (the {len(out)} flagged outliers included)" if out else " (none flagged as an outlier)")
                     + ": " + _fmt(o["before"], o["after"]))
        c = h.get("without_outliers")
        if c:
            names = ", ".join(map(str, c["excluded"][:10])) + (", ..." if len(c["excluded"]) > 10 else "")
            lines.append(f"  without the {len(c['excluded'])} flagged outliers ({names}), {c['n_poses']} poses: "
                         + _fmt(c["before"], c["after"]))
        if h.get("tool"):
            t = h["tool"]
            lo, hi = t["position_rms_change_mm"]
            lines.append(f"  at the tool point {h['tcp_m']} m (flange frame): " + _fmt(t["before"], t["after"])
                         + f" (RMS change {lo:+.3g}..{hi:+.3g} mm)")
        p = h.get("predicted")
        if p:
            tool = p.get("tool")
            lines.append(f"  predicted from the parameter covariance over {p['workspace']}: target position std "
                         f"median {p['target']['position_median_mm']:.3g} mm, 95 % {p['target']['position_p95_mm']:.3g} mm"
                         + (f"; tool point median {tool['position_median_mm']:.3g} mm, 95 % "
                            f"{tool['position_p95_mm']:.3g} mm" if tool else "")
                         + f"; held-out RMS predicted {p['heldout_position_rms_mm']:.3g} mm, observed / predicted "
                         + (f"{p['ratio_observed_to_predicted']:.2f}" if p.get("ratio_observed_to_predicted") else "n/a"))
    for f in h["per_fold"]:
        if "error" in f:
            lines.append(f"  fold {f['fold']}: {f['error']}")
            continue
        no = f.get("n_outliers_held_out")
        lines.append(f"  fold {f['fold']} ({f['n_test']} poses held out"
                     + (f", {no} flagged outlier{'s' if no > 1 else ''}" if no else "") + "): "
                     + _fmt(f["before"], f["after"]) + ("" if f["converged"] else " NOT CONVERGED"))
    lines.append(("  decision: ok, " if h["decision"]["ok"] else "  decision: FAILED, ") + h["decision"]["reason"])
    return lines


__all__ = ["DEFAULT_FOLDS", "fold_indices", "holdout_decision", "with_holdout_warning", "error_stats", "rms_change_interval", "holdout_validation", "holdout_folds", "HeldOut", "holdout_failure", "holdout_lines",
           "predicted_accuracy", "tool_point_supported", "flagged_labels"]
