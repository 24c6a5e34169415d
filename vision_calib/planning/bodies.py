"""The robot's collision model for the planner: a list of rigid bodies, each attached to one of the arm's frames
(:class:`~vision_calib.rig.base.ArmFrames` ``link_frames``: base, after each joint, flange, right mount), and the
pairs of bodies checked against each other; plus the cell's obstacles as the same kind of bodies, static in the
robot base frame.

Where the bodies come from:

- the URDF's ``<collision>`` elements (box, cylinder, sphere; a link reached from the chain through fixed joints
  counts), when the robot file is a URDF that has some on the chain's links; a link whose collision geometry is a
  mesh gets its primitive capsule instead (named in the notes);
- else primitives: a capsule from each joint origin to the next (the base: from the base frame to joint 1; the last
  link: to the flange; a zero-length link is a sphere), radius per link from the scene (``planning.link_radii``)
  or :data:`DEFAULT_LINK_RADII_M` for the shipped robots (otherwise :data:`FALLBACK_RADIUS_FRACTION` of the longest
  link, at most :data:`DEFAULT_RADIUS_M`, named in the notes);
- always: the tool on the flange, a capsule from the flange to the right mount (the camera of an eye-in-hand cell,
  the target of a fixed camera) of radius ``planning.tool_radius`` (default 0.04 m); a target on the flange is also
  a thin box of the board's outline.

Pairs: every moving body against every obstacle (bodies on the base frame are not: the base stands where the cell
puts it, on its table or pedestal), and every two bodies of non-adjacent frames (frames i and i + 1 are adjacent;
the flange and the right mount are one rigid body), except the pairs that are closer than the clearance in nearly
every configuration (:data:`ALWAYS_NEAR_FRACTION` of :data:`ALWAYS_NEAR_SAMPLES` joint sets drawn in the joint
limits: structural neighbours such as a wrist link and the forearm, MoveIt's "always in collision" pairs), named.

Every body has a **hull**: a capsule (segment + radius) that contains it, exact for capsules and spheres; the
broad phase (:mod:`.collision`) bounds distances with the hulls, FCL gives the exact ones.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..frames import make_T
from ..rig.cell import Obstacle

#: link radii [m] of the primitive model of the shipped robots (robot name -> n radii: the base up to joint 1, then
#: the link from each joint to the next, the last to the flange), from their data sheets' outer diameters
#: (UR5e: base 149 mm, shoulder and elbow housings ~120 mm, tubes ~85 / 75 mm, wrists 90 mm)
DEFAULT_LINK_RADII_M = {
    "ur5e": (0.08, 0.075, 0.06, 0.05, 0.045, 0.045),
    "rx90": (0.12, 0.10, 0.08, 0.07, 0.05, 0.04),
}
DEFAULT_RADIUS_M = 0.05
#: the radius of every link of a robot without defaults: this fraction of its longest link (a slender arm)
FALLBACK_RADIUS_FRACTION = 0.1
DEFAULT_TOOL_RADIUS_M = 0.04
#: thickness [m] of a board on the flange (fixed camera) or on the table (eye-in-hand) as a body / obstacle
BOARD_THICKNESS_M = 0.005
#: radius [m] of a tripod camera as an obstacle (fixed-camera cells)
TRIPOD_CAMERA_RADIUS_M = 0.05
#: a pair of bodies closer than the clearance in at least this fraction of random joint sets is not checked
ALWAYS_NEAR_FRACTION = 0.99
ALWAYS_NEAR_SAMPLES = 1000
#: joint sets of the scene's own sampler on which no checked self pair may be closer than its allowed distance
OWN_POSES = 500
#: a self pair that the scene's own poses bring closer than the clearance keeps being checked, at an allowed distance
#: of its smallest distance over those poses minus this margin [m] (other sampler draws go a little deeper)
OWN_POSE_MARGIN_M = 0.01
#: the side [m] of the box that stands for a plane in FCL (its distance queries to a half-space are unreliable)
PLANE_BOX_M = 20.0


@dataclass(frozen=True)
class Body:
    """One rigid body. frame: index of the ``link_frames`` frame it is attached to (-1: static, robot base frame);
    shape: capsule | sphere | box | cylinder; dims: capsule/cylinder (radius, length), sphere (radius,), box (x, y, z)
    edges [m]; T_frame_body (4, 4): the shape's centre pose in that frame (capsule and cylinder axes along its z);
    hull_a, hull_b (3,), hull_r: a capsule containing the shape (frame coordinates), ``exact`` when it is the shape;
    plane: a half-space (the plane z = 0 of T_frame_body, solid below), hull unused."""

    name: str
    frame: int
    shape: str
    dims: tuple[float, ...]
    T_frame_body: np.ndarray
    hull_a: np.ndarray
    hull_b: np.ndarray
    hull_r: float
    exact: bool
    plane: bool = False


def _axis_frame(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(4, 4) pose centred between a and b (3,) with its z axis along b - a (any z when a == b)."""
    d = b - a
    n = np.linalg.norm(d)
    z = d / n if n > 1e-12 else np.array([0.0, 0.0, 1.0])
    x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    return make_T(np.column_stack([x, np.cross(z, x), z]), 0.5 * (a + b))


def segment_body(name: str, frame: int, a, b, radius: float) -> Body:
    """A capsule from a to b (3,) [m, frame coordinates] of ``radius`` (a sphere when a == b)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    length = float(np.linalg.norm(b - a))
    if length < 1e-9:
        return Body(name, frame, "sphere", (float(radius),), make_T(None, a), a, a, float(radius), True)
    return Body(name, frame, "capsule", (float(radius), length), _axis_frame(a, b), a, b, float(radius), True)


def shape_body(name: str, frame: int, shape: str, dims, T: np.ndarray) -> Body:
    """A box (x, y, z edges), cylinder (radius, length, axis z) or sphere (radius,) centred at T (4, 4), with the
    smallest capsule along its longest axis as hull."""
    T = np.asarray(T, float)
    dims = tuple(float(v) for v in dims)
    if shape == "sphere":
        c = T[:3, 3]
        return Body(name, frame, shape, dims, T, c, c, dims[0], True)
    if shape == "cylinder":
        r, h = dims
        ax = T[:3, 2] * (0.5 * h)
        return Body(name, frame, shape, dims, T, T[:3, 3] - ax, T[:3, 3] + ax, r, False)
    if shape == "box":
        half = np.array(dims) / 2
        k = int(np.argmax(half))
        others = [i for i in range(3) if i != k]
        ax = T[:3, k] * half[k]
        return Body(name, frame, shape, dims, T, T[:3, 3] - ax, T[:3, 3] + ax,
                    float(np.hypot(half[others[0]], half[others[1]])), False)
    raise ValueError(f"unknown shape {shape!r}")


def obstacle_bodies(obstacles: tuple[Obstacle, ...]) -> list[Body]:
    """The cell's obstacles as static bodies (frame -1, robot base frame); a plane as a half-space body."""
    out = []
    for o in obstacles:
        if o.kind == "plane":
            T = np.asarray(o.T_base_obj, float)
            out.append(Body(o.name, -1, "box", (PLANE_BOX_M, PLANE_BOX_M, PLANE_BOX_M / 2),
                            T @ make_T(None, [0.0, 0.0, -PLANE_BOX_M / 4]), T[:3, 3], T[:3, 3], 0.0, True, plane=True))
        else:
            out.append(shape_body(o.name, -1, o.kind, o.dims_m, o.T_base_obj))
    return out


@dataclass(frozen=True)
class RobotModel:
    """The robot's bodies (attached to ``link_frames`` indices), the static obstacles, and the pairs checked:
    ``obstacle_pairs`` (K, 2) [robot body, obstacle] and ``self_pairs`` (S, 2) [body, body] indices; ``disabled``:
    [(body, body, why)] of the self pairs left out beyond adjacent frames; ``self_allowed_m`` (S,) [m]: the distance
    each self pair must keep (the clearance, or less for a pair the scene's own poses bring closer: ``reduced``
    [(body, body, allowed m, why)]; negative: the primitive shapes may overlap that deep); ``source``: where the
    bodies came from; ``notes``: what the model could not represent; ``warnings``: collision geometry it did not
    read (named, with what was checked instead), the self pairs checked at a reduced distance."""

    bodies: tuple[Body, ...]
    obstacles: tuple[Body, ...]
    obstacle_pairs: np.ndarray
    self_pairs: np.ndarray
    source: str
    disabled: tuple = ()
    notes: tuple[str, ...] = field(default=())
    warnings: tuple[str, ...] = field(default=())
    self_allowed_m: np.ndarray | None = None
    reduced: tuple = ()

    def to_dict(self) -> dict:
        return {"source": self.source,
                "bodies": [{"name": b.name, "frame": b.frame, "shape": b.shape, "dims_m": list(b.dims)}
                           for b in self.bodies],
                "obstacles": [{"name": b.name, "shape": "plane" if b.plane else b.shape,
                               "dims_m": [] if b.plane else list(b.dims)} for b in self.obstacles],
                "self_pairs_checked": [[self.bodies[i].name, self.bodies[j].name] for i, j in self.self_pairs],
                "self_pairs_left_out": [{"pair": [a, b], "why": why} for a, b, why in self.disabled],
                "self_pairs_reduced": [{"pair": [a, b], "allowed_m": d, "why": why} for a, b, d, why in self.reduced],
                "notes": list(self.notes), "warnings": list(self.warnings)}


# ----------------------------------------------------------------------------------------------- URDF geometry
def _numbers(text, n: int | None, where: str, what: str, positive: bool = False) -> tuple[float, ...]:
    """The whitespace-separated numbers of a URDF attribute: ConfigError naming ``where`` (file, link) and ``what``
    when they do not read, are not ``n`` many, are not finite or (``positive``) not > 0."""
    from ..errors import ConfigError

    try:
        v = tuple(float(t) for t in str(text).split())
    except ValueError:
        raise ConfigError(f"{where}: {what} {text!r} is not a list of numbers") from None
    if n is not None and len(v) != n:
        raise ConfigError(f"{where}: {what} {text!r}: expected {n} numbers, got {len(v)}")
    if not all(np.isfinite(v)):
        raise ConfigError(f"{where}: {what} {text!r} is not finite")
    if positive and not all(x > 0 for x in v):
        raise ConfigError(f"{where}: {what} {text!r}: sizes must be > 0")
    return v


def _origin(el, where: str = "URDF") -> np.ndarray:
    from scipy.spatial.transform import Rotation

    from ..errors import ConfigError

    T = np.eye(4)
    if el is not None:
        T[:3, 3] = _numbers(el.get("xyz", "0 0 0"), 3, where, "origin xyz")
        rpy = _numbers(el.get("rpy", "0 0 0"), 3, where, "origin rpy")
        if max(abs(a) for a in rpy) > 2 * np.pi + 0.1:
            raise ConfigError(f"{where}: origin rpy {el.get('rpy')!r} is beyond +-2 pi: URDF angles are in radians "
                              "(degrees read as radians?)")
        T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    return T


def urdf_collisions(path: Path, chain_links: tuple[str, ...]) -> tuple[dict, list[str]]:
    """({chain frame index: [(link, shape, dims, T_frame_shape (4, 4))]}, notes) of the URDF's ``<collision>``
    elements on links rigidly attached (through fixed joints) to the chain's links ``chain_links`` (the names of
    ``link_frames`` 0..n, base to tip); mesh geometry is listed in the notes (with the frame, under shape "mesh")."""
    root = ET.parse(path).getroot()
    fixed = {}  # link -> [(other link, T_link_other)] over fixed joints, both directions
    for j in root.findall("joint"):
        if j.get("type") != "fixed":
            continue
        p, c = j.find("parent").get("link"), j.find("child").get("link")
        T = _origin(j.find("origin"), f"{path}: joint {j.get('name')!r}")
        fixed.setdefault(p, []).append((c, T))
        fixed.setdefault(c, []).append((p, np.linalg.inv(T)))
    where = {}  # link -> (chain frame index, T_frame_link)
    for k, name in enumerate(chain_links):
        if name in where:
            continue
        todo = [(name, np.eye(4))]
        while todo:
            lk, T = todo.pop()
            if lk in where:
                continue
            where[lk] = (k, T)
            todo += [(o, T @ To) for o, To in fixed.get(lk, ()) if o not in where]
    out, notes = {}, []
    for link in root.findall("link"):
        name = link.get("name")
        cols = link.findall("collision")
        if not cols:
            continue
        if name not in where:
            notes.append(f"link {name!r}: collision geometry not checked (not rigid with the calibrated chain)")
            continue
        k, T_fl = where[name]
        for c in cols:
            g = c.find("geometry")
            at = f"{path}: link {name!r} <collision>"
            T = T_fl @ _origin(c.find("origin"), at)
            el = None if g is None else next(iter(g), None)
            if el is None:
                continue
            if el.tag == "box":
                dims = _numbers(el.get("size"), 3, at, "box size", positive=True)
                out.setdefault(k, []).append((name, "box", dims, T))
            elif el.tag in ("cylinder", "capsule"):
                dims = (_numbers(el.get("radius"), 1, at, f"{el.tag} radius", positive=True)[0],
                        _numbers(el.get("length"), 1, at, f"{el.tag} length", positive=True)[0])
                out.setdefault(k, []).append((name, el.tag, dims, T))
            elif el.tag == "sphere":
                out.setdefault(k, []).append((name, "sphere", _numbers(el.get("radius"), 1, at, "sphere radius",
                                                                       positive=True), T))
            else:
                out.setdefault(k, []).append((name, "mesh", (), T))
    return out, notes


# ----------------------------------------------------------------------------------------------- the model
def _tool_bodies(setup, frames_ref: np.ndarray, radius: float, target) -> list[Body]:
    """The tool: a capsule flange -> right mount (frame n), and a target on the flange as a thin box (frame n + 1)."""
    n1 = frames_ref.shape[0] - 1
    Fn, Fm = frames_ref[n1 - 1], frames_ref[n1]
    b = (np.linalg.inv(Fn) @ np.append(Fm[:3, 3], 1.0))[:3]
    right = setup.link_names()[-1]
    what = {"eye_in_hand": "camera", "fixed": "target"}.get(setup.mount, "tool")
    out = [segment_body(f"{what} ({right})", n1 - 1, np.zeros(3), b, radius)]
    if what == "target" and target is not None:
        x0, y0, x1, y1 = target.texture_extent_m()
        T = make_T(None, [(x0 + x1) / 2, (y0 + y1) / 2, BOARD_THICKNESS_M / 2])
        out.append(shape_body("target board", n1, "box", (x1 - x0, y1 - y0, BOARD_THICKNESS_M), T))
    return out


def primitive_bodies(setup, frames_ref: np.ndarray, radii) -> list[Body]:
    """Capsules between consecutive frame origins 0..n (base up to joint 1, ..., the last link to the flange),
    each rigid with its first frame; ``frames_ref`` (n + 2, 4, 4): the frames at one configuration."""
    names = setup.link_names()
    n = frames_ref.shape[0] - 2
    out = []
    for k in range(n):
        b = (np.linalg.inv(frames_ref[k]) @ np.append(frames_ref[k + 1][:3, 3], 1.0))[:3]
        out.append(segment_body(names[k], k, np.zeros(3), b, radii[k]))
    return out


def mount_obstacles(setup, target) -> tuple[Obstacle, ...]:
    """Obstacles the mount implies: the board on the table of an eye-in-hand cell (a box of its outline,
    BOARD_THICKNESS_M thick on the side its printed face does not show: target z > 0), the tripod camera of a fixed
    one (a sphere of TRIPOD_CAMERA_RADIUS_M); poses from the nominal model at the zero joint set."""
    q0 = np.zeros((1, setup.n_joints))
    T_base_right = setup.link_frames(q0)[0, -1]
    T_cam_target = setup.T_cam_target(q0, setup.params.nominal)[0]
    if setup.mount == "eye_in_hand":
        if target is None:
            return ()
        x0, y0, x1, y1 = target.texture_extent_m()
        T = T_base_right @ T_cam_target @ make_T(None, [(x0 + x1) / 2, (y0 + y1) / 2, BOARD_THICKNESS_M / 2])
        return (Obstacle("box", "target board", T, (x1 - x0, y1 - y0, BOARD_THICKNESS_M)),)
    if setup.mount == "fixed":
        T_base_cam = T_base_right @ np.linalg.inv(T_cam_target)
        return (Obstacle("sphere", "tripod camera", T_base_cam, (TRIPOD_CAMERA_RADIUS_M,)),)
    return ()


def segment_distance(p1, q1, p2, q2) -> np.ndarray:
    """Distance [m] between segments [p1, q1] and [p2, q2] (..., 3) each, broadcast (Ericson, Real-Time Collision
    Detection, 5.1.9), vectorised."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum("...i,...i->...", d1, d1)
    e = np.einsum("...i,...i->...", d2, d2)
    f = np.einsum("...i,...i->...", d2, r)
    c = np.einsum("...i,...i->...", d1, r)
    b = np.einsum("...i,...i->...", d1, d2)
    eps = 1e-18
    a_ok, e_ok = a > eps, e > eps
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > eps * np.maximum(a * e, eps), np.clip((b * f - c * e) / denom, 0, 1), 0.0)
        t = np.where(e_ok, (b * s + f) / np.where(e_ok, e, 1.0), 0.0)
        s_lo = np.where(a_ok, np.clip(-c / np.where(a_ok, a, 1.0), 0, 1), 0.0)
        s_hi = np.where(a_ok, np.clip((b - c) / np.where(a_ok, a, 1.0), 0, 1), 0.0)
    s = np.where(t < 0, s_lo, np.where(t > 1, s_hi, s))
    t = np.clip(t, 0, 1)
    # degenerate first segment (a point): s = 0, t from the point's projection
    s = np.where(a_ok, s, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(a_ok, t, np.where(e_ok, np.clip(f / np.where(e_ok, e, 1.0), 0, 1), 0.0))
    # first segment a segment but the second a point: t = 0, s from the projection
    s = np.where(a_ok & ~e_ok, s_lo, s)
    d = (p1 + d1 * s[..., None]) - (p2 + d2 * t[..., None])
    return np.sqrt(np.einsum("...i,...i->...", d, d))


def body_hulls(bodies, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hull segment ends of the robot bodies in the base frame, (N, B, 3) each, for frames (N, n + 2, 4, 4)."""
    idx = np.array([b.frame for b in bodies], int)
    A = np.array([np.append(b.hull_a, 1.0) for b in bodies])
    Bm = np.array([np.append(b.hull_b, 1.0) for b in bodies])
    Fk = frames[:, idx]  # (N, B, 4, 4)
    return np.einsum("nbij,bj->nbi", Fk, A)[..., :3], np.einsum("nbij,bj->nbi", Fk, Bm)[..., :3]


def build_model(scene, setup, rng: np.random.Generator | None = None) -> RobotModel:
    """The collision model of a scene's arm (module docstring): bodies, obstacles and the checked pairs."""
    ps = scene.planning
    n = setup.n_joints
    q_ref = np.zeros((1, n))
    frames_ref = setup.link_frames(q_ref)[0]
    notes, warns = [], []
    radii = ps.link_radii_m
    if radii is None:
        radii = DEFAULT_LINK_RADII_M.get(setup.robot_name)
        if radii is None or len(radii) != n:
            longest = float(np.max(np.linalg.norm(np.diff(frames_ref[:n + 1, :3, 3], axis=0), axis=1)))
            r = min(DEFAULT_RADIUS_M, FALLBACK_RADIUS_FRACTION * longest)
            radii = (r,) * n
            notes.append(f"link radii: {r:.3g} m for every link ({100 * FALLBACK_RADIUS_FRACTION:.0f} % of the longest "
                         f"link; no default for robot {setup.robot_name!r}: give planning.link_radii in the scene)")
    prim = primitive_bodies(setup, frames_ref, radii)
    bodies, source = prim, "primitives: capsules between consecutive joint origins (link radii " + \
        ", ".join(f"{r:.3g}" for r in radii) + " m)"
    robot_file = Path(setup.robot_file) if setup.robot_file else None
    if robot_file is not None and robot_file.suffix.lower() == ".urdf":
        cols, more = urdf_collisions(robot_file, setup.link_names()[:-1])
        if cols:
            bodies, source = [], f"URDF collision elements ({robot_file.name})"
            bare = []
            for k in range(n + 1):
                items = cols.get(k, [])
                if not items and k < n:  # no <collision> on this link: its primitive capsule, named
                    bodies.append(prim[k])
                    bare.append(prim[k].name)
                if any(s == "mesh" for _, s, _, _ in items):
                    meshes = sorted({lk for lk, s, _, _ in items if s == "mesh"})
                    warns.append(f"{', '.join(meshes)}: mesh collision geometry is not read"
                                 + (f": the primitive capsule of {prim[k].name} is used" if k < n else
                                    " (no primitive on the flange: not checked)"))
                    if k < n:
                        bodies.append(prim[k])
                per_link = {}
                for link, _, _, _ in items:
                    per_link[link] = per_link.get(link, 0) + 1
                seen = {}
                for link, shape, dims, T in items:
                    j = seen[link] = seen.get(link, -1) + 1
                    if shape == "mesh":
                        continue
                    nm = link if per_link[link] == 1 else f"{link}[{j}]"
                    if shape == "capsule":
                        ax = T[:3, 2] * dims[1] / 2
                        bodies.append(segment_body(nm, k, T[:3, 3] - ax, T[:3, 3] + ax, dims[0]))
                    else:
                        bodies.append(shape_body(nm, k, shape, dims, T))
            if bare:
                warns.append(f"{', '.join(bare)}: no collision element in the URDF: the primitive capsules are used")
            if warns:
                warns[-1] += " (checked: " + ", ".join(b.name for b in bodies) + ")"
            warns += more
    tool_r = DEFAULT_TOOL_RADIUS_M if ps.tool_radius_m is None else ps.tool_radius_m
    target = None
    if scene.target_path is not None:
        from ..targets import load_target

        target = load_target(scene.target_path)
    bodies = list(bodies) + _tool_bodies(setup, frames_ref, tool_r, target)
    obstacles = obstacle_bodies(tuple(scene.obstacles) + mount_obstacles(setup, target))
    group = np.array([min(b.frame, n) for b in bodies])  # the right mount (n + 1) is rigid with the flange (n)
    moving = group > 0
    obstacle_pairs = np.array([(i, j) for i in np.flatnonzero(moving) for j in range(len(obstacles))], int).reshape(-1, 2)
    cand = [(i, j) for i in range(len(bodies)) for j in range(i + 1, len(bodies)) if abs(group[i] - group[j]) > 1]
    disabled, keep, allowed, reduced = [], [], [], []
    if cand:
        rng = rng or np.random.default_rng(0)
        r = np.array([bd.hull_r for bd in bodies])
        P = np.array(cand)

        def pair_bounds(q):
            a, b = body_hulls(bodies, setup.link_frames(q))
            return segment_distance(a[:, P[:, 0]], b[:, P[:, 0]], a[:, P[:, 1]], b[:, P[:, 1]]) - r[P[:, 0]] - r[P[:, 1]]

        d = pair_bounds(setup.generic_poses(rng, ALWAYS_NEAR_SAMPLES))
        near = np.mean(d < ps.clearance_m, axis=0)
        # the scene's own poses (its random sampler, target in view) are poses the arm takes: a pair of capsules
        # closer than the clearance there is a modelling error of the primitives, not a collision; the pair is still
        # checked, at a distance just below the smallest those poses reach (it refuses poses that go deeper)
        own = own_poses(scene, setup, rng)
        d_own = pair_bounds(own) if own is not None else None
        for k, ((i, j), f) in enumerate(zip(cand, near)):
            if f >= ALWAYS_NEAR_FRACTION:
                disabled.append((bodies[i].name, bodies[j].name,
                                 f"closer than the clearance in {100 * f:.0f} % of {ALWAYS_NEAR_SAMPLES} random joint "
                                 "sets (structural neighbours)"))
                continue
            keep.append((i, j))
            allowed.append(ps.clearance_m)
            if d_own is not None and np.any(d_own[:, k] < ps.clearance_m):
                allowed[-1] = float(np.min(d_own[:, k])) - OWN_POSE_MARGIN_M
                if not (bodies[i].exact and bodies[j].exact):  # FCL decides: a distance, never a penetration depth
                    allowed[-1] = max(allowed[-1], 0.0)
                reduced.append((bodies[i].name, bodies[j].name, allowed[-1],
                                f"closer than the clearance in {int(np.sum(d_own[:, k] < ps.clearance_m))} of "
                                f"{len(own)} of the scene's own random poses (smallest {1e3 * np.min(d_own[:, k]):.1f} "
                                "mm)"))
    if reduced:
        warns.append("self pairs checked at a reduced distance (the primitive shapes come closer than the clearance "
                     f"{1e3 * ps.clearance_m:.0f} mm on the scene's own random poses, where the arm does not collide: "
                     "give planning.link_radii or URDF collision elements): "
                     + "; ".join(f"{a} / {b} at {1e3 * d:.1f} mm ({1e3 * (ps.clearance_m - d):.1f} mm less)"
                                 for a, b, d, _ in reduced))
    return RobotModel(tuple(bodies), tuple(obstacles), obstacle_pairs, np.array(keep, int).reshape(-1, 2), source,
                      tuple(disabled), tuple(notes), tuple(warns), np.array(allowed, float), tuple(reduced))


def own_poses(scene, setup, rng: np.random.Generator) -> np.ndarray | None:
    """(OWN_POSES, n) joint sets of the scene's own random pose sampler (``sample_poses``: its region, target in
    view; what ``simulate`` draws its random identification and validation poses from), None when it finds none."""
    from ..errors import VisionCalibError

    try:
        return setup.sample_poses(rng, OWN_POSES)
    except VisionCalibError:
        return None


__all__ = ["Body", "RobotModel", "build_model", "segment_distance", "body_hulls", "DEFAULT_LINK_RADII_M",
           "segment_body", "shape_body", "obstacle_bodies", "urdf_collisions"]
