"""D-optimal choice of the poses among the screened candidates, for the base parameters at the cell's measurement
noise (``identify.pose_selection.select_poses``), and the figures of a design: D criterion, D-efficiency against
another design, each pose's leverage.

The exchange algorithm holds every candidate pair's information in memory ((K m)^2 numbers for K candidates of m
rows), so it runs on a pool: the :data:`POOL_TOP` candidates of largest leverage in the information of all screened
candidates (at most :data:`MAX_INFO` of them, drawn at random; leverage = trace(A_k M^-1 A_k^T): how much of the
parameter space a pose alone pins down; the extreme poses a D-optimal design needs are among them) and
:data:`POOL_RANDOM` others drawn at random. On the UR5e cell this pool gave validation errors 0.66x those of random
poses (synthetic, 10 seeds), against 0.78x for a pool of 300 random candidates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import IdentifiabilityError
from ..experiment.steps import analyze_setup, base_problem
from ..identify.pose_selection import design_criterion, information_blocks, select_poses

POOL_TOP = 200
POOL_RANDOM = 100
MAX_INFO = 20000
#: candidates analysed for the base parameters (identifiability at the nominal, SVD)
BASE_POSES = 300
#: exchange restarts of select_poses (from random designs; 0: greedy start only)
RESTARTS = 1


@dataclass(frozen=True)
class Information:
    """Information of candidate poses for the base parameters: A (K, m, L) the scaled whitened Jacobian blocks
    (``identify.pose_selection.information_blocks``), ``base`` (n_params,) bool, the base-parameter names, the
    residual kind, the analysis (IdentifiabilityReport) of the poses it was computed on."""

    A: np.ndarray
    base: np.ndarray
    names: tuple[str, ...]
    residual: str
    analysis: object


def pose_covariances(scene, n: int) -> np.ndarray:
    """(n, 6, 6) the cell's pose measurement covariance (``measurement.sigma_mm`` / ``sigma_deg``), per pose."""
    m = scene.measurement
    st, sr = max(m.sigma_t_m, 1e-6), max(m.sigma_r_rad, 1e-6)
    return np.broadcast_to(np.diag([st**2] * 3 + [sr**2] * 3), (n, 6, 6)).copy()


def base_mask(scene, poses: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, object]:
    """(base parameter mask (n_params,) bool, IdentifiabilityReport) over up to BASE_POSES of the poses."""
    k = min(len(poses), BASE_POSES)
    sub = poses if k == len(poses) else poses[np.sort(rng.choice(len(poses), k, replace=False))]
    rep, _ = analyze_setup(scene.setup, sub, scene.identification.residual)
    return scene.setup.params.mask(rep.base_parameters), rep


def _problem(scene, poses: np.ndarray, base: np.ndarray):
    setup = scene.setup
    residual = setup.residual_for(scene.identification.method, scene.identification.residual)
    meas = setup.synthetic_measurements(poses, setup.params.nominal, np.random.default_rng(0),
                                        pose_cov=pose_covariances(scene, len(poses)))
    problem, params = base_problem(setup, meas, residual, base)
    return problem, params, residual


def information(scene, poses: np.ndarray, base: np.ndarray, analysis=None) -> Information:
    """Information blocks of commanded poses (K, .) for the ``base`` parameters, at the nominal geometry whitened
    by the cell's measurement noise."""
    problem, params, residual = _problem(scene, poses, base)
    return Information(information_blocks(problem), np.asarray(base, bool), tuple(params.free_names), residual, analysis)


def identifiability(scene, poses: np.ndarray, base: np.ndarray):
    """IdentifiabilityReport (``identify.analyze``) of commanded poses for the ``base`` parameters, whitened by the
    cell's noise (the parameters outside the base set are not identifiable from the candidate region at all)."""
    from ..identify import analyze

    return analyze(_problem(scene, poses, base)[0], selection="order")


def info_matrix(A: np.ndarray, idx=None) -> np.ndarray:
    Ai = A if idx is None else A[np.asarray(idx, int)]
    return np.einsum("kmi,kmj->ij", Ai, Ai)


def leverages(A: np.ndarray, M: np.ndarray) -> np.ndarray:
    """(K,) trace(A_k M^-1 A_k^T) of blocks A (K, m, L) against the information M (L, L) (pseudo-inverse)."""
    Mi = np.linalg.pinv(M)
    return np.einsum("kmi,ij,kmj->k", A, Mi, A)


def pool_indices(A: np.ndarray, rng: np.random.Generator, top: int = POOL_TOP, extra: int = POOL_RANDOM) -> np.ndarray:
    """Indices of the exchange pool among K candidates (module docstring), sorted."""
    K = A.shape[0]
    if K <= top + extra:
        return np.arange(K)
    order = np.argsort(-leverages(A, info_matrix(A)), kind="stable")
    rest = rng.choice(order[top:], extra, replace=False)
    return np.sort(np.concatenate([order[:top], rest]))


def d_criterion(A: np.ndarray, idx) -> dict:
    """{logdet (D criterion, scaled units), O1 (Borm-Menq), s_min (E)} of the design idx over blocks A."""
    return {"logdet": design_criterion(A, idx, "D"), "O1": design_criterion(A, idx, "O1"),
            "s_min": design_criterion(A, idx, "E")}


def d_efficiency(logdet_a: float, logdet_b: float, L: int) -> float:
    """D-efficiency of design a against design b: exp((logdet_a - logdet_b) / L) (1: as good, 0.5: b needs half
    the poses for the same parameter-confidence volume)."""
    if not (np.isfinite(logdet_a) and np.isfinite(logdet_b)):
        return 0.0 if not np.isfinite(logdet_a) else float("inf")
    return float(np.exp((logdet_a - logdet_b) / L))


def select(scene, info: Information, poses: np.ndarray, n: int, rng: np.random.Generator,
           candidates: np.ndarray | None = None) -> np.ndarray:
    """Indices (n,) into the commanded poses (K, .) of the information ``info`` (or among ``candidates``, a subset
    of them) of a D-optimal design of n poses: leverage pool, then ``select_poses`` (greedy + Fedorov exchange) on
    the pool's problem. IdentifiabilityError when n poses cannot identify the base parameters (naming the minimum)
    or when fewer candidates than n are left."""
    sub = np.arange(info.A.shape[0]) if candidates is None else np.asarray(candidates, int)
    A = info.A[sub]
    m, L = A.shape[1], A.shape[2]
    if n * m < L:
        raise IdentifiabilityError(f"{n} poses give {n * m} equations for the {L} base parameters: plan at least "
                                   f"{-(-L // m)} poses")
    if n > len(sub):
        raise IdentifiabilityError(f"{n} poses asked, only {len(sub)} candidates are measurable and collision-free: "
                                   "widen the candidate region or ask for fewer poses")
    pool = pool_indices(A, rng)
    problem, _, _ = _problem(scene, np.asarray(poses)[sub[pool]], info.base)
    idx = select_poses(problem, n, restarts=RESTARTS)
    return sub[pool[idx]]


__all__ = ["Information", "information", "base_mask", "identifiability", "select", "d_criterion", "d_efficiency", "leverages",
           "pool_indices", "info_matrix", "pose_covariances"]
