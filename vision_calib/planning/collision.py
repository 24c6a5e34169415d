"""Collision and clearance checks of joint sets against the robot's collision model (:mod:`.bodies`), with FCL.

Two phases, per joint set:

1. broad phase, numpy, vectorised over all joint sets and pairs: a lower bound of every checked pair's distance
   from the bodies' capsule hulls (segment-to-segment distance minus both radii). A pair whose bound is at least
   the clearance is clear. When both hulls are the shapes themselves (capsules, spheres) the bound IS the
   distance: the pair is decided there. The height of any body above a plane is computed exactly
   (:func:`plane_heights`; FCL's half-space distance query is unreliable: it crashed in python-fcl 0.7, and a large
   box standing for the plane is off by ~0.5 mm);
2. narrow phase, FCL, only for the pairs left (a box or a cylinder closer than the clearance by its hull):
   ``fcl.distance`` on the exact shapes.

:func:`CollisionChecker.clearances` gives the exact clearance of a few joint sets (FCL on every pair): what the
plan reports per pose. FCL is imported on first use (``errors.import_extra``: the ``[plan]`` extra).
"""

from __future__ import annotations

import numpy as np

from ..errors import import_extra
from .bodies import Body, RobotModel, body_hulls, segment_distance

#: a pair whose distance varies less than this [m] over the scene's poses is fixed by the geometry
FIXED_DISTANCE_M = 0.002
#: joint sets per broad-phase block (memory: ~ pairs x block x 100 bytes)
BLOCK = 4096


def plane_heights(shape: str, dims, T: np.ndarray, n: np.ndarray, p0: np.ndarray) -> np.ndarray:
    """Signed distance [m] of a body (shape, dims as ``bodies.Body``) at poses T (..., 4, 4) above the plane through
    p0 (3,) of unit normal n (3,) (negative: it reaches below the plane)."""
    c = np.einsum("...i,i->...", T[..., :3, 3] - p0, n)
    if shape == "sphere":
        return c - dims[0]
    cz = np.abs(np.einsum("...i,i->...", T[..., :3, 2], n))
    if shape == "capsule":
        return c - 0.5 * dims[1] * cz - dims[0]
    if shape == "cylinder":
        return c - 0.5 * dims[1] * cz - dims[0] * np.sqrt(np.clip(1 - cz**2, 0, 1))
    h = np.asarray(dims, float) / 2  # box: the lowest corner
    return c - sum(h[k] * np.abs(np.einsum("...i,i->...", T[..., :3, k], n)) for k in range(3))


def _fcl():
    return import_extra("fcl", "plan", "collision checks of planned poses")


def _geometry(fcl, b: Body):
    if b.shape == "capsule":
        return fcl.Capsule(b.dims[0], b.dims[1])
    if b.shape == "sphere":
        return fcl.Sphere(b.dims[0])
    if b.shape == "box":
        return fcl.Box(*b.dims)
    return fcl.Cylinder(b.dims[0], b.dims[1])


class CollisionChecker:
    """Checks joint sets' link frames (N, n + 2, 4, 4) [m, robot base frame] against a :class:`RobotModel` with a
    clearance [m]. ``n_fcl``: FCL distance queries made so far (the narrow phase's cost)."""

    def __init__(self, model: RobotModel, clearance_m: float):
        self.fcl = _fcl()
        self.model = model
        self.clearance = float(clearance_m)
        fcl = self.fcl
        self.robot_objs = [fcl.CollisionObject(_geometry(fcl, b), fcl.Transform()) for b in model.bodies]
        self.obst_objs = []
        for b in model.obstacles:
            T = b.T_frame_body
            self.obst_objs.append(fcl.CollisionObject(_geometry(fcl, b), fcl.Transform(T[:3, :3], T[:3, 3])))
        self.r = np.array([b.hull_r for b in model.bodies])
        self.n_fcl = 0
        self.request = fcl.DistanceRequest()
        obs = model.obstacles
        self.o_plane = np.array([b.plane for b in obs], bool)
        self.o_a = np.array([b.hull_a for b in obs]).reshape(-1, 3)
        self.o_b = np.array([b.hull_b for b in obs]).reshape(-1, 3)
        self.o_r = np.array([b.hull_r for b in obs])
        self.o_n = np.array([b.T_frame_body[:3, 2] for b in obs]).reshape(-1, 3)  # plane normals (+z of the plane)
        self.o_exact = np.array([b.exact for b in obs], bool)
        self.b_exact = np.array([b.exact for b in model.bodies], bool)
        self.varying = None  # (obstacle pairs (K,) bool, self pairs (S,) bool) of the clearance figures
        # (S,) distance each self pair must keep: the clearance, or the model's reduced one (RobotModel.reduced)
        self.self_allowed = np.full(len(model.self_pairs), self.clearance) if model.self_allowed_m is None else \
            np.minimum(np.asarray(model.self_allowed_m, float), self.clearance)

    def mark_fixed(self, frames: np.ndarray) -> dict:
        """Mark the pairs whose distance bound varies less than :data:`FIXED_DISTANCE_M` over the joint sets'
        frames (N, n + 2, 4, 4) (the scene's own poses: a sphere on joint 1's axis and the table, a wrist link and
        the camera) as fixed: :meth:`clearances` leaves them out. Returns {obstacle: [[body, obstacle]], self:
        [[body, body]]} of the fixed pairs."""
        lo, ls = self.lower_bounds(frames)
        vo, vs = np.ptp(lo, axis=0) >= FIXED_DISTANCE_M, np.ptp(ls, axis=0) >= FIXED_DISTANCE_M
        if not (vo.any() or vs.any()):
            return {"obstacle": [], "self": []}
        self.varying = (vo, vs)
        names = [b.name for b in self.model.bodies]
        onames = [b.name for b in self.model.obstacles]
        op, sp = self.model.obstacle_pairs, self.model.self_pairs
        return {"obstacle": [[names[i], onames[j]] for i, j in op[~vo]],
                "self": [[names[i], names[j]] for i, j in sp[~vs]]}

    # ------------------------------------------------------------------ broad phase
    def lower_bounds(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(obstacle pair bounds (N, K), self pair bounds (N, S)) [m]: lower bounds of the pairs' distances."""
        a, b = body_hulls(self.model.bodies, frames)
        op, sp = self.model.obstacle_pairs, self.model.self_pairs
        N = frames.shape[0]
        lo = np.empty((N, len(op)))
        if len(op):
            bi, oi = op[:, 0], op[:, 1]
            pl = self.o_plane[oi]
            for k in np.flatnonzero(pl):  # exact height above the plane
                bd = self.model.bodies[bi[k]]
                T = frames[:, bd.frame] @ bd.T_frame_body
                lo[:, k] = plane_heights(bd.shape, bd.dims, T, self.o_n[oi[k]], self.o_a[oi[k]])
            k = np.flatnonzero(~pl)
            if k.size:
                lo[:, k] = segment_distance(a[:, bi[k]], b[:, bi[k]], self.o_a[oi[k]], self.o_b[oi[k]]) \
                    - self.r[bi[k]] - self.o_r[oi[k]]
        ls = np.empty((N, len(sp)))
        if len(sp):
            i, j = sp[:, 0], sp[:, 1]
            ls[:] = segment_distance(a[:, i], b[:, i], a[:, j], b[:, j]) - self.r[i] - self.r[j]
        return lo, ls

    # ------------------------------------------------------------------ narrow phase
    def place(self, frame_set: np.ndarray, bodies) -> None:
        """Set the FCL transforms of the robot bodies ``bodies`` (indices) for one joint set's frames (n + 2, 4, 4)."""
        for k in bodies:
            bd = self.model.bodies[k]
            T = frame_set[bd.frame] @ bd.T_frame_body
            self.robot_objs[k].setTransform(self.fcl.Transform(T[:3, :3], T[:3, 3]))

    def _distance(self, o1, o2) -> float:
        self.n_fcl += 1
        return float(self.fcl.distance(o1, o2, self.request, self.fcl.DistanceResult()))

    def screen(self, frames: np.ndarray) -> tuple[np.ndarray, list]:
        """(ok (N,) bool: every checked pair at least the clearance apart (a self pair: its allowed distance,
        ``RobotModel.self_allowed_m``); why: per joint set, the first pair found closer as (body, other, distance m)
        or None). Vectorised broad phase, FCL for undecided pairs only."""
        N = frames.shape[0]
        ok = np.ones(N, bool)
        why = [None] * N
        op, sp = self.model.obstacle_pairs, self.model.self_pairs
        op_exact = (self.b_exact[op[:, 0]] & self.o_exact[op[:, 1]]) | self.o_plane[op[:, 1]] if len(op) else \
            np.zeros(0, bool)
        sp_exact = self.b_exact[sp[:, 0]] & self.b_exact[sp[:, 1]] if len(sp) else np.zeros(0, bool)
        c, cs = self.clearance, self.self_allowed
        names = [b.name for b in self.model.bodies]
        onames = [b.name for b in self.model.obstacles]
        for s in range(0, N, BLOCK):
            F = frames[s:s + BLOCK]
            lo, ls = self.lower_bounds(F)
            # decided by the exact hulls
            bad_o = (lo < c) & op_exact
            bad_s = (ls < cs) & sp_exact
            for n in np.flatnonzero(bad_o.any(axis=1) | bad_s.any(axis=1)):
                ok[s + n] = False
                if bad_o[n].any():
                    k = int(np.argmin(np.where(bad_o[n], lo[n], np.inf)))
                    why[s + n] = (names[op[k, 0]], onames[op[k, 1]], float(lo[n, k]))
                else:
                    k = int(np.argmin(np.where(bad_s[n], ls[n], np.inf)))
                    why[s + n] = (names[sp[k, 0]], names[sp[k, 1]], float(ls[n, k]))
            # undecided: FCL on the exact shapes
            und_o = (lo < c) & ~op_exact
            und_s = (ls < cs) & ~sp_exact
            for n in np.flatnonzero((und_o.any(axis=1) | und_s.any(axis=1)) & ok[s:s + len(F)]):
                ko, ks = np.flatnonzero(und_o[n]), np.flatnonzero(und_s[n])
                self.place(F[n], set(op[ko, 0].tolist()) | set(sp[ks].ravel().tolist()))
                for k in ko:
                    d = self._distance(self.robot_objs[op[k, 0]], self.obst_objs[op[k, 1]])
                    if d < c:
                        ok[s + n], why[s + n] = False, (names[op[k, 0]], onames[op[k, 1]], d)
                        break
                if not ok[s + n]:
                    continue
                for k in ks:
                    d = self._distance(self.robot_objs[sp[k, 0]], self.robot_objs[sp[k, 1]])
                    if d < cs[k]:
                        ok[s + n], why[s + n] = False, (names[sp[k, 0]], names[sp[k, 1]], d)
                        break
        return ok, why

    def clearances(self, frames: np.ndarray) -> list[dict]:
        """Exact clearance of each joint set (FCL on every checked pair, planes exactly): [{clearance_m, closest: [body, other],
        obstacle_m, self_m}] (the smallest distance overall, to an obstacle, between two links; a negative or zero
        distance: in contact or penetrating). The pairs whose distance the joints do not change (:meth:`mark_fixed`;
        screened all the same) are left out: the same figure on every pose; so are the self pairs checked at a
        reduced distance (their primitive shapes overlap on poses the arm takes)."""
        out = []
        op, sp = self.model.obstacle_pairs, self.model.self_pairs
        # a self pair at a reduced distance (RobotModel.reduced): its primitives overlap where the arm does not
        full = self.self_allowed >= self.clearance
        if self.varying is not None:
            op, sp = op[self.varying[0]], sp[self.varying[1] & full]
        else:
            sp = sp[full]
        names = [b.name for b in self.model.bodies]
        onames = [b.name for b in self.model.obstacles]
        for F in frames:
            self.place(F, range(len(self.model.bodies)))
            best, which, d_o, d_s = np.inf, None, np.inf, np.inf
            for i, j in op:
                if self.o_plane[j]:
                    bd = self.model.bodies[i]
                    d = float(plane_heights(bd.shape, bd.dims, F[bd.frame] @ bd.T_frame_body, self.o_n[j], self.o_a[j]))
                else:
                    d = self._distance(self.robot_objs[i], self.obst_objs[j])
                d_o = min(d_o, d)
                if d < best:
                    best, which = d, [names[i], onames[j]]
            for i, j in sp:
                d = self._distance(self.robot_objs[i], self.robot_objs[j])
                d_s = min(d_s, d)
                if d < best:
                    best, which = d, [names[i], names[j]]
            out.append({"clearance_m": None if not np.isfinite(best) else float(best), "closest": which,
                        "obstacle_m": None if not np.isfinite(d_o) else float(d_o),
                        "self_m": None if not np.isfinite(d_s) else float(d_s)})
        return out


__all__ = ["CollisionChecker", "plane_heights"]
