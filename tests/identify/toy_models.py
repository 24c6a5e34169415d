"""Toy identification problems for the identify/ tests (tests-only helpers).

1. Planar 3R arm: base offset (base.x, base.y, base.theta), link lengths L1..L3, joint offsets
   q0_1..q0_3. Joint k absolute angle phi_k = base.theta + sum_{i<=k} (q_i + q0_i); tool point
   p = (base.x, base.y) + sum_k L_k (cos phi_k, sin phi_k); orientation phi_3.
   Measured: "pose" = (px, py, phi3) [m, m, rad] or "position" = (px, py) [m].
   Known deficiency: base.theta and q0_1 enter only through their sum (coupling +1 in SI).
2. Linear problem r = y - A_k x (constant Jacobian), for hand-checkable identifiability figures.
"""

from __future__ import annotations

import numpy as np

from vision_calib.identify.problem import IdentificationProblem
from vision_calib.kinematics.params import ParameterSet

NAMES = ("base.x", "base.y", "base.theta", "L1", "L2", "L3", "q0_1", "q0_2", "q0_3")
KINDS = ("length", "length", "angle", "length", "length", "length", "angle", "angle", "angle")
NOMINAL = np.array([0.0, 0.0, 0.0, 0.40, 0.30, 0.10, 0.0, 0.0, 0.0])
#: base.theta gets a larger typical deviation than q0_1 so that pivoted QR keeps it (drops q0_1)
SCALE = np.array([1e-3, 1e-3, 2e-3, 1e-3, 1e-3, 1e-3, 1e-3, 1e-3, 1e-3])


def planar_params(free=None) -> ParameterSet:
    return ParameterSet.from_lists(NAMES, NOMINAL, KINDS, free=free, scale=SCALE)


def true_deviation(rng: np.random.Generator) -> np.ndarray:
    """A perturbed geometry: deviations of a few scales, (9,) SI."""
    return NOMINAL + SCALE * rng.uniform(-3, 3, size=len(NAMES))


def planar_model(x, q):
    """Tool pose (px, py, phi3) (k, 3) and angles phi (k, 3) for parameters x (9,) and joints q (k, 3) rad."""
    bx, by, th, L1, L2, L3, o1, o2, o3 = x
    phi = th + np.cumsum(q + np.array([o1, o2, o3]), axis=1)
    L = np.array([L1, L2, L3])
    p = np.array([bx, by]) + np.stack([np.cos(phi) @ L, np.sin(phi) @ L], axis=1)
    return np.column_stack([p, phi[:, 2]]), phi


def planar_model_jacobian(x, q):
    """d model / d x, (k, 3, 9)."""
    L = np.array(x[3:6])
    _, phi = planar_model(x, q)
    c, s = np.cos(phi), np.sin(phi)
    k = q.shape[0]
    J = np.zeros((k, 3, 9))
    J[:, 0, 0] = 1.0
    J[:, 1, 1] = 1.0
    # d p / d phi_j = L_j (-sin, cos); phi_j depends on theta, q0_1..q0_j
    dpx = -s * L  # (k, 3)
    dpy = c * L
    tail_x = np.cumsum(dpx[:, ::-1], axis=1)[:, ::-1]  # sum_{j>=i}
    tail_y = np.cumsum(dpy[:, ::-1], axis=1)[:, ::-1]
    for col, i in ((2, 0), (6, 0), (7, 1), (8, 2)):
        J[:, 0, col] = tail_x[:, i]
        J[:, 1, col] = tail_y[:, i]
        J[:, 2, col] = 1.0
    J[:, 0, 3:6] = c
    J[:, 1, 3:6] = s
    return J


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def planar_problem(
    x_true,
    n_poses=30,
    measure="pose",
    sigma_pos=1e-4,
    sigma_ang=2e-4,
    rng=None,
    noise=True,
    cov=None,
    q=None,
    labels=None,
    params=None,
) -> tuple[IdentificationProblem, np.ndarray]:
    """Synthetic problem: joints uniform in [-pi, pi] (or given q (k, 3)), measurements from x_true
    plus Gaussian noise with covariance ``cov`` (m, m) (default diag of sigma_pos², sigma_ang²).
    Returns (problem, q)."""
    rng = np.random.default_rng(0) if rng is None else rng
    q = rng.uniform(-np.pi, np.pi, size=(n_poses, 3)) if q is None else np.asarray(q, float)
    k = q.shape[0]
    comps = [0, 1, 2] if measure == "pose" else [0, 1]
    m = len(comps)
    if cov is None:
        cov = np.diag([sigma_pos**2, sigma_pos**2, sigma_ang**2][:m])
    cov = np.asarray(cov, float)
    y = planar_model(np.asarray(x_true, float), q)[0][:, comps]
    if noise:
        y = y + rng.standard_normal((k, m)) @ np.linalg.cholesky(cov).T
    labels = tuple(f"pose{i:03d}" for i in range(k)) if labels is None else tuple(labels)

    def residual(x, idx=None):
        sel = slice(None) if idx is None else np.asarray(idx, int)
        r = y[sel] - planar_model(np.asarray(x, float), q[sel])[0][:, comps]
        if m == 3:
            r[:, 2] = _wrap(r[:, 2])
        return r

    def jacobian(x, idx=None):
        sel = slice(None) if idx is None else np.asarray(idx, int)
        return -planar_model_jacobian(np.asarray(x, float), q[sel])[:, comps, :]

    prob = IdentificationProblem(
        params=planar_params() if params is None else params,
        residual=residual,
        jacobian=jacobian,
        obs_cov=np.broadcast_to(cov, (k, m, m)).copy(),
        residual_kind="pose" if m == 3 else "position",
        labels=labels,
        component_names=("x", "y", "phi")[:m],
        meta={"y": y},
    )
    return prob, q


def linear_problem(A, y, cov, names, scale, nominal=None) -> IdentificationProblem:
    """r_k = y_k - A_k x with A (n_obs, m, n), y (n_obs, m), cov (n_obs, m, m)."""
    A = np.asarray(A, float)
    y = np.asarray(y, float)
    n = A.shape[2]
    nominal = np.zeros(n) if nominal is None else nominal
    params = ParameterSet.from_lists(names, nominal, ["length"] * n, scale=scale)

    def residual(x, idx=None):
        sel = slice(None) if idx is None else np.asarray(idx, int)
        return y[sel] - np.einsum("kmn,n->km", A[sel], np.asarray(x, float))

    def jacobian(x, idx=None):
        sel = slice(None) if idx is None else np.asarray(idx, int)
        return -A[sel].copy()

    return IdentificationProblem(
        params=params, residual=residual, jacobian=jacobian, obs_cov=np.asarray(cov, float), residual_kind="position",
        labels=tuple(f"obs{i}" for i in range(A.shape[0])),
    )


def h4_problem(variant="D", sigma_q_rad=0.0, seed=0, n_poses=None, all_free=False):
    """H4 IGM problem from the real builders (skips the test if they are missing).

    Truth = nominal + uniform(-2, 2) scales; poses: the seed's 81-pose grid (or its first n_poses).
    Returns (problem, x_true). sigma_q_rad: joint noise (rad) used for the data AND the weighting
    (1e-4 rad for the weighting when the data are noise-free)."""
    import pytest

    h4_io = pytest.importorskip("vision_calib.kinematics.h4_io")
    h4_variants = pytest.importorskip("vision_calib.kinematics.h4_variants")
    hp = pytest.importorskip("vision_calib.identify.h4_problem")
    from pathlib import Path

    scene = Path(__file__).resolve().parents[2] / "scenes" / "robots" / "h4.yaml"
    if not scene.exists():
        pytest.skip(f"{scene} missing")
    rob = h4_variants.variant(h4_io.load_h4_robot(scene), variant)
    rng = np.random.default_rng(seed)
    x_true = rob.params.nominal + rob.params.scale * rng.uniform(-2, 2, len(rob.params))
    X = rob.pose_grid()
    if n_poses is not None:
        X = X[rng.permutation(len(X))[:n_poses]]
    q, T = hp.synthetic_h4_measurements(rob, X, x_true, rng, sigma_q_rad=sigma_q_rad)
    prob = hp.h4_igm_problem(rob, q, T, sigma_q_rad=sigma_q_rad if sigma_q_rad > 0 else 1e-4)
    if all_free:
        prob = prob.with_params(prob.params.with_free(prob.params.names))
    return prob, x_true
