"""Identification problem of a serial arm from measured poses (or positions) of its end frame.

The observations are the transforms ``T_left_right`` of a :class:`~vision_calib.kinematics.serial.SerialChain`
(for example ``T_target_cam`` measured by solvePnP for an eye-in-hand camera, ``T_cam_target`` for a
tripod camera, ``T_world_tool`` from a tracker), one per joint set.

Residual (``measured - model``, per pose)::

    r_k(x) = frames.pose_error(T_model(q_k, x), T_meas_k)      # [dt (m), dtheta (rad)] in frame `left`
                                                              # "position": the first 3 components

Jacobian: ``d r / d x = -[dt/dx ; J_r(rho)^-1 dtheta/dx]`` where ``[dt/dx; dtheta/dx]`` is the chain's
analytic :meth:`~vision_calib.kinematics.serial.SerialChain.pose_jacobian` and ``J_r(rho)^-1`` the
inverse right Jacobian of SO(3) at the rotation residual rho (exact derivative of the rotation-vector
residual; it is the identity at rho = 0, so near convergence this is the plain ``-J_model``).
"""

from __future__ import annotations

from typing import Iterable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..errors import DataError, ParameterError
from ..frames import inv_T, inverse_error_map, perturb_pose, pose_error, so3_right_jacobian_inv  # noqa: F401
from ..kinematics.protocols import ChainModel, WalkFrames
from .problem import NOISE_ESTIMATED, IdentificationProblem

POSE_COMPONENTS = ("dt_x", "dt_y", "dt_z", "dtheta_x", "dtheta_y", "dtheta_z")
#: largest walk (bytes: poses x (joints + 2) frames x 128) a serial problem keeps with its last residual, so that the
#: Jacobian at the same x does not walk the chain again: 64 MB, ~60,000 poses of a 6-joint arm
FRAMES_KEEP_BYTES = 64 * 2 ** 20
#: relative weights (not noise) when neither obs_cov nor sigmas are given: 1 mm per 1 mrad (a pose error
#: of 1 mrad moves a point 1 m away by 1 mm); the noise scale is then estimated from the residuals
RELATIVE_WEIGHT_T_M = 1e-3
RELATIVE_WEIGHT_R_RAD = 1e-3


def _pose_name(k: int, labels) -> str:
    """"pose 'p007'" (its id) when the caller gave labels, else "pose 7" (its index)."""
    return f"pose {labels[k]!r}" if labels is not None and len(labels) > k else f"pose {k}"


def _check_poses(T, n, name="T_meas", labels=None) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise DataError(f"{name} must have shape (N, 4, 4), got {T.shape}")
    if T.shape[0] != n:
        raise DataError(f"{name} has {T.shape[0]} poses but there are {n} joint sets")
    bad = ~np.all(np.isfinite(T), axis=(1, 2))
    if bad.any():
        raise DataError(f"{name}: {_pose_name(int(np.flatnonzero(bad)[0]), labels)} contains a non-finite value (NaN or inf)")
    R = T[:, :3, :3]
    err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = (err > 1e-6) | (det < 0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise DataError(f"{name}: {_pose_name(k, labels)} does not hold a rotation matrix (|R R^T - I| = {err[k]:.2g}, det = {det[k]:.3g})")
    return T


def _obs_cov(n, m, obs_cov, sigma_t_m, sigma_r_rad, labels=None) -> tuple[np.ndarray, str]:
    if obs_cov is not None:
        if sigma_t_m is not None or sigma_r_rad is not None:
            raise ParameterError("give either obs_cov or sigma_t_m/sigma_r_rad, not both")
        C = np.asarray(obs_cov, dtype=float)
        if C.ndim == 2:
            C = np.broadcast_to(C, (n,) + C.shape)
        if C.ndim != 3 or C.shape[0] != n or C.shape[1] != C.shape[2] or C.shape[1] not in (m, 6):
            raise DataError(f"obs_cov must have shape ({n}, {m}, {m}) or ({m}, {m}) (or 6x6 for a pose "
                            f"covariance), got {np.shape(obs_cov)}")
        C = np.array(C[:, :m, :m])
        bad = ~np.all(np.isfinite(C), axis=(1, 2))
        if bad.any():
            raise DataError(f"obs_cov of {_pose_name(int(np.flatnonzero(bad)[0]), labels)} contains a non-finite value")
        sym = np.abs(C - np.swapaxes(C, 1, 2)).max(axis=(1, 2)) <= 1e-12 * np.abs(C).max(axis=(1, 2)) + 1e-300
        if not sym.all():
            raise DataError(f"obs_cov of {_pose_name(int(np.flatnonzero(~sym)[0]), labels)} is not symmetric")
        with np.errstate(all="ignore"):  # an overflowing covariance is named below, not warned about
            ev = np.linalg.eigvalsh(C)
        if np.any(~(ev[:, 0] > 0)):
            raise DataError(f"obs_cov of {_pose_name(int(np.flatnonzero(~(ev[:, 0] > 0))[0]), labels)} is not "
                            "positive definite")
        return C, "given"
    if (sigma_t_m is None) != (sigma_r_rad is None) and m == 6:
        raise ParameterError("give both sigma_t_m and sigma_r_rad for a pose residual (or obs_cov), or neither "
                             "(noise then estimated from the residuals)")
    st = RELATIVE_WEIGHT_T_M if sigma_t_m is None else float(sigma_t_m)
    sr = RELATIVE_WEIGHT_R_RAD if sigma_r_rad is None else float(sigma_r_rad)
    if not (st > 0 and sr > 0 and np.isfinite(st) and np.isfinite(sr)):
        raise ParameterError(f"sigma_t_m and sigma_r_rad must be positive, got {st}, {sr}")
    d = np.array([st, st, st, sr, sr, sr])[:m] ** 2
    src = "sigmas" if (sigma_t_m is not None or sigma_r_rad is not None) else NOISE_ESTIMATED
    return np.broadcast_to(np.diag(d), (n, m, m)).copy(), src


def serial_problem(
    chain: ChainModel,
    q: ArrayLike,
    T_meas: ArrayLike,
    residual: str = "pose",
    obs_cov: ArrayLike | None = None,
    sigma_t_m: float | None = None,
    sigma_r_rad: float | None = None,
    labels: Sequence[str] | None = None,
    free: Iterable[str] | None = None,
    check_limits: bool = True,
    measured: str | None = None,
) -> IdentificationProblem:
    """Identification problem for ``chain`` from joint sets ``q`` (N, n) rad and measured
    ``T_meas`` (N, 4, 4) = ``T_left_right`` (m).

    residual: "pose" (6 components [dt (m), dtheta (rad)] in frame ``chain.left``) or "position"
    (the first 3). obs_cov: (N, m, m) or (m, m) measurement covariance (a (N, 6, 6) pose
    covariance is cut to (N, 3, 3) for "position"); or sigma_t_m / sigma_r_rad (isotropic);
    neither -> no noise is invented: relative weights 1 mm : 1 mrad, the noise scale is estimated from
    the residuals by the solvers (a-posteriori variance factor chi2/dof; ``meta["noise"]`` and
    ``IdentificationResult.noise`` say "estimated from residuals, not given"). labels: (N,) pose ids
    (default "0".."N-1"). free: names to identify (default: the chain's free mask). check_limits: a
    joint value outside the chain's ``joint_limits`` is a DataError naming the pose and joint, the same
    check (and message) as the pipelines' input files (``check_limits=False`` to fit such data anyway).
    measured: the transform the rows of ``T_meas`` AND their noise (obs_cov / sigmas) hold, in the
    ``frames.pose_error`` convention of that transform (the convention of ``vision-calib docs measured_poses``):
    ``chain.measured_name`` (default, e.g. ``T_target_cam`` eye-in-hand) or its inverse (e.g.
    ``T_cam_target``, what solvePnP gives); the inverse is carried into the chain's direction exactly
    (poses inverted, covariance ``G C G^T`` with ``frames.inverse_error_map``), so equal sigmas give the
    same answer here and in ``vision-calib process-poses`` when both name the same direction.
    Raises ParameterError if two exactly redundant parameters (``chain.redundant_pairs()``, e.g.
    a Hayati ``beta3`` and ``d3``) are both free.
    Longer than 80 lines: input validation then the residual and Jacobian closures over the same checked arrays.
    """
    if not isinstance(chain, ChainModel):  # SerialChain, URDFChain or any chain of that interface
        raise ParameterError(f"serial_problem needs a chain of the kinematics.protocols.ChainModel interface "
                             f"(e.g. a SerialChain), got {type(chain).__name__}")
    if residual not in ("pose", "position"):
        raise ParameterError(f"residual must be 'pose' or 'position', got {residual!r}")
    q = chain.check_joints(q)
    n = q.shape[0]
    if check_limits:
        from ..kinematics.serial import check_joint_limits

        check_joint_limits(q, chain.joint_limits, f"{chain.name}: joint values",
                           labels if labels is not None and len(labels) == n else None)
    lab = labels if labels is not None and len(labels) == n else None
    T_meas = _check_poses(T_meas, n, labels=lab)
    m = 6 if residual == "pose" else 3
    params = chain.params if free is None else chain.params.only_free(list(free))
    free_set = set(params.free_names)
    for a, b, why in chain.redundant_pairs():
        if a in free_set and b in free_set:
            raise ParameterError(f"{a} and {b} cannot both be free: {why}; fix one of them")
    own = chain.measured_name
    a, b = own[2:].split("_", 1) if own.count("_") == 2 else (None, None)
    inverse = f"T_{b}_{a}" if a else None
    measured = own if measured is None else str(measured)
    if measured not in (own, inverse):
        raise ParameterError(f"measured={measured!r}: the chain {chain.name!r} computes {own}; give {own!r} or "
                             f"{inverse!r} (the direction the rows of T_meas and their noise hold)")
    if measured == own:
        cov, cov_src = _obs_cov(n, m, obs_cov, sigma_t_m, sigma_r_rad, lab)
    else:  # rows and noise in the inverse direction: carry both into the chain's direction exactly
        if obs_cov is not None and np.shape(obs_cov)[-1] != 6:
            raise DataError(f"measured={measured!r}: mapping the noise to {own} needs the full (6, 6) pose "
                            f"covariance, got {np.shape(obs_cov)}")
        cov6, cov_src = _obs_cov(n, 6, obs_cov, sigma_t_m, sigma_r_rad, lab)
        G = inverse_error_map(T_meas)
        cov = np.ascontiguousarray((G @ cov6 @ np.swapaxes(G, -1, -2))[:, :m, :m])
        T_meas = inv_T(T_meas)
    if labels is None:
        labels = tuple(str(i) for i in range(n))
    else:
        labels = tuple(labels)
        if len(labels) != n:
            raise DataError(f"labels has {len(labels)} entries but there are {n} poses")

    def _idx(idx):
        if idx is None:
            return np.arange(n)
        idx = np.asarray(idx, dtype=int).reshape(-1)
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise DataError(f"observation index out of range 0..{n - 1}: {idx[(idx < 0) | (idx >= n)][0]}")
        return idx

    # the last pose errors over all poses (the Jacobian at that x reads their rotations), with the walk's frames
    # when the chain gives them and they fit in FRAMES_KEEP_BYTES (the Jacobian at that x reads them: no second
    # walk), and the last Jacobian over all poses
    last = {}
    keep_frames = isinstance(chain, WalkFrames) and n * (chain.n_joints + 2) * 128 <= FRAMES_KEEP_BYTES

    def errors(x, idx, T=None):
        """Pose errors (k, 6) of the poses idx (None: all) at x: a slice of those kept over all poses at this x,
        else from T (k, 4, 4) (a walk the caller made at x) or a forward walk; kept when over all poses."""
        key = np.asarray(x, float).tobytes()
        if last.get("x") == key:
            return last["e"] if idx is None else last["e"][_idx(idx)]
        frames = chain.walk_frames(q, x) if T is None and idx is None and keep_frames else None
        if frames is not None:
            T = frames[-1]
        e = pose_error(chain.forward(q[_idx(idx)], x) if T is None else T, T_meas[_idx(idx)])
        if idx is None:
            last.update(x=key, e=e, frames=frames)
        return e

    def kept_frames(x, idx):
        """The kept walk's frames (k+2, len(idx), 4, 4) of the poses idx (None: all) at x, or None."""
        if last.get("frames") is None or last.get("x") != np.asarray(x, float).tobytes():
            return None
        if idx is None:
            return last["frames"]
        i = _idx(idx)
        if i.size and i[-1] - i[0] == i.size - 1 and np.all(np.diff(i) == 1):  # a range: a view
            return last["frames"][:, i[0]:i[-1] + 1]
        return last["frames"][:, i]

    def residual_fn(x, idx=None):
        return errors(x, idx)[:, :m].copy()

    def jacobian_fn(x, idx=None):  # the last one over all poses is kept: the solvers ask twice at the start
        key = np.asarray(x, float).tobytes() if idx is None else None
        if key is not None and last.get("xJ") == key:
            return last["J"].copy()
        J = np.matmul(*factors_fn(x, idx))  # (k, m, n): D @ Jm
        if key is not None:
            last.update(xJ=key, J=J.copy())
        return J

    def factors_fn(x, idx=None):
        """(D (k, m, 6), Jm (k, 6, n)): the chain's pose Jacobian Jm (as the chain returns it: a view) and the map
        D of its rows to the residual's, -I for translation and -Jr^-1(rho) for rotation, so jacobian = D @ Jm."""
        fr = kept_frames(x, idx)
        T, Jm = chain.pose_and_jacobian(q[_idx(idx)], x) if fr is None else \
            chain.pose_and_jacobian(q[_idx(idx)], x, frames=fr)
        D = np.zeros((Jm.shape[0], m, 6))
        D[:, :3, :3] = -np.eye(3)
        if m == 6:
            D[:, 3:, 3:] = -so3_right_jacobian_inv(errors(x, idx, T)[:, 3:])
        return D, Jm

    return IdentificationProblem(
        params=params,
        residual=residual_fn,
        jacobian=jacobian_fn,
        jacobian_factors=factors_fn,
        obs_cov=cov,
        residual_kind=residual,
        labels=labels,
        component_names=POSE_COMPONENTS[:m],
        meta={
            "model": "serial",
            "chain": chain,
            "q": q,
            "T_meas": T_meas,
            "measured": chain.measured_name,
            "frame": chain.left,
            "obs_cov_source": cov_src,
            "measured_as_given": measured,
            **({"noise": NOISE_ESTIMATED} if cov_src == NOISE_ESTIMATED else {}),
        },
    )


def synthetic_pose_measurements(chain: ChainModel, q: ArrayLike, x_true: ArrayLike, sigma_t_m: float,
                                sigma_r_rad: float, rng: np.random.Generator) -> np.ndarray:
    """Noisy measured poses T_left_right (N, 4, 4): the true pose ``chain.forward(q, x_true)`` perturbed
    by Gaussian noise ``d ~ N(0, diag(sigma_t^2 I3, sigma_r^2 I3))`` with :func:`frames.perturb_pose`,
    so that ``pose_error(T_true, T_meas) == d`` (the residual convention of :func:`serial_problem`).

    x_true: full parameter vector (n_params,) or a {name: value} mapping of absolute values applied
    to the nominal. rng: a numpy Generator (the only source of randomness).
    """
    if not isinstance(rng, np.random.Generator):
        raise ParameterError("rng must be a numpy.random.Generator (seeded by the caller)")
    if not (np.isfinite(sigma_t_m) and np.isfinite(sigma_r_rad) and sigma_t_m >= 0 and sigma_r_rad >= 0):
        raise ParameterError(f"sigma_t_m and sigma_r_rad must be >= 0, got {sigma_t_m}, {sigma_r_rad}")
    if isinstance(x_true, Mapping):
        x_true = chain.params.vector(x_true)
    T = chain.forward(q, x_true)
    d = rng.standard_normal((T.shape[0], 6)) * np.array([sigma_t_m] * 3 + [sigma_r_rad] * 3)
    return perturb_pose(T, d)
