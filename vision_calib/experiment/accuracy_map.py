"""Where is the calibrated robot accurate? The predicted tool-point accuracy over its workspace (report.json
``accuracy_map``, report.html "Accuracy map", ``plan`` before any image).

Points: a grid of tool positions (:data:`PER_AXIS` per axis) over the box of the calibration poses' tool positions,
widened on every side by :data:`MARGIN` of its size, at least :data:`MIN_MARGIN_M`; each grid position is held with
the tool orientation of the nearest calibration pose and turned into a joint set by the calibrated model's inverse
kinematics (``deploy.kinematics``, started from that pose's joints; positions it does not reach are left out). A
point outside the convex hull of the calibration tool positions is ``extrapolated``; the calibration poses themselves
are points of the map too (``calibration``: true).

At each joint set q the tool pose T_base_tool(q) (``deploy.kinematics``: the robot alone, base frame, tool =
flange + tcp; the camera and target mounts are not in it, so their uncertainty, a nuisance here, drops out) has
the covariance J_x C J_x^T + sigma_q^2 J_q J_q^T [m, rad; translation, then rotation vector, base frame]: C (n, n)
the identified parameters' covariance (scaled by the fit's variance factor where above 1), J_x the analytic
parameter Jacobian of the tool pose, sigma_q [rad] the joints' repeatability (0 when not known: recorded data)
through the joint Jacobian J_q. ``r95_mm`` / ``r95_deg``: the radius holding 95 % of the position / rotation error
of that Gaussian (:func:`norm_quantile`: the exact quantile of the norm of a 3-D Gaussian, not a per-axis sigma).
The measurement noise of a camera is not in it: the map is the error of the model's tool pose, what a controller
commanding q gets; the held-out figures of the report are the errors of a measurement.

Frames: the model's base frame, whose convention the parameters that no pose identifies fix at their nominal
values, registered on the calibration poses (:func:`registration`: their mean tool pose error removed, what a base
or mount transform absorbs; an eye-in-hand calibration sees the tool well relative to where it was calibrated, the
robot's base poorly). The ``not_covered`` entries name the parameters no pose identifies whose deviation the tool
pose carries (e.g. a camera mount's offset along the flange axis, folded into d6): the map assumes them nominal. In
a simulation ``true_error_mm`` / ``true_error_deg`` are the tool pose errors of the calibrated model against the
true robot at each q (a joint error drawn with sigma_q where it is not 0), registered the same way
(:func:`registered_error`), ``true_error_z`` their normalised position error, and ``coverage`` the share of points
within their r95.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from .. import frames as F
from ..config import Section
from ..errors import DataError, VisionCalibError

#: probability of the radii
LEVEL = 0.95
#: grid positions per axis, and the widening of the calibration poses' box on every side: this share of its size, at
#: least MIN_MARGIN_M (the workspace around a compact set of calibration poses)
PER_AXIS = 7
MARGIN = 0.25
MIN_MARGIN_M = 0.1
#: smallest box size [m] per axis (a flat set of calibration poses still gets a 3-D grid): this share of its largest
#: size, at least MIN_SIZE_M
FLAT_SHARE = 0.25
MIN_SIZE_M = 0.02
#: random stream of a simulation's joint errors (sigma_q) at the map's points: numpy default_rng([seed, STREAM_MAP])
STREAM_MAP = 37
#: parameter errors drawn from the covariance for the coverage a correct map gives (:func:`coverage_law`), and how
#: many of those coverages a simulation's report keeps (pooling over runs: a draw per run)
LAW_DRAWS = 4000
LAW_KEPT = 200
#: Gauss-Legendre nodes per angle of the sphere quadrature of :func:`norm_quantile`, and its Newton steps
QUAD_NODES = 24
NEWTON_STEPS = 8
#: ... which stop once every probability is within this of the level
NEWTON_TOL = 1e-13


# ------------------------------------------------------------------------------------------ the radius of a Gaussian
def _octant_nodes(n: int = QUAD_NODES) -> tuple[np.ndarray, np.ndarray]:
    """(u (n^2, 3) unit vectors of the first octant, weights (n^2,) summing to 1) for the mean of an even function over
    the sphere: u = (c, sqrt(1 - c^2) cos phi, sqrt(1 - c^2) sin phi), c uniform on [0, 1] and phi on [0, pi/2] (the
    area element is dc dphi), Gauss-Legendre in both."""
    t, w = np.polynomial.legendre.leggauss(n)
    c, wc = (t + 1) / 2, w / 2
    phi, wp = (t + 1) * np.pi / 4, w / 2
    C, P = np.meshgrid(c, phi, indexing="ij")
    s = np.sqrt(1 - C**2)
    u = np.stack([C, s * np.cos(P), s * np.sin(P)], axis=-1).reshape(-1, 3)
    return u, np.outer(wc, wp).reshape(-1)


def norm_quantile(cov: ArrayLike, level: float = LEVEL) -> np.ndarray:
    """The radius r with P(|e| <= r) = level for e ~ N(0, cov), cov (..., 3, 3) symmetric positive semi-definite;
    returns (...) in the unit of e. Exact up to quadrature (relative error below 1e-6): with cov = V diag(lam) V^T,
    |e|^2 = rho^2 q(u), rho^2 ~ chi2(3) independent of the direction u uniform on the sphere, q(u) = sum lam_i u_i^2;
    so P(|e|^2 <= t) = mean over u of F_chi2(3)(t / q(u)) (a product Gauss rule on the octant, the polar axis along
    the largest eigenvalue), solved for t by safeguarded Newton steps between lam_max chi2_1(level) and lam_max
    chi2_3(level), from the Welch-Satterthwaite approximation. Isotropic sigma: 2.796 sigma at 95 %; one direction
    only: 1.960 sigma. Non-finite cov: NaN."""
    from scipy.special import chdtri, erf

    cov = np.asarray(cov, float)
    if cov.shape[-2:] != (3, 3):
        raise ValueError(f"norm_quantile: expected (..., 3, 3) covariances, got shape {cov.shape}")
    shape = cov.shape[:-2]
    C = cov.reshape(-1, 3, 3)
    out = np.full(len(C), np.nan)
    ok = np.all(np.isfinite(C), axis=(1, 2))
    if not ok.any():
        return out.reshape(shape)
    lam = np.clip(np.linalg.eigvalsh(0.5 * (C[ok] + np.swapaxes(C[ok], 1, 2))), 0.0, None)[:, ::-1]  # largest first
    lmax = lam[:, 0]
    zero = lmax <= 0
    rel = lam / np.where(zero, 1.0, lmax)[:, None]
    u, w = _octant_nodes()
    q = rel @ (u**2).T  # (N, nodes), q in (0, 1]
    lo = np.full(len(q), chdtri(1, 1 - level))
    hi = np.full(len(q), chdtri(3, 1 - level))
    s1, s2 = rel.sum(axis=1), np.maximum((rel**2).sum(axis=1), 1e-300)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # the start: Welch-Satterthwaite
        t = np.clip(np.nan_to_num(s2 / np.maximum(s1, 1e-300) * chdtri(s1**2 / s2, 1 - level), nan=hi[0]), lo, hi)
        inf_q = not np.all(q > 0)  # x = inf where q = 0
        for _ in range(NEWTON_STEPS):  # in place, (N, nodes) each: the same arithmetic as the formulas in comments
            x = t[:, None] / q
            sx = np.sqrt(x)
            g = np.multiply(x, -0.5)  # g = sqrt(x) exp(-x / 2); 0 at x = inf
            np.exp(g, out=g)
            g *= sx
            if inf_q:
                g[~np.isfinite(x)] = 0.0
            a = np.divide(sx, np.sqrt(2.0), out=sx)  # p = (erf(sx / sqrt 2) - sqrt(2 / pi) g) @ w - level
            erf(a, out=a)
            a -= np.multiply(g, np.sqrt(2.0 / np.pi), out=x)
            p = a @ w - level  # the chi2(3) CDF, closed form
            if np.all(np.abs(p) <= NEWTON_TOL):
                break
            g /= np.sqrt(2 * np.pi)  # dens = (g / sqrt(2 pi) / q) @ w
            g /= q
            dens = g @ w
            lo = np.where(p < 0, t, lo)
            hi = np.where(p < 0, hi, t)
            step = t - p / np.where(dens > 0, dens, np.nan)
            t = np.where(np.isfinite(step) & (step >= lo) & (step <= hi), step, 0.5 * (lo + hi))  # (closed: a
            # converged t is a bracket end, and its Newton step stays there)
    r = np.sqrt(t * lmax)
    r[zero] = 0.0
    out[ok] = r
    return out.reshape(shape)


# ------------------------------------------------------------------------------------------------ the model's robot
def model_kinematics(setup, tcp: ArrayLike | None = None):
    """(deploy kinematics of the setup's robot, parameter names in its order): the robot as a calibrated-model file
    rebuilds it (``rig.registry`` kind ``load_model`` from the setup's ``model_dict`` and robot file), so the map is
    computed by the same kinematics as ``CalibratedRobot`` (``vision-calib compare``, ``compensate``). tcp: x, y, z
    [m] of the tool in the flange frame (default 0)."""
    from ..deploy.kinematics import kinematics_for
    from ..rig.registry import get_kind

    robot_path = setup.meta.get("robot_path")
    if not robot_path:
        raise DataError(f"{setup.name}: the setup names no robot file: no tool kinematics for the accuracy map")
    robot = get_kind(setup.kind).load_model(Section(dict(setup.model_dict()), robot_path), Path(robot_path))
    names = tuple(robot.params.names)
    missing = sorted(set(names) - set(setup.params.names))
    if missing:
        raise DataError(f"{setup.name}: the robot file's parameters {missing} are not the setup's")
    kin = kinematics_for(robot, np.zeros(3) if tcp is None else np.asarray(tcp, float))
    return kin, names


def in_order(names: Sequence[str], own: Sequence[str], x: ArrayLike) -> np.ndarray:
    """x (len(own),) ordered by ``own`` -> (len(names),) ordered by ``names``."""
    pos = {n: i for i, n in enumerate(own)}
    return np.asarray(x, float)[[pos[n] for n in names]]


def embed_covariance(names: Sequence[str], cov_names: Sequence[str], cov: ArrayLike) -> np.ndarray:
    """(n, n) covariance in ``names`` order of a covariance ``cov`` over ``cov_names`` (zeros elsewhere; names not in
    ``names``, e.g. nuisance or mount tilts the robot does not have, are dropped: their marginal is the sub-block)."""
    cov = np.asarray(cov, float)
    out = np.zeros((len(names), len(names)))
    pos = {n: i for i, n in enumerate(names)}
    keep = [k for k, n in enumerate(cov_names) if n in pos]
    idx = [pos[cov_names[k]] for k in keep]
    out[np.ix_(idx, idx)] = cov[np.ix_(keep, keep)]
    return out


# --------------------------------------------------------------------------------------------------- the grid
def _inside_hull(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(M,) bool: X (M, 3) inside the convex hull of P (K, 3); the box of P when the hull is flat or P too few."""
    lo, hi = P.min(axis=0), P.max(axis=0)
    box = np.all((X >= lo - 1e-9) & (X <= hi + 1e-9), axis=1)
    if len(P) < 4:
        return box
    try:
        from scipy.spatial import Delaunay

        return Delaunay(P).find_simplex(X) >= 0
    except Exception:  # a flat or degenerate set (scipy's QhullError): the box
        return box


def workspace_grid(kin, x: np.ndarray, q_cal: np.ndarray, per_axis: int = PER_AXIS,
                   margin: float = MARGIN) -> dict:
    """The map's joint sets (module docstring) around the calibration joint sets q_cal (K, n_joints) on the model of
    x (kin's parameter order): {q (M, n), T (M, 4, 4) tool poses [m, base frame], ijk (M, 3) grid indices (-1 for
    the calibration poses, appended last), axes [3 x (per_axis,)] grid coordinates [m], extrapolated (M,) bool,
    calibration (M,) bool, cal_xyz (K, 3) [m], goals (per_axis^3), reached (grid positions reached)}."""
    q_cal = np.asarray(q_cal, float)
    T_cal = kin.tool(q_cal, x)
    P = T_cal[:, :3, 3]
    lo, hi = P.min(axis=0), P.max(axis=0)
    size = hi - lo
    floor = max(FLAT_SHARE * float(size.max()), MIN_SIZE_M)
    grow = np.maximum(size, floor) - size
    lo, hi = lo - grow / 2, hi + grow / 2
    size = hi - lo
    grow = np.maximum(margin * size, MIN_MARGIN_M if margin > 0 else 0.0)
    axes = [np.linspace(lo[a] - grow[a], hi[a] + grow[a], per_axis) for a in range(3)]
    ijk = np.stack(np.meshgrid(*[np.arange(per_axis)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    X = np.column_stack([axes[a][ijk[:, a]] for a in range(3)])
    near = np.argmin(((X[:, None, :] - P[None]) ** 2).sum(-1), axis=1)
    goals = T_cal[near].copy()
    goals[:, :3, 3] = X
    q, why = kin.inverse_rows(goals, x, q_start=q_cal[near], branch_only=True)
    ok = (np.asarray(why) == "") & np.all(np.isfinite(q), axis=1)
    q = q[ok]
    T = kin.tool(q, x) if len(q) else np.zeros((0, 4, 4))
    ext = ~_inside_hull(P, T[:, :3, 3])
    # the calibration poses themselves, last: the points of the map where the model was measured (grid index -1)
    return {"q": np.concatenate([q, q_cal]), "T": np.concatenate([T, T_cal]),
            "ijk": np.concatenate([ijk[ok], np.full((len(q_cal), 3), -1)]), "axes": axes,
            "extrapolated": np.concatenate([ext, np.zeros(len(q_cal), bool)]),
            "calibration": np.concatenate([np.zeros(len(q), bool), np.ones(len(q_cal), bool)]),
            "cal_xyz": P, "goals": int(len(X)), "reached": int(ok.sum())}


def registration(kin, x: np.ndarray, q_reg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(c (3,) [m], H (6, n)): the registration of the base frame on the calibration poses, to first order: the
    small rigid motion db = (dt, dw) of the model's base frame (translation at the centroid c of the tool positions
    at the joint sets q_reg (K, n_joints), rotation vector) that removes the mean tool pose error over those poses
    (dw: minus the mean rotation error, dt: minus the mean position error) is db = H dx for a parameter error dx (n,)
    [what a base / mount transform absorbs; :func:`registered_error` applies it to errors]."""
    T = kin.tool(q_reg, x)
    J = kin.tool_jacobian(q_reg, x)
    return T[:, :3, 3].mean(axis=0), -J.mean(axis=0)


def base_motion_lever(p: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(M, 6, 6) [[I, -[p - c]x], [0, I]]: the pose error at tool positions p (M, 3) of a base motion (dt at c, dw)."""
    Bt = np.zeros((len(p), 6, 6))
    Bt[:, :3, :3] = np.eye(3)
    Bt[:, :3, 3:] = -F.skew(p - c)
    Bt[:, 3:, 3:] = np.eye(3)
    return Bt


def registered_error(e_reg: np.ndarray, p_reg: np.ndarray, e: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(M, 6) pose errors e (M, 6) [m, rad] at tool positions p (M, 3) after the registration of :func:`registration`
    computed from the errors e_reg (K, 6) at the calibration tool positions p_reg (K, 3)."""
    db = -np.asarray(e_reg, float).mean(axis=0)
    return np.asarray(e, float) + base_motion_lever(np.asarray(p, float), np.asarray(p_reg, float).mean(axis=0)) @ db


def registered_jacobian(kin, x: np.ndarray, q: np.ndarray, reg: tuple | None) -> np.ndarray:
    """(M, 6, n) parameter Jacobian of the tool pose at q (M, n_joints) [base frame], after the registration ``reg``
    (:func:`registration`; None: none): J + [[I, -[p - c]x], [0, I]] H."""
    J = kin.tool_jacobian(q, x)
    if reg is None:
        return J
    c, H = reg
    return J + base_motion_lever(kin.tool(q, x)[:, :3, 3], c) @ H


def joint_term(kin, x: np.ndarray, q: np.ndarray, sigma_q_rad: float) -> np.ndarray | None:
    """(M, 6, 6) sigma_q^2 J_q J_q^T: the tool pose covariance [m, rad] of the joints' repeatability sigma_q [rad] at
    joint sets q (M, n), J_q the joint Jacobian of the tool pose on the model of x; None when sigma_q is 0."""
    if not sigma_q_rad > 0:
        return None
    from ..deploy.solve import joint_jacobian

    Jq = joint_jacobian(lambda v: kin.tool(v, x), q, kin.tool(q, x))
    return sigma_q_rad**2 * np.einsum("kin,kjn->kij", Jq, Jq)


def tool_covariance(kin, x: np.ndarray, cov: np.ndarray, q: np.ndarray, sigma_q_rad: float = 0.0,
                    reg: tuple | None = None, J: np.ndarray | None = None,
                    joint: np.ndarray | None = None) -> np.ndarray:
    """(M, 6, 6) covariance of the tool pose at joint sets q (M, n) [m, rad; translation then rotation vector, base
    frame]: J_x cov J_x^T (cov (n, n) of x, kin's order; J_x after the registration ``reg``, :func:`registration`)
    + sigma_q^2 J_q J_q^T (module docstring). J (M, 6, n) / joint (M, 6, 6): J_x and the joint term
    (:func:`joint_term`) when the caller has them already."""
    J = registered_jacobian(kin, x, q, reg) if J is None else J
    C = np.einsum("kin,nm,kjm->kij", J, cov, J)
    joint = joint_term(kin, x, q, sigma_q_rad) if joint is None else joint
    if joint is not None:
        C = C + joint
    return 0.5 * (C + np.swapaxes(C, 1, 2))


def coverage_law(J: np.ndarray, cov: np.ndarray, r95: np.ndarray, rng: np.random.Generator,
                 draws: int = LAW_DRAWS, extra: np.ndarray | None = None) -> np.ndarray:
    """(draws,) the share of the M points whose position error is within its r95 (M,) [m] when the parameter error is
    drawn from the map's own law N(0, cov) (cov (n, n)) through the registered Jacobian J (M, 3, n), plus, per point
    and independently, N(0, extra) (extra (M, 3, 3): e.g. the joints' repeatability term): the coverage a correct
    map gives. Its mean is the level; its spread is wide because every point of one calibration shares the
    same parameter error (one draw moves the whole map), so a pooled coverage of a few runs is judged against this
    law, not against a band around the level."""
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    D = rng.standard_normal((draws, w.size)) * np.sqrt(np.clip(w, 0.0, None)) @ V.T
    L = None
    if extra is not None:
        we, Ve = np.linalg.eigh(0.5 * (extra + np.swapaxes(extra, 1, 2)))
        L = Ve * np.sqrt(np.clip(we, 0.0, None))[:, None, :]
    out = np.empty(draws)
    Jf = np.asarray(J, float).reshape(-1, w.size)  # (M 3, n)
    for a in range(0, draws, 500):  # (500, M, 3) at a time, one BLAS product
        E = (D[a:a + 500] @ Jf.T).reshape(-1, J.shape[0], 3)
        if L is not None:
            E += np.einsum("kij,dkj->dki", L, rng.standard_normal(E.shape))
        out[a:a + 500] = np.mean(np.linalg.norm(E, axis=2) <= r95, axis=1)
    return out


def pooled_coverage_law(laws: Sequence[Sequence[float]], rng: np.random.Generator, draws: int = 20000) -> np.ndarray:
    """(draws,) the mean coverage over R runs when each run's coverage follows its own law (``laws``: R samples of
    :func:`coverage_law`, e.g. ``coverage.under_the_map.draws`` of R reports): one draw per run, averaged."""
    laws = [np.asarray(v, float) for v in laws]
    return np.mean([v[rng.integers(0, v.size, draws)] for v in laws], axis=0)


# --------------------------------------------------------------------------------------------------- the block
def _stats(v: np.ndarray) -> dict | None:
    v = v[np.isfinite(v)]
    if not v.size:
        return None
    return {"median": float(np.median(v)), "p95": float(np.percentile(v, 95)), "max": float(v.max()), "n": int(v.size)}


def not_covered(names: Sequence[str], kin, x: np.ndarray, q: np.ndarray, identifiability: dict | None) -> list[dict]:
    """[{parameter, carried_by}] of the parameters no pose identifies whose deviation the reduction folds into
    parameters the tool pose depends on (``identifiability["couplings"]``): the map assumes them nominal."""
    if not identifiability or not len(q):
        return []
    J = kin.tool_jacobian(q[: min(len(q), 20)], x)
    moves = {n for k, n in enumerate(names) if np.abs(J[:, :, k]).max() > 1e-12}
    out = []
    for c in identifiability.get("couplings", []):
        into = [k for k, v in (c.get("combination_si") or {}).items() if k in moves and abs(v) > 1e-9]
        if into and not c.get("no_effect") and c["parameter"] not in moves:
            out.append({"parameter": c["parameter"], "carried_by": into})
    return out


def build_map(kin, names: Sequence[str], x: ArrayLike, cov: ArrayLike, q_cal: ArrayLike, *, tcp=None,
              sigma_q_rad: float = 0.0, identifiability: dict | None = None, truth=None,
              per_axis: int = PER_AXIS, margin: float = MARGIN, covariance_of: str = "",
              rng: np.random.Generator | None = None) -> dict:
    """The report's ``accuracy_map`` block (module docstring) of the model (kin, ``names`` its parameter order) at
    parameters x (n,) with covariance cov (n, n) [SI], calibrated on joint sets q_cal (K, n_joints). truth: (kin of the
    true robot, its x) in a simulation: adds ``true_error_mm`` / ``true_error_deg`` per point and the coverage
    (rng: the joint errors drawn when sigma_q_rad > 0). covariance_of: where cov comes from, in words."""
    x = np.asarray(x, float)
    cov = np.asarray(cov, float)
    if cov.shape != (len(x), len(x)) or not np.all(np.isfinite(cov)):
        raise DataError(f"accuracy map: the parameter covariance is not a finite {len(x)} x {len(x)} matrix")
    g = workspace_grid(kin, x, q_cal, per_axis, margin)
    q, T = g["q"], g["T"]
    if not len(q):
        raise DataError(f"accuracy map: none of the {g['goals']} grid positions around the calibration poses is "
                        "reached by the calibrated model")
    q_cal = np.asarray(q_cal, float)
    reg = registration(kin, x, q_cal)
    J, Cq = registered_jacobian(kin, x, q, reg), joint_term(kin, x, q, sigma_q_rad)
    C = tool_covariance(kin, x, cov, q, reg=reg, J=J, joint=Cq)
    r_mm = norm_quantile(C[:, :3, :3]) * 1e3
    r_deg = np.degrees(norm_quantile(C[:, 3:, 3:]))
    ext = g["extrapolated"]
    pts = [{"xyz_m": [float(v) for v in T[k, :3, 3]], "q_rad": [float(v) for v in q[k]],
            "ijk": [int(v) for v in g["ijk"][k]], "extrapolated": bool(ext[k]),
            "calibration": bool(g["calibration"][k]), "r95_mm": float(r_mm[k]), "r95_deg": float(r_deg[k])}
           for k in range(len(q))]
    block = {
        "level": LEVEL, "tcp_m": [float(v) for v in (np.zeros(3) if tcp is None else np.asarray(tcp, float))],
        "frame": "the robot's base frame (the model's) registered on the calibration poses (their mean tool pose "
                 "error removed: what a base or mount transform absorbs), tool = flange + tcp",
        "how": ("r95: radius holding 95 % of the tool pose error of N(0, J C J^T + sigma_q^2 J_q J_q^T) at each "
                "joint set (exact quantile of the norm of the 3-D Gaussian); C: " + (covariance_of or
                "the identified parameters' covariance") + "; the mounts (camera, target) are not in the tool pose, "
                "their uncertainty drops out; no camera measurement noise (the error of the model's tool pose)"),
        "repeatability_sigma_q_deg": float(np.degrees(sigma_q_rad)),
        "grid": {"per_axis": int(per_axis), "margin": float(margin),
                 "axes_m": [[float(v) for v in a] for a in g["axes"]], "goals": g["goals"], "reached": g["reached"],
                 "how": f"tool positions on the box of the calibration tool positions widened on every side by the "
                        f"margin (share of its size), at least {MIN_MARGIN_M * 1e3:g} mm, each with the tool "
                        "orientation of the nearest calibration pose, joint sets by the model's inverse kinematics "
                        "from that pose's joints; extrapolated: outside the convex hull of the calibration tool "
                        "positions"},
        "calibration_xyz_m": [[float(v) for v in p] for p in g["cal_xyz"]],
        "calibration_q_rad": [[float(v) for v in p] for p in q_cal],
        "not_covered": not_covered(names, kin, x, q, identifiability),
        "n_points": len(pts), "n_extrapolated": int(ext.sum()),
        "r95_mm": {"inside": _stats(r_mm[~ext]), "extrapolated": _stats(r_mm[ext])},
        "r95_deg": {"inside": _stats(r_deg[~ext]), "extrapolated": _stats(r_deg[ext])},
        "points": pts,
    }
    if truth is not None:
        tkin, x_true = truth
        qt = q
        if sigma_q_rad > 0:
            rng = rng or np.random.default_rng(0)
            qt = q + rng.normal(scale=sigma_q_rad, size=q.shape)
        x_true = np.asarray(x_true, float)
        T_cal = T[g["calibration"]]  # the calibration poses' tool poses on the model, the map's last points
        e = registered_error(F.pose_error(tkin.tool(q_cal, x_true), T_cal), T_cal[:, :3, 3],
                             F.pose_error(tkin.tool(qt, x_true), T), T[:, :3, 3])
        e_mm = np.linalg.norm(e[:, :3], axis=1) * 1e3
        z = np.sqrt(np.einsum("ki,ki->k", e[:, :3], np.linalg.solve(C[:, :3, :3] + 1e-30 * np.eye(3),
                                                                    e[:, :3, None])[..., 0]))
        e_deg = np.degrees(np.linalg.norm(e[:, 3:], axis=1))
        cov_pos = float(np.mean(e_mm <= r_mm))
        law = coverage_law(J[:, :3, :], cov, r_mm * 1e-3, np.random.default_rng([STREAM_MAP, len(q)]),
                           extra=None if Cq is None else Cq[:, :3, :3])
        for k, p in enumerate(pts):
            p["true_error_mm"] = float(e_mm[k])
            p["true_error_deg"] = float(e_deg[k])
            p["true_error_z"] = float(z[k])
        block["coverage"] = {
            "position": {"all": cov_pos,
                         "inside": float(np.mean(e_mm[~ext] <= r_mm[~ext])) if (~ext).any() else None,
                         "extrapolated": float(np.mean(e_mm[ext] <= r_mm[ext])) if ext.any() else None},
            "rotation": {"all": float(np.mean(e_deg <= r_deg))},
            "mean_z2_over_3": float(np.mean(z**2) / 3),
            "under_the_map": {
                "mean": float(law.mean()), "p05": float(np.percentile(law, 5)), "p95": float(np.percentile(law, 95)),
                "p_at_least_observed": float(np.mean(law >= cov_pos - 1e-12)),
                "draws": [round(float(v), 4) for v in law[:LAW_KEPT]],
                "of": "the position coverage a correct map gives (parameter errors drawn from the map's own covariance "
                      "through the registered Jacobian): its mean is the level, its spread wide since all points of "
                      "one calibration share one parameter error; p_at_least_observed: the chance of a coverage at "
                      "least the observed one (near 0: conservative, near 1: optimistic); draws: a sample of it, to "
                      "pool runs"},
            "of": "share of the points whose true tool error (calibrated model vs the true robot, registered as the "
                  "map) is within r95; mean_z2_over_3: the mean squared Mahalanobis distance of the true position "
                  "errors over 3 (1 when the predicted covariance describes them; true_error_z per point)"}
    return block


def robot_x(setup, names: Sequence[str], x: ArrayLike) -> np.ndarray:
    """The setup's parameter vector x (setup order) in the robot's ``names`` order."""
    return in_order(names, setup.params.names, x)


def run_map(setup, result, q_cal: ArrayLike, *, tcp=None, sigma_q_rad: float = 0.0, identifiability: dict | None = None,
            truth_setup=None, x_true: ArrayLike | None = None, rng: np.random.Generator | None = None,
            variance_factor: float = 1.0) -> dict:
    """:func:`build_map` of an identification: ``setup`` the identified setup, ``result`` its IdentificationResult
    (covariance over its free parameters, already scaled by the variance factor where above 1), q_cal (K, n) the
    joint readings of the poses it kept; truth_setup / x_true: the true robot of a simulation."""
    kin, names = model_kinematics(setup, tcp)
    free = [n for n, f in zip(result.names, result.free) if f]
    cov = embed_covariance(names, free, result.covariance)
    truth = None
    if truth_setup is not None:
        tkin, tnames = model_kinematics(truth_setup, tcp)
        truth = (tkin, in_order(tnames, truth_setup.params.names, x_true))
    how = "the identified parameters' covariance" + (f" (scaled by the variance factor {variance_factor:.3g})"
                                                     if variance_factor > 1 else "")
    return build_map(kin, names, robot_x(setup, names, result.identified), cov, q_cal, tcp=tcp,
                     sigma_q_rad=sigma_q_rad, identifiability=identifiability, truth=truth, rng=rng,
                     covariance_of=how)


def map_rng(seed: int) -> np.random.Generator:
    """The generator of a simulation's joint errors at the map's points (:data:`STREAM_MAP`)."""
    return np.random.default_rng([int(seed), STREAM_MAP])


def summary_line(block: dict) -> str:
    """One line of the printed summary."""
    def part(s, unit):
        return "none" if not s else f"median {s['median']:.3g}, max {s['max']:.3g} {unit}"

    r, d = block["r95_mm"], block["r95_deg"]
    line = (f"accuracy map ({block['n_points']} tool positions, {block['n_extrapolated']} extrapolated; 95 % radius of "
            f"the tool error): inside the calibration region position {part(r['inside'], 'mm')}, rotation "
            f"{part(d['inside'], 'deg')}; extrapolated position {part(r['extrapolated'], 'mm')}")
    cov = block.get("coverage")
    if cov:
        line += f"; true error within r95 at {100 * cov['position']['all']:.0f} % of the points"
    if block.get("not_covered"):
        line += ("; assumed nominal (not identifiable, carried by the tool): "
                 + ", ".join(f"{c['parameter']} (in {', '.join(c['carried_by'])})" for c in block["not_covered"]))
    return line


def add_accuracy_map(report: dict, setup, result, q_cal: ArrayLike, **kw) -> None:
    """Add the ``accuracy_map`` block (:func:`run_map`) and its summary line to a report whose verdict is usable; a
    map that cannot be computed is a warning naming why (the report is kept)."""
    v = report.get("verdict") or {}
    if not v.get("usable", v.get("ok")) or setup is None or result is None:
        return
    import time

    t0 = time.perf_counter()
    try:
        block = run_map(setup, result, q_cal, identifiability=report.get("identifiability"),
                        variance_factor=float(report.get("variance_factor") or 1.0), **kw)
    except (VisionCalibError, np.linalg.LinAlgError, ValueError) as exc:
        report.setdefault("warnings", []).append(f"accuracy map not computed: {exc}")
        report["summary_text"] = report.get("summary_text", "") + f"\nwarning: accuracy map not computed: {exc}"
        return
    report["accuracy_map"] = block
    report["summary_text"] = report.get("summary_text", "") + "\n" + summary_line(block)
    if isinstance(report.get("timings_s"), dict):
        report["timings_s"]["accuracy_map"] = time.perf_counter() - t0


def planned_map(scene, names: Sequence[str], information: ArrayLike, joints: ArrayLike,
                identifiability: dict | None = None) -> dict:
    """The map ``plan`` predicts before any image: the nominal model, the base parameters' covariance
    diag(s) M^-1 diag(s) of the planned poses' information M (L, L) in scaled units (``planning.design``: whitened by
    the image model's pose covariance; s: the parameters' scale, the columns' unit), ``names`` (L,) its columns, the
    planned joint sets (K, n) as the calibration poses; the scene's joint repeatability (measurement.sigma_q_deg)."""
    setup = scene.setup
    kin, rnames = model_kinematics(setup)
    own = dict(zip(setup.params.names, setup.params.scale))
    s = np.array([own.get(n, 1.0) for n in names], float)  # a name the robot lacks (a tilt) is dropped below
    cov = np.linalg.pinv(np.asarray(information, float), hermitian=True) * np.outer(s, s)
    return build_map(kin, rnames, robot_x(setup, rnames, setup.params.nominal),
                     embed_covariance(rnames, list(names), cov), joints,
                     sigma_q_rad=float(scene.measurement.sigma_q_rad), identifiability=identifiability,
                     covariance_of="predicted for the planned poses before any image (first order: the inverse of "
                                   "their information under the image measurement model, at the nominal geometry)")


def add_planned_map(plan: dict, scene, names: Sequence[str], information: ArrayLike, joints: ArrayLike,
                    identifiability: dict | None = None) -> None:
    """plan.json's ``accuracy_map`` (:func:`planned_map`); a map that cannot be computed is a warning of the plan."""
    try:
        plan["accuracy_map"] = planned_map(scene, names, information, joints, identifiability)
    except (VisionCalibError, np.linalg.LinAlgError, ValueError) as exc:
        plan.setdefault("warnings", []).append(f"accuracy map not computed: {exc}")


__all__ = ["LAW_DRAWS", "LAW_KEPT", "LEVEL", "MARGIN", "PER_AXIS", "STREAM_MAP", "add_accuracy_map", "add_planned_map",
           "base_motion_lever", "coverage_law", "pooled_coverage_law",
           "build_map", "embed_covariance", "map_rng", "model_kinematics", "norm_quantile", "planned_map",
           "joint_term", "registered_error", "registered_jacobian", "registration", "run_map", "summary_line",
           "tool_covariance",
           "workspace_grid"]
