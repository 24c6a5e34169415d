"""Lack-of-fit tests: do the fitted residuals depend on the joints or on the image position? (numpy/scipy only)

The global chi-square (:func:`~vision_calib.identify.adequacy.model_adequacy`) misses a small smooth error
the model lacks: spread over 300 residual components, a joint-angle-dependent error of 0.01 deg on the
RX-90's joint 2 raises chi2/dof by less than its noise. Regressing the residuals on a few candidate error
shapes concentrates that power.

Let e (N,) be the whitened final residuals (``problem.whitening()``; N = n_obs * m, plus the problem's prior
rows) and A (N, p) the whitened Jacobian of the p free parameters at the solution. A candidate group is k
regressor columns X (n_obs, m, k) (whitened like the residuals) projected orthogonally to the column space
of A, Xp = (I - P_A) X, so what the parameters already absorb is not counted (a joint offset absorbs a
constant joint error). With B (N, r) an orthonormal basis of Xp (r = numerical rank) the group statistic is

    T = |B^T e|^2,   F = (T / r) / ((|e|^2 - T) / (dof - r)),   dof = N - rank(A),

F ~ F(r, dof - r) for a right (linear) model whatever the scale of obs_cov (``test="F"``, default: image
measurements carry errors their covariance misses), or T ~ chi2(r) when obs_cov is the true noise
(``test="chi2"``). Both are exact for a linear model: e = (I - P_A) eps and Xp is orthogonal to A -- when the
covariance's *shape* is right. It is not when a pose's measurement error varies with the view beyond its
covariance (a detector bias that a pose's frames share): on clean image-mode thesis_arm_eye_in_hand runs (held-out
error 1.29x its prediction) the F test of a joint flagged 3 of 20 seeds at a 1 % family level. So each named
group is also tested with a cluster-robust (CR2, one cluster per pose) covariance of its score
(:func:`_robust_test`, ``test="F"``); ``p_value`` is the larger of the two (``p_model``, ``p_robust``): a term is flagged only
when the residuals depend on it whatever each pose's own error covariance.

Candidate groups (each a test), all optional:

- ``joint j``: a joint error delta_j(q) = c + sum_h a_h sin(h q_j) + b_h cos(h q_j), h in ``harmonics``
  (default 1, 2: eccentricity and the 2nd-order terms of gears, encoders and bearings; c: an offset, absorbed
  when the model has one); columns ``joint_response[:, :, j] * f(q_j)``, joint_response (n_obs, m, n_joints)
  = d r / d(true joint error) (the residual change per rad of a joint's true value moving away from the reported one). Without
  joint_response each term acts on each residual component freely ((2 H + 1) m columns; no amplitudes).
- ``image position``: the target's normalised image coordinates (x/z, y/z of a target point, centred),
  acting on each residual component (2 m columns): measurement errors that depend on where the target is
  in the image (distortion, principal point).
- ``depth``: the target's distance z / mean(z) - 1 on each component (m columns): a scale error (focal
  length, target size) the parameters do not absorb.

The family that decides (``significant``): the named groups, each at ``level / n_groups`` (Bonferroni): on data
the model explains, the probability that a term is flagged is at most ``level``. The overall test (all columns
together) is reported beside them (``overall``, its p-value at the same threshold) but does not flag on its own:
image measurements carry view-dependent detector errors (pixel-phase locking, similar views) that spread thinly
over all columns; on clean image-mode H4 runs with a new true robot per seed it fired in 2 of 15
(``benchmarks/bench_honest.py``) where no named term did. A model error the verdict must name is one term.

:func:`parameter_shift` is the companion first-order question: how far do the parameters move when every
residual changes by dR (e.g. the poses re-measured with other camera intrinsics)?
"""

from __future__ import annotations

import functools

from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigError, DataError
from .identifiability import whitened_free_jacobian
from .problem import IdentificationProblem, IdentificationResult

#: default family-wise false-alarm level of the lack-of-fit tests
DEFAULT_LEVEL = 0.01
#: default harmonic orders of the joint-error candidates
DEFAULT_HARMONICS = (1, 2)
#: detection probability of the detectable amplitudes reported per joint harmonic
DETECT_POWER = 0.8
#: a projected regressor direction counts when its singular value exceeds this fraction of the columns' own
#: (unit) norm. A direction the parameters absorb to within 1 % in amplitude keeps < 1e-4 of a regressor's energy
#: (no power) but, normalised, magnifies second-order structure of the residuals: on clean synthetic H4 runs
#: (model 12, 81 poses) the overall test had p < 0.05 in 35 % of 100 runs with 1e-6, 7 % with 1e-2 (KS p 0.66)
RANK_TOL = 1e-2
#: a joint-error shape (one harmonic at one phase) whose group test sees at most this fraction of its own whitened
#: energy counts as absorbed by the parameters: no detectable amplitude (None). Round-off level: absorbed shapes
#: compute to 1e-17..1e-20 (also negative), the smallest meaningful fractions on the RX-90 example are ~3e-5
SEEN_TOL = 1e-12
#: detectable amplitudes above this [deg] are reported as None: a joint error of that size is no small error,
#: the first-order analysis (residual change per rad of joint error) that gives the amplitude does not hold
MAX_DETECTABLE_DEG = 10.0


def _stats():
    from scipy import stats

    return stats


def _free_problem(problem: IdentificationProblem, result: IdentificationResult) -> IdentificationProblem:
    """``problem`` with the result's free mask (the solver may have fixed unidentifiable parameters)."""
    free = np.asarray(result.free, bool)
    if len(free) != len(problem.params):
        raise DataError(f"lack_of_fit: the result has {len(free)} parameters, the problem {len(problem.params)}")
    if np.array_equal(free, problem.params.free):
        return problem
    return problem.with_params(problem.params.only_free([n for n, f in zip(problem.params.names, free) if f]))


def _whitened(problem: IdentificationProblem, result: IdentificationResult):
    """(W (n_obs, m, m), e (N,) whitened residuals with the prior rows, A (N, p) whitened free Jacobian)."""
    problem = _free_problem(problem, result)
    x = np.asarray(result.identified, float)
    W = problem.whitening()
    r = np.asarray(result.residuals, float)
    if r.shape != (problem.n_obs, problem.m):
        raise DataError(f"lack_of_fit: residuals of shape {r.shape}, the problem has ({problem.n_obs}, {problem.m})")
    e = np.concatenate([np.einsum("kij,kj->ki", W, r).ravel(), problem.prior_residual(x)])
    A = whitened_free_jacobian(problem, np.asarray(problem.jacobian(x), float), W)
    return W, e, A


def _column_basis(A: np.ndarray) -> np.ndarray:
    """Orthonormal basis (N, rank) of the column space of A (N, p) (columns normalised first)."""
    if A.shape[1] == 0:
        return np.zeros((A.shape[0], 0))
    nrm = np.linalg.norm(A, axis=0)
    U, s, _ = np.linalg.svd(A / np.where(nrm > 0, nrm, 1.0), full_matrices=False)
    tol = max(A.shape) * np.finfo(float).eps * (s[0] if s.size else 0.0) * 1e3
    return U[:, s > tol]


def _group_test(Q, e, dof_res, Xw, test):
    """Statistic of the projected columns Xw (N, k): dict with rank r, T, F, p_value, and the least-squares
    coefficients of the UNprojected columns (k,) with their covariance (k, k) (pseudo-inverse)."""
    nrm = np.linalg.norm(Xw, axis=0)
    keep = nrm > 0
    Xn = Xw[:, keep] / nrm[keep]
    Xp = Xn - Q @ (Q.T @ Xn)
    U, s, Vt = np.linalg.svd(Xp, full_matrices=False)
    ok = s > RANK_TOL
    r = int(ok.sum())
    rss = float(e @ e)
    if r == 0 or dof_res - r <= 0:
        return {"dof": r, "statistic": None, "p_value": None, "chi2": None}
    z = U[:, ok].T @ e
    T = float(z @ z)
    sig2 = max(rss - T, 0.0) / (dof_res - r)
    if test == "F":
        F = (T / r) / sig2 if sig2 > 0 else np.inf
        p = float(_stats().f.sf(F, r, dof_res - r))
        stat = float(F)
    else:
        p = float(_stats().chi2.sf(T, r))
        stat, sig2 = T, 1.0
    # coefficients of the normalised columns: Xp c = projection of e (minimum norm on the kept directions)
    Vk = Vt[ok].T / s[ok]
    c = Vk @ z
    C = sig2 * (Vk @ Vk.T)
    beta = np.zeros(Xw.shape[1])
    cov = np.zeros((Xw.shape[1], Xw.shape[1]))
    idx = np.flatnonzero(keep)
    beta[idx] = c / nrm[keep]
    cov[np.ix_(idx, idx)] = C / np.outer(nrm[keep], nrm[keep])
    return {"dof": r, "statistic": stat, "p_value": p, "chi2": T, "beta": beta, "cov": cov, "basis": U[:, ok]}


def _robust_test(Q, e, basis, clusters) -> float | None:
    """p-value of the group's columns (orthonormal ``basis`` (N, r), orthogonal to Q) with a cluster-robust
    covariance: one cluster per pose (its m rows) and per prior row (``clusters`` (N,) ids). The score z = B^T e
    has covariance sum_k B_k^T Sigma_k B_k, estimated from the residuals left by the group's own fit, each
    cluster's rescaled by (I - H_kk)^(-1/2) (CR2, H the hat matrix of [Q, B]); Wald W = z^T Omega^-1 z, referred to
    F(r, G - r) as W (G - r) / (r (G - 1)) (G clusters). Valid when a pose's error covariance is not the one
    the whitening assumed (a detector error that varies with the view) -- where the model F test is not; None
    when there are too few clusters."""
    r = basis.shape[1]
    ids, inv = np.unique(clusters, return_inverse=True)
    G = len(ids)
    if r == 0 or G - r < 2:
        return None
    z = basis.T @ e
    res = e - basis @ z
    H = np.hstack([Q, basis])
    S = np.zeros((G, r))
    for g in range(G):
        rows = np.flatnonzero(inv == g)
        Hk = H[rows] @ H[rows].T
        w, V = np.linalg.eigh(np.eye(len(rows)) - Hk)
        adj = V @ ((V.T @ res[rows]) / np.sqrt(np.clip(w, 1e-6, None)))
        S[g] = basis[rows].T @ adj
    omega = S.T @ S
    try:
        W = float(z @ np.linalg.solve(omega, z))
    except np.linalg.LinAlgError:
        return None
    return float(_stats().f.sf(W * (G - r) / (r * (G - 1)), r, G - r))


def _harmonics(q, harmonics) -> tuple[np.ndarray, list[str]]:
    """(n_obs, 2H + 1) [sin(h q), cos(h q)] per order h, then the constant 1, and their names."""
    cols, names = [], []
    for h in harmonics:
        cols += [np.sin(h * q), np.cos(h * q)]
        names += [f"sin {h}q", f"cos {h}q"]
    return np.stack(cols + [np.ones_like(q)], axis=1), names + ["1"]


def _per_component(f: np.ndarray, m: int) -> np.ndarray:
    """(n_obs, m, k m): each column of f (n_obs, k) acting on each residual component alone."""
    n, k = f.shape
    X = np.zeros((n, m, k * m))
    for c in range(m):
        X[:, c, c::m] = f
    return X


def lack_of_fit(problem: IdentificationProblem, result: IdentificationResult, joints: ArrayLike | None = None,
                joint_response: ArrayLike | None = None, image_xy: ArrayLike | None = None,
                depth: ArrayLike | None = None, level: float = DEFAULT_LEVEL,
                harmonics: Sequence[int] = DEFAULT_HARMONICS, test: str = "F") -> dict:
    """Lack-of-fit tests of ``result`` (fit of ``problem``, same poses in the same order; module docstring).

    joints: (n_obs, n_joints) rad, the reported joint values of each pose. joint_response: (n_obs, m,
    n_joints) residual change (SI) per rad of true joint error (None: free per-component harmonics).
    image_xy: (n_obs, 2) normalised image coordinates of the target (x/z, y/z). depth: (n_obs,) m, the
    target's distance along the optical axis. level: family-wise false-alarm level. test: "F" or "chi2".

    Returns a JSON-ready dict: test, level, n_tests, p_threshold (= level / n_tests), dof_residual,
    significant (bool), groups [{name, kind, term, dof, statistic, p_value (the larger of p_model and p_robust),
    p_model, p_robust (None: test="chi2" or too few poses), significant, ...}] (joint groups:
    joint (1-based), harmonics [{order, amplitude_deg, amplitude_std_deg, phase_deg, statistic,
    p_value, detectable_amplitude_deg [best, worst phase]}] from the fit of that order's sin/cos pair alone
    (order 0: the constant, when no parameter absorbs it; the detectable amplitude: flagged with probability
    DETECT_POWER by the group's model F test -- the decision also needs the cluster-robust test, so it is a lower
    bound; None where no amplitude is meaningful: a phase the parameters absorb, or one above
    MAX_DETECTABLE_DEG), best_order; other groups: effect_rms_sigma
    (RMS per pose of the fitted effect, noise std units) and coefficients (SI per unit regressor, per
    component)), overall {dof, statistic, p_value, significant}, message (empty when nothing is flagged).
    """
    if not 0 < level < 1:
        raise ConfigError(f"lack_of_fit: level={level}, expected 0 < level < 1")
    if test not in ("F", "chi2"):
        raise ConfigError(f"lack_of_fit: test={test!r}, expected 'F' or 'chi2'")
    W, e, A = _whitened(problem, result)
    n_obs, m = problem.n_obs, problem.m
    n_extra = e.size - n_obs * m  # prior rows: the regressors have no component there
    Q = _column_basis(A)
    dof_res = e.size - Q.shape[1]
    clusters = np.concatenate([np.repeat(np.arange(n_obs), m), n_obs + np.arange(n_extra)])
    groups = []  # (name, kind, term, X (n_obs, m, k), extra)

    def whiten(X):
        Xw = np.einsum("kij,kjl->kil", W, X).reshape(n_obs * m, -1)
        return np.vstack([Xw, np.zeros((n_extra, Xw.shape[1]))])

    if joints is not None:
        q = np.asarray(joints, float)
        if q.ndim != 2 or len(q) != n_obs:
            raise DataError(f"lack_of_fit: joints of shape {q.shape}, expected ({n_obs}, n_joints)")
        if joint_response is not None:
            G = np.asarray(joint_response, float)
            if G.shape != (n_obs, m, q.shape[1]):
                raise DataError(f"lack_of_fit: joint_response of shape {G.shape}, "
                                f"expected ({n_obs}, {m}, {q.shape[1]})")
        for j in range(q.shape[1]):
            f, names = _harmonics(q[:, j], harmonics)
            X = G[:, :, j, None] * f[:, None, :] if joint_response is not None else _per_component(f, m)
            groups.append((f"joint {j + 1}", "joint", f"q{j + 1}", X, {"joint": j + 1, "names": names}))
    if image_xy is not None:
        xy = np.asarray(image_xy, float)
        if xy.shape != (n_obs, 2):
            raise DataError(f"lack_of_fit: image_xy of shape {xy.shape}, expected ({n_obs}, 2)")
        groups.append(("image position", "image", "u, v", _per_component(xy - xy.mean(axis=0), m), {}))
    if depth is not None:
        z = np.asarray(depth, float).reshape(-1)
        if z.shape != (n_obs,) or not np.all(z > 0):
            raise DataError(f"lack_of_fit: depth must be (n_obs,) > 0, got shape {z.shape}")
        groups.append(("depth", "depth", "z", _per_component((z / z.mean() - 1.0)[:, None], m), {}))
    n_tests = len(groups)
    p_thr = level / max(n_tests, 1)
    out = {"test": test, "level": float(level), "n_tests": int(n_tests), "p_threshold": float(p_thr),
           "dof_residual": int(dof_res), "harmonics": [int(h) for h in harmonics], "groups": [], "overall": None}
    all_cols = []
    for name, kind, term, X, extra in groups:
        Xw = whiten(X)
        all_cols.append(Xw)
        g = _group_test(Q, e, dof_res, Xw, test)
        p_rob = _robust_test(Q, e, g["basis"], clusters) if g["statistic"] is not None and test == "F" else None
        p_dec = g["p_value"] if p_rob is None or g["p_value"] is None else max(g["p_value"], p_rob)
        row = {"name": name, "kind": kind, "term": term, "dof": g["dof"], "statistic": g["statistic"],
               "p_value": p_dec, "p_model": g["p_value"], "p_robust": p_rob,
               "significant": bool(p_dec is not None and p_dec < p_thr)}
        if g["statistic"] is not None:
            if kind == "joint" and joint_response is not None:
                lam = detectable_noncentrality(g["dof"], dof_res, p_thr, DETECT_POWER, test)
                row.update(joint=extra["joint"], **_joint_amplitudes(Q, e, dof_res, Xw, harmonics, test, lam,
                                                                     g["basis"]))
            else:
                row["effect_rms_sigma"] = float(np.sqrt(g["chi2"] / n_obs))  # the part no parameter absorbs
                row["coefficients"] = g["beta"].reshape(-1, m).tolist()
        out["groups"].append(row)
    if len(groups) > 1:
        g = _group_test(Q, e, dof_res, np.hstack(all_cols), test)
        out["overall"] = {"dof": g["dof"], "statistic": g["statistic"], "p_value": g["p_value"],
                          "significant": bool(g["p_value"] is not None and g["p_value"] < p_thr)}
    sig = [g for g in out["groups"] if g["significant"]]
    out["significant"] = bool(sig)  # named terms only (module docstring); the overall test is information
    out["message"] = lack_of_fit_message(out) if out["significant"] else ""
    return out


@functools.lru_cache(maxsize=256)
def detectable_noncentrality(dof: int, dof_res: int, p_threshold: float, power: float = DETECT_POWER,
                             test: str = "F") -> float:
    """Noncentrality lambda at which the group test (dof columns, threshold p_threshold) flags with probability
    ``power`` (noncentral F(dof, dof_res - dof) or chi2(dof)); the minimal detectable bias of geodesy. The
    distributions by their ``scipy.special`` functions (the same values as ``scipy.stats``' ncf / ncx2, without a
    distribution object per call); cached: the folds of one run ask the same."""
    from scipy.optimize import brentq
    from scipy.special import chdtri, chndtr, fdtri, ncfdtr

    if test == "F":
        d2 = dof_res - dof
        crit = float(fdtri(dof, d2, 1.0 - p_threshold))
        pw = lambda lam: 1.0 - float(ncfdtr(dof, d2, lam, crit)) - power  # noqa: E731
    else:
        crit = float(chdtri(dof, p_threshold))
        pw = lambda lam: 1.0 - float(chndtr(crit, dof, lam)) - power  # noqa: E731
    hi = 1.0
    while pw(hi) < 0:
        hi *= 2
    return float(brentq(pw, 0.0 if pw(0.0) > 0 else 1e-12, hi, xtol=1e-6))


def _detectable_deg(lam_star: float, seen: float, own: float) -> float | None:
    """Detectable amplitude [deg] sqrt(lam_star / seen) of a joint-error shape whose group test sees ``seen`` of
    noncentrality per rad^2, out of the shape's own whitened energy ``own`` per rad^2; None where no amplitude is
    meaningfully detectable: the test sees at most :data:`SEEN_TOL` of the shape's energy (the parameters absorb
    it; what is left is round-off), or the amplitude exceeds :data:`MAX_DETECTABLE_DEG` (beyond the first-order
    analysis). Without these bounds an absorbed phase read as a detectable amplitude of 1e+06-1e+07 deg
    (``process --refine-intrinsics`` of examples/rx90_eye_in_hand, joint 2)."""
    if not (own > 0 and seen > SEEN_TOL * own):
        return None
    amp = float(np.degrees(np.sqrt(lam_star / seen)))
    return amp if amp <= MAX_DETECTABLE_DEG else None


def _joint_amplitudes(Q, e, dof_res, Xw, harmonics, test, lam_star, B) -> dict:
    """Per harmonic order h: the sin/cos pair fitted alone (columns 2i, 2i+1 of Xw): amplitude sqrt(a^2 + b^2)
    [deg] of delta = a sin(h q) + b cos(h q) (of the part the test sees: a phase component the parameters absorb
    to within RANK_TOL counts 0), its std (first order), phase [deg] (delta = amp sin(h q +
    phase)), statistic and p-value, and detectable_amplitude_deg [best phase, worst phase]: the amplitude
    of a joint error A sin(h q + phase) that the group's test flags with probability DETECT_POWER (noncentrality
    ``lam_star`` = A^2 |B^T W x_phase|^2, B (N, r) the group test's basis, extreme over the phase; None where
    none is meaningful, e.g. at a phase the parameters absorb: :func:`_detectable_deg`); best_order =
    the order with the smallest p-value."""
    rows = []
    for i, h in enumerate(harmonics):
        X2 = Xw[:, 2 * i: 2 * i + 2]
        g = _group_test(Q, e, dof_res, X2, test)
        if g["statistic"] is None:
            continue
        a, b = g["beta"]
        amp = float(np.hypot(a, b))
        grad = np.array([a, b]) / amp if amp > 0 else np.zeros(2)
        sd = float(np.sqrt(max(grad @ g["cov"] @ grad, 0.0)))
        M = B.T @ X2  # what the group's test sees of each column, per rad
        ev, V = np.linalg.eigh(M.T @ M)  # noncentrality per rad^2, min/max over the phase
        own = np.sum((X2 @ V) ** 2, axis=0)  # the regressor's own energy in those two phase directions
        mda = [_detectable_deg(lam_star, ev[i], own[i]) for i in (1, 0)]
        rows.append({"order": int(h), "amplitude_deg": float(np.degrees(amp)),
                     "amplitude_std_deg": float(np.degrees(sd)),
                     "phase_deg": float(np.degrees(np.arctan2(b, a))), "statistic": g["statistic"],
                     "p_value": g["p_value"], "detectable_amplitude_deg": mda})
    X1 = Xw[:, 2 * len(harmonics):]  # the constant: a joint offset, unless a parameter absorbs it (then no row)
    g = _group_test(Q, e, dof_res, X1, test)
    if g["statistic"] is not None:
        mda = _detectable_deg(lam_star, float(np.sum((B.T @ X1) ** 2)), float(np.sum(X1 ** 2)))
        rows.append({"order": 0, "amplitude_deg": float(np.degrees(abs(g["beta"][0]))),
                     "amplitude_std_deg": float(np.degrees(np.sqrt(max(g["cov"][0, 0], 0.0)))),
                     "phase_deg": 90.0 if g["beta"][0] >= 0 else -90.0, "statistic": g["statistic"],
                     "p_value": g["p_value"], "detectable_amplitude_deg": [mda, mda]})
    best = min(rows, key=lambda r: r["p_value"])["order"] if rows else None
    return {"harmonics": rows, "best_order": best}


def lack_of_fit_message(lof: dict) -> str:
    """'residuals depend on joint 2 (sin/cos 2 q2, amplitude 0.011 deg, p 3e-06): an error the model lacks'
    for the most significant group of a :func:`lack_of_fit` dict (or the overall test)."""
    sig = sorted((g for g in lof.get("groups", []) if g.get("significant")), key=lambda g: g["p_value"])
    if not sig:
        return ""
    parts = []
    for g in sig:
        if g["kind"] == "joint":
            h = next((r for r in g.get("harmonics", []) if r["order"] == g.get("best_order")), None)
            if h and h["order"] == 0:
                what = f"a constant {g['term']} offset, {h['amplitude_deg']:.2g} deg, p {g['p_value']:.2g}"
            elif h:
                what = f"sin/cos {h['order']} {g['term']}, amplitude {h['amplitude_deg']:.2g} deg, p {g['p_value']:.2g}"
            else:
                what = f"p {g['p_value']:.2g}"
            parts.append(f"{g['name']} ({what})")
        else:
            parts.append(f"the target's {g['name']} ({g['term']}, effect {g.get('effect_rms_sigma', float('nan')):.2g} "
                         f"noise std per pose, p {g['p_value']:.2g})")
    return "residuals depend on " + "; ".join(parts) + ": an error the model lacks"


def parameter_shift(problem: IdentificationProblem, result: IdentificationResult, dR: ArrayLike) -> np.ndarray:
    """(n, d) first-order change of the parameters (SI; 0 for fixed ones) when every pose's residual changes by
    dR (n_obs, m, d) at the solution (d cases): the Gauss-Newton step -(A^T A)^+ A^T (W dR), A the whitened
    free Jacobian (prior rows included, their residuals unchanged)."""
    dR = np.asarray(dR, float)
    if dR.ndim == 2:
        dR = dR[:, :, None]
    W, _, A = _whitened(problem, result)
    if dR.shape[:2] != (problem.n_obs, problem.m):
        raise DataError(f"parameter_shift: dR of shape {dR.shape}, expected ({problem.n_obs}, {problem.m}, d)")
    b = np.einsum("kij,kjd->kid", W, dR).reshape(problem.n_obs * problem.m, -1)
    b = np.vstack([b, np.zeros((A.shape[0] - b.shape[0], b.shape[1]))])
    nrm = np.linalg.norm(A, axis=0)
    s = np.where(nrm > 0, nrm, 1.0)
    step = np.linalg.lstsq(A / s, -b, rcond=None)[0] / s[:, None]
    out = np.zeros((len(result.free), dR.shape[2]))
    out[np.flatnonzero(result.free)] = step
    return out


__all__ = ["lack_of_fit", "lack_of_fit_message", "parameter_shift", "detectable_noncentrality", "DEFAULT_LEVEL",
           "DEFAULT_HARMONICS", "DETECT_POWER", "SEEN_TOL", "MAX_DETECTABLE_DEG"]
