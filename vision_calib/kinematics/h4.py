"""H4 parallel robot (seed 000): models 12 and 31, external parameters, closed-form IGM,
Newton FGM and analytic Jacobians. numpy only.

Frames and pose
---------------
Base frame B: defined by the nacelle in its "H" configuration, z_B up (normal to the nacelle
plane), x_B along the central rod, y_B along the half-nacelles (the legs of the H); the motors
lie near the plane z_B = 0 and the workspace is below it (z < 0). The pose is
X = (x, y, z, theta) (m, m, m, rad): position p of the effector point in B and rotation of
the effector about z_B; T_base_nacelle = [Rz(theta), p].

Nacelle (self-consistent replacement of the seed's garbled eq. 18)
------------------------------------------------------------------
The central rod (half-length h) is rigid with the effector and turns by theta about the
effector point; the two half-nacelles only translate (they stay parallel to y_B) and pivot on
the rod ends; the forearms attach at +-d along them. Chain i (1..4) sits at the corner
(eps_h[i] h, eps_d[i] d) = (+h,+d), (-h,+d), (-h,-d), (+h,-d):

    A_i(X) = p + eps_h[i] h (cos theta, sin theta, 0) + eps_d[i] d (0, 1, 0)

so that A_i = p + (+-h, +-d, 0) at theta = 0.

Arm and forearm (both models)
-----------------------------
Motor i at P_i; its frame is Rz(psi_i) Rx(beta_i) (the two first ZXZ Euler angles of the seed's
model 31); its z axis k_i is the motor axis. With phi_i = q_i + q0_i (q_i = measured joint
value, q0_i = joint offset) the arm direction is

    u_i = Rz(psi_i) Rx(beta_i) Rz(phi_i) e_x = cos(phi_i) a_i + sin(phi_i) b_i,
    a_i = (cos psi, sin psi, 0),  b_i = (-sin psi cos beta, cos psi cos beta, sin beta),

the elbow is B_i = P_i + L_i u_i and the forearm (a perfect parallelogram) satisfies
||A_i - B_i|| = l_i. With D_i = A_i - P_i this is C cos(phi) + S sin(phi) = T,
C = L a.D, S = L b.D, T = (|D|^2 + L^2 - l^2)/2 (seed eq. 19-20), solved with the half-angle
tangent (seed eq. 21-22): tan(phi/2) = (S -+ sqrt(C^2 + S^2 - T^2)) / (T + C). The "arm
outward" assembly mode is the MINUS root: phi = gamma - mu with gamma = atan2(S, C) (direction
of P->A in the arm plane) and mu = acos(T / sqrt(C^2+S^2)) in [0, pi]; the elbow is on the
+a side (away from the nacelle) of the line P->A. Then dG/dphi = +sqrt(disc) > 0.

Model 12 (design model, seed §3.2): P_i = A_i^H + R (cos alpha_i, sin alpha_i, 0) with
A_i^H = (eps_h h, eps_d d, 0); the arm turns in the vertical plane of direction alpha_i
(psi_i = alpha_i, beta_i = -pi/2: a_i = (cos alpha, sin alpha, 0) outward, b_i = (0, 0, -1)
down, so phi > 0 lowers the arm). All arms have length L, all forearms l. Parameters (12):
h4.R, h4.L, h4.l, h4.h, h4.alpha1..4, q0_1..4. d has NO influence: D_i = A_i - P_i =
p + eps_h h (cos theta - 1, sin theta, 0) - R (cos alpha, sin alpha, 0) -- the +-d of the
attachment point and of the motor position cancel (the motors are placed relative to A_i^H).
d is therefore kept as a constant (``H4Robot.d12``) used only for drawing and conversion.

Model 31 (identification model, seed §3.3): free P_i, motor axis by (psi_i, beta_i), per-chain
L_i, l_i, plus h, d, q0_i. P_1 fixes the base frame (it is a constant, ``H4Robot.P1``), so the
31 parameters are: h4.x2, h4.y2, h4.z2, h4.x3, h4.y3, h4.z3, h4.x4, h4.y4, h4.z4 (9),
h4.psi1..4 (4), h4.beta1..4 (4), h4.L1..4 (4), h4.l1..4 (4), h4.h, h4.d (2), q0_1..4 (4).
Model 12 maps exactly to model 31 with psi_i = alpha_i, beta_i = -pi/2 (``to_model31``).
The conversion and the table-2 variants live in :mod:`.h4_variants`, the file loader in :mod:`.h4_io`.

The external parameters (camera on the base, target on the nacelle, optional tilts) and the camera
measurement with its Jacobians: :mod:`.h4_camera` (mixed into :class:`H4Robot`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import DataError, ParameterError, UnreachablePoseError
from ..frames import rot_x
from .h4_camera import H4CameraChain
from .params import ParameterSet

#: corner signs of chains 1..4: (+h,+d), (-h,+d), (-h,-d), (+h,-d)
EPS_H = np.array([1.0, -1.0, -1.0, 1.0])
EPS_D = np.array([1.0, 1.0, -1.0, -1.0])
EXTERNAL_NAMES = (
    "B_T_C.x", "B_T_C.y", "B_T_C.z", "B_T_C.theta",
    "M_T_E.x", "M_T_E.y", "M_T_E.z", "M_T_E.theta",
)  # fmt: skip
#: optional camera / target tilt parameters (rad), see :mod:`.h4_camera`
TILT_NAMES = ("B_T_C.tilt_x", "B_T_C.tilt_y", "M_T_E.tilt_x", "M_T_E.tilt_y")
EXTERNAL_KINDS = ("length",) * 3 + ("angle",) + ("length",) * 3 + ("angle",)
MODEL12_NAMES = ("h4.R", "h4.L", "h4.l", "h4.h") + tuple(f"h4.alpha{i}" for i in range(1, 5)) + tuple(
    f"q0_{i}" for i in range(1, 5)
)
#: primitive per-chain quantities the chain solver differentiates against
_PRIM = ("Px", "Py", "Pz", "psi", "beta", "L", "l", "h", "d", "q0")
_NP = len(_PRIM)
from .h4_workspace import DEFAULT_CENTER, DEFAULT_SIZE, DEFAULT_THETA_DEG, pose_grid_81, random_workspace_poses  # noqa: F401,E501


def model31_names(shared_L: bool = False) -> tuple[str, ...]:
    """Geometric parameter names of model 31 (31 names, 28 if the four arm lengths are shared)."""
    names = [f"h4.{c}{i}" for i in range(2, 5) for c in "xyz"]
    names += [f"h4.psi{i}" for i in range(1, 5)] + [f"h4.beta{i}" for i in range(1, 5)]
    names += ["h4.L"] if shared_L else [f"h4.L{i}" for i in range(1, 5)]
    names += [f"h4.l{i}" for i in range(1, 5)] + ["h4.h", "h4.d"] + [f"q0_{i}" for i in range(1, 5)]
    return tuple(names)


def param_kind(name: str) -> str:
    """"angle" or "length": the ParameterSet kind of an H4 parameter name."""
    base = name.split(".")[-1]
    if name.startswith("q0_") or base.startswith(("alpha", "psi", "beta", "theta")):
        return "angle"
    return "length"


def _wrap(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


# ----------------------------------------------------------------------------- chain solver
def _chain_solve(D, psi, beta, L, l):
    """Solve ||D - L u(phi)|| = l for the outward root, per pose and chain.

    D: (N, 4, 3) m, A_i - P_i in B. psi, beta, L, l: (4,). Returns phi (N, 4) (NaN where
    unreachable), sqrt(disc) (N, 4), and partials of phi wrt D (N,4,3), psi, beta, L, l (N,4).
    """
    cp, sp, cb, sb = np.cos(psi), np.sin(psi), np.cos(beta), np.sin(beta)
    z = np.zeros_like(psi)
    a = np.stack([cp, sp, z], -1)
    b = np.stack([-sp * cb, cp * cb, sb], -1)
    k = np.stack([sp * sb, -cp * sb, cb], -1)
    C = L * np.einsum("nij,ij->ni", D, a)
    S = L * np.einsum("nij,ij->ni", D, b)
    T = 0.5 * (np.einsum("nij,nij->ni", D, D) + L**2 - l**2)
    disc = C * C + S * S - T * T
    sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
    phi = _wrap(2.0 * np.arctan2(S - sq, T + C))  # seed eq. 22, "arm outward" = minus root
    c, s = np.cos(phi), np.sin(phi)
    u = c[..., None] * a + s[..., None] * b  # (N,4,3)
    # implicit G = L D.u - (|D|^2 + L^2 - l^2)/2 = 0, dG/dphi = -s C + c S = +sqrt(disc)
    Gphi = -s * C + c * S
    f = D - L[:, None] * u  # forearm vector B->A, (N,4,3)
    dphi_dD = f / Gphi[..., None]  # -(dG/dD)/Gphi with dG/dD = L u - D = -f
    ez_u = np.stack([-u[..., 1], u[..., 0], np.zeros_like(c)], -1)
    dphi_dpsi = -L * np.einsum("nij,nij->ni", D, ez_u) / Gphi
    dphi_dbeta = -L * s * np.einsum("nij,ij->ni", D, k) / Gphi
    dphi_dL = -(np.einsum("nij,nij->ni", D, u) - L) / Gphi
    dphi_dl = -l / Gphi
    return phi, sq, dphi_dD, dphi_dpsi, dphi_dbeta, dphi_dL, dphi_dl


# ----------------------------------------------------------------------------- robot
@dataclass(frozen=True)
class H4Robot(H4CameraChain):
    """H4 robot model with its external (camera/target mounting) parameters.

    model: "12" or "31". params: geometric + external ParameterSet (names in the module doc and :mod:`.h4_camera`).
    P1: (3,) m, fixed motor-1 centre in B (model 31 only). d12: nacelle half-width (m), no
    influence in model 12 (kept for drawing/conversion). R_BC0, R_ME0: (3, 3) fixed tilts of
    the camera and of the target (see :mod:`.h4_camera`). center (3,) m, size (3,) m, theta_deg:
    workspace of the seed's 81-pose grid. shared_L: model 31 with one arm length "h4.L".
    tilt_params: params end with TILT_NAMES (camera and target tilts, :mod:`.h4_camera`).
    """

    model: str
    params: ParameterSet
    P1: np.ndarray = field(default_factory=lambda: np.zeros(3))
    d12: float = 0.05
    R_BC0: np.ndarray = field(default_factory=lambda: rot_x(np.pi))
    R_ME0: np.ndarray = field(default_factory=lambda: rot_x(np.pi))
    center: np.ndarray = field(default_factory=lambda: DEFAULT_CENTER.copy())
    size: np.ndarray = field(default_factory=lambda: DEFAULT_SIZE.copy())
    theta_deg: tuple = DEFAULT_THETA_DEG
    shared_L: bool = False
    tilt_params: bool = False

    def __post_init__(self):
        if self.model not in ("12", "31"):
            raise ParameterError(f"H4 model must be '12' or '31', got {self.model!r}")
        geo = MODEL12_NAMES if self.model == "12" else model31_names(self.shared_L)
        want = geo + EXTERNAL_NAMES + (TILT_NAMES if self.tilt_params else ())
        if tuple(self.params.names) != want:
            missing = sorted(set(want) - set(self.params.names))
            extra = sorted(set(self.params.names) - set(want))
            raise ParameterError(
                f"H4 model {self.model} parameter names do not match: missing {missing}, unexpected {extra}"
            )
        for nm in ("P1", "R_BC0", "R_ME0", "center", "size"):
            object.__setattr__(self, nm, np.asarray(getattr(self, nm), float))
        object.__setattr__(self, "_M", None)

    # ------------------------------------------------------------------ parameter access
    @property
    def names(self) -> tuple[str, ...]:
        return self.params.names

    @property
    def n_geometric(self) -> int:
        return len(self.params) - len(EXTERNAL_NAMES) - (len(TILT_NAMES) if self.tilt_params else 0)

    def _x(self, x):
        if x is None:
            return self.params.nominal
        x = np.asarray(x, float).reshape(-1)
        if x.shape != (len(self.params),):
            raise ParameterError(f"H4 parameter vector has {x.size} entries, expected {len(self.params)}")
        return x

    def _chain_prims(self, x):
        """Per-chain primitive values (4, 10) [Px, Py, Pz, psi, beta, L, l, h, d, q0] and
        their derivatives wrt the full parameter vector (4, 10, n)."""
        v = dict(zip(self.names, x))
        n = len(self.names)
        ix = {nm: i for i, nm in enumerate(self.names)}
        prim = np.zeros((4, _NP))
        M = np.zeros((4, _NP, n))
        for i in range(4):
            j = i + 1
            if self.model == "12":
                R, h, al = v["h4.R"], v["h4.h"], v[f"h4.alpha{j}"]
                prim[i] = [
                    EPS_H[i] * h + R * np.cos(al), EPS_D[i] * self.d12 + R * np.sin(al), 0.0,
                    al, -np.pi / 2, v["h4.L"], v["h4.l"], h, self.d12, v[f"q0_{j}"],
                ]  # fmt: skip
                M[i, 0, ix["h4.h"]] = EPS_H[i]
                M[i, 0, ix["h4.R"]] = np.cos(al)
                M[i, 0, ix[f"h4.alpha{j}"]] = -R * np.sin(al)
                M[i, 1, ix["h4.R"]] = np.sin(al)
                M[i, 1, ix[f"h4.alpha{j}"]] = R * np.cos(al)
                M[i, 3, ix[f"h4.alpha{j}"]] = 1.0
                M[i, 5, ix["h4.L"]] = 1.0
                M[i, 6, ix["h4.l"]] = 1.0
                M[i, 7, ix["h4.h"]] = 1.0
            else:
                Lname = "h4.L" if self.shared_L else f"h4.L{j}"
                if j == 1:
                    P = self.P1
                else:
                    P = [v[f"h4.x{j}"], v[f"h4.y{j}"], v[f"h4.z{j}"]]
                    for c, nm in enumerate("xyz"):
                        M[i, c, ix[f"h4.{nm}{j}"]] = 1.0
                prim[i] = [*P, v[f"h4.psi{j}"], v[f"h4.beta{j}"], v[Lname], v[f"h4.l{j}"], v["h4.h"], v["h4.d"],
                           v[f"q0_{j}"]]  # fmt: skip
                M[i, 3, ix[f"h4.psi{j}"]] = 1.0
                M[i, 4, ix[f"h4.beta{j}"]] = 1.0
                M[i, 5, ix[Lname]] = 1.0
                M[i, 6, ix[f"h4.l{j}"]] = 1.0
                M[i, 7, ix["h4.h"]] = 1.0
                M[i, 8, ix["h4.d"]] = 1.0
            M[i, 9, ix[f"q0_{j}"]] = 1.0
        return prim, M

    # ------------------------------------------------------------------ IGM core
    @staticmethod
    def _check_X(X, what="pose"):
        X = np.asarray(X, dtype=float)
        if X.ndim == 1:
            X = X[None, :]
        if X.ndim != 2 or X.shape[1] != 4:
            cols = "[x, y, z (m), theta (rad)]" if what == "pose" else "[q1..q4 (rad)]"
            raise DataError(f"H4 {what}s must have shape (N, 4) {cols}, got {X.shape}")
        bad = ~np.isfinite(X)
        if bad.any():
            i = int(np.argwhere(bad)[0][0])
            raise DataError(f"H4 {what} {i} contains a non-finite value (NaN or inf): {X[i].tolist()}")
        return X

    def _solve(self, X, x):
        """X (N, 4) -> dict with phi, q (NaN where unreachable) and the pieces of the Jacobians."""
        prim, M = self._chain_prims(x)
        P = prim[:, :3]
        psi, beta, L, l, h, d, q0 = prim[:, 3:].T
        th = X[:, 3]
        r = np.stack([np.cos(th), np.sin(th), np.zeros_like(th)], -1)  # (N,3)
        A = X[:, None, :3] + (EPS_H * h)[None, :, None] * r[:, None, :] + (EPS_D * d)[None, :, None] * np.array(
            [0.0, 1.0, 0.0]
        )
        D = A - P[None]
        phi, sq, dD, dpsi, dbeta, dL, dl = _chain_solve(D, psi, beta, L, l)
        return dict(
            q=phi - q0, phi=phi, sq=sq, dD=dD, dpsi=dpsi, dbeta=dbeta, dL=dL, dl=dl, r=r, M=M, h=h, D=D, L=L, l=l
        )

    def _raise_unreachable(self, X, q, sq):
        bad = ~np.isfinite(q)
        i, c = (int(v) for v in np.argwhere(bad)[0])
        raise UnreachablePoseError(
            f"H4 pose {i} (x={X[i, 0]:.4f} m, y={X[i, 1]:.4f} m, z={X[i, 2]:.4f} m, "
            f"theta={np.rad2deg(X[i, 3]):.2f} deg) is unreachable by chain {c + 1} "
            f"(arm + forearm cannot close; {int(bad.sum())} pose/chain pairs unreachable)",
            pose_index=i,
            chain=c + 1,
        )

    def igm(self, X, x=None) -> np.ndarray:
        """Inverse model: poses X (N, 4) [m, m, m, rad] in B -> joint values q (N, 4) rad
        (arm-outward mode). x: full parameter vector (n,) (default nominal).
        UnreachablePoseError names the first unreachable pose and chain; DataError on NaN."""
        X = self._check_X(X)
        s = self._solve(X, self._x(x))
        if not np.all(np.isfinite(s["q"])):
            self._raise_unreachable(X, s["q"], s["sq"])
        return s["q"]

    def reach_margin(self, X, x=None) -> np.ndarray:
        """Distance of each chain to its serial singularity, (N, 4) rad: min(mu, pi - mu) with
        mu the angle between the arm and the motor->nacelle direction projected on the arm
        plane (0: arm and forearm aligned in projection, the limit of reach). NaN where
        unreachable. Pure diagnostic (does not raise on unreachable poses)."""
        X = self._check_X(X)
        x = self._x(x)
        s = self._solve(X, x)
        prim, _ = self._chain_prims(x)
        psi, beta = prim[:, 3], prim[:, 4]
        k = np.stack([np.sin(psi) * np.sin(beta), -np.cos(psi) * np.sin(beta), np.cos(beta)], -1)
        Dk = np.einsum("nij,ij->ni", s["D"], k)
        rho = s["L"] * np.linalg.norm(s["D"] - Dk[..., None] * k, axis=-1)
        return np.arcsin(np.clip(s["sq"] / rho, 0.0, 1.0))

    def igm_jacobian_pose(self, X, x=None) -> np.ndarray:
        """d q / d X (N, 4 joints, 4 pose components [x, y, z, theta]) rad/m and rad/rad."""
        X = self._check_X(X)
        s = self._solve(X, self._x(x))
        if not np.all(np.isfinite(s["q"])):
            self._raise_unreachable(X, s["q"], s["sq"])
        return self._jac_pose(s)

    @staticmethod
    def _jac_pose(s):
        dA_dth = (EPS_H * s["h"])[None, :, None] * np.stack(
            [-s["r"][:, 1], s["r"][:, 0], np.zeros(len(s["r"]))], -1
        )[:, None, :]
        Jp = np.empty(s["q"].shape + (4,))
        Jp[..., :3] = s["dD"]
        Jp[..., 3] = np.einsum("nij,nij->ni", s["dD"], dA_dth)
        return Jp

    def igm_jacobian_params(self, X, x=None) -> np.ndarray:
        """d q / d x (N, 4, n) over the full parameter vector, X fixed in B (external columns 0)."""
        X = self._check_X(X)
        s = self._solve(X, self._x(x))
        if not np.all(np.isfinite(s["q"])):
            self._raise_unreachable(X, s["q"], s["sq"])
        return self._jac_params(s)

    @staticmethod
    def _jac_params(s):
        N = s["q"].shape[0]
        Jprim = np.zeros((N, 4, _NP))
        Jprim[..., 0:3] = -s["dD"]
        Jprim[..., 3] = s["dpsi"]
        Jprim[..., 4] = s["dbeta"]
        Jprim[..., 5] = s["dL"]
        Jprim[..., 6] = s["dl"]
        Jprim[..., 7] = np.einsum("nij,nj->ni", s["dD"], s["r"]) * EPS_H
        Jprim[..., 8] = s["dD"][..., 1] * EPS_D
        Jprim[..., 9] = -1.0
        return np.einsum("nip,ipk->nik", Jprim, s["M"])

    # ------------------------------------------------------------------ FGM
    def fgm(self, q, x=None, X0=None, tol=1e-13, max_iter=60) -> np.ndarray:
        """Forward model by Newton on the IGM: q (N, 4) rad -> X (N, 4). X0: (4,) or (N, 4)
        starting pose(s), default the workspace centre at theta = 0. Steps are halved when an
        iterate leaves the reachable set. DataError if it does not converge."""
        q = self._check_X(q, "joint set")
        x = self._x(x)
        N = q.shape[0]
        X = np.broadcast_to(
            np.append(self.center, 0.0) if X0 is None else np.asarray(X0, float), (N, 4)
        ).copy()
        s = self._solve(X, x)
        if not np.all(np.isfinite(s["q"])):
            self._raise_unreachable(X, s["q"], s["sq"])
        for _ in range(max_iter):
            e = s["q"] - q
            e = _wrap(e)
            try:
                dX = -np.linalg.solve(self._jac_pose(s), e[..., None])[..., 0]
            except np.linalg.LinAlgError:
                raise DataError("H4 FGM: singular pose Jacobian (parallel singularity) during Newton") from None
            step = np.ones(N)
            for _h in range(30):
                Xn = X + step[:, None] * dX
                sn = self._solve(Xn, x)
                bad = ~np.all(np.isfinite(sn["q"]), axis=1)
                if not bad.any():
                    break
                step[bad] *= 0.5
            else:
                raise DataError("H4 FGM: Newton iterates left the reachable workspace")
            X, s = Xn, sn
            if np.max(np.abs(dX)) < tol:
                break
        err = np.abs(_wrap(s["q"] - q))
        if np.max(err) > 1e-9:
            i = int(np.argmax(err.max(axis=1)))
            raise DataError(f"H4 FGM did not converge for joint set {i}: residual {err[i].max():.3g} rad")
        return X

    def joint_offset_form(self, x=None) -> tuple[np.ndarray, np.ndarray]:
        """(x (n,) unchanged, offsets (4,) = q0_1..q0_4 rad): the motor angle is q_i + q0_i
        (``kinematics.protocols.JointOffsetForm``)."""
        x = self._x(x).copy()
        return x, np.array([x[self.names.index(f"q0_{i}")] for i in range(1, 5)])

    # ------------------------------------------------------------------ copies
    def with_values(self, x) -> "H4Robot":
        """Copy whose nominal values are x (n,) (e.g. a perturbed 'true' robot)."""
        return replace(self, params=self.params.with_nominal(self._x(x)))

    def pose_grid(self) -> np.ndarray:
        """The seed's 81-pose grid on this robot's workspace, (81, 4)."""
        return pose_grid_81(self.center, self.size, self.theta_deg)

