"""The cell around the robot, as the pose planner (``vision_calib.planning``) needs it: static obstacles and the
planning settings of a scene, read once into typed SI values.

Scene keys (both optional; lengths and angles in the scene's ``units``, keys with a unit suffix in that unit)::

    obstacles:                     # static objects, poses in the robot base frame
      - {kind: plane, xyz: [0, 0, -0.092], rpy: [0, 0, 0], name: table}   # the plane z = 0 of its frame;
                                   # solid below it (on its -z side): the robot stays on its +z side
      - {kind: box, size: [0.3, 0.2, 0.15], xyz: [..], rpy: [..]}         # edges along the frame's x, y, z
      - {kind: cylinder, radius: 0.05, length: 0.4, xyz: [..], rpy: [..]} # axis along the frame's z, centred
      - {kind: sphere, radius: 0.1, xyz: [..]}
    planning:
      clearance: 0.02              # every robot body keeps this distance from the obstacles and its own links
      distance: [0.2, 1.5]         # camera-target distance limits (depth of field)
      max_incidence: 60            # board normal vs the viewing ray to the board centre
      margin_px: 10                # the whole board this far inside the image border
      max_joint_speed: 60          # per second, every joint (travel time of the tour)
      move_step: 2                 # sampling of the straight joint-space moves for collisions
      link_radii: [..]             # primitive collision model: n radii (the base up to joint 1, then the link
                                   # from joint i to joint i + 1, the last one to the flange)
      tool_radius: 0.04            # the body from the flange to the right mount (camera or target)

``obstacles``, ``link_radii`` and ``tool_radius`` need a robot kind with a collision model
(:class:`~vision_calib.rig.base.ArmFrames`); a scene of another kind (H4) that gives them is refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..config import Section, transform_from

OBSTACLE_KINDS = ("plane", "box", "cylinder", "sphere")
#: keys of each obstacle kind besides ``kind``, ``name``, ``xyz``, ``rpy``/``quat``
OBSTACLE_KEYS = {"plane": (), "box": ("size",), "cylinder": ("radius", "length"), "sphere": ("radius",)}
PLANNING_KEYS = ("clearance", "distance", "max_incidence", "margin_px", "max_joint_speed", "move_step", "link_radii",
                 "tool_radius")
#: the keys that need a collision model (rig.base.ArmFrames)
COLLISION_KEYS = ("link_radii", "tool_radius")

DEFAULT_CLEARANCE_M = 0.02
DEFAULT_DISTANCE_M = (0.2, 1.5)
#: the view limits default to those of the scene's own pose sampler (``Setup.visible``: the whole board 10 px
#: inside the image, its normal within 60 deg of the viewing ray), so that the planner's candidates cover the
#: region random poses are drawn from; a scene's planning: keys make them stricter
DEFAULT_MAX_INCIDENCE_DEG = 60.0
DEFAULT_MARGIN_PX = 10.0
#: joint speed of the tour's travel times when the scene gives none: a cautious speed for a calibration session
#: (the UR5e's limit is 180 deg/s; 60 deg/s is what a person next to the robot lets it drive)
DEFAULT_JOINT_SPEED_DEG_S = 60.0
DEFAULT_MOVE_STEP_DEG = 2.0


@dataclass(frozen=True)
class Obstacle:
    """A static object of the cell. kind: plane | box | cylinder | sphere; T_base_obj (4, 4) [m] its pose in the
    robot base frame; dims_m: box (x, y, z) edge lengths, cylinder (radius, length), sphere (radius,), plane ()."""

    kind: str
    name: str
    T_base_obj: np.ndarray
    dims_m: tuple[float, ...] = ()

    def to_dict(self) -> dict:
        return {"kind": self.kind, "name": self.name, "xyz_m": [float(v) for v in self.T_base_obj[:3, 3]],
                "R": self.T_base_obj[:3, :3].tolist(), "dims_m": [float(v) for v in self.dims_m]}


@dataclass(frozen=True)
class PlanningSettings:
    """The planner's settings of a scene, SI: clearance_m, distance_m (min, max) camera-target, max_incidence_rad,
    margin_px, max_joint_speed_rad_s, move_step_rad, link_radii_m (n,) or None (the planner's defaults),
    tool_radius_m or None."""

    clearance_m: float = DEFAULT_CLEARANCE_M
    distance_m: tuple[float, float] = DEFAULT_DISTANCE_M
    max_incidence_rad: float = float(np.radians(DEFAULT_MAX_INCIDENCE_DEG))
    margin_px: float = DEFAULT_MARGIN_PX
    max_joint_speed_rad_s: float = float(np.radians(DEFAULT_JOINT_SPEED_DEG_S))
    move_step_rad: float = float(np.radians(DEFAULT_MOVE_STEP_DEG))
    link_radii_m: tuple[float, ...] | None = None
    tool_radius_m: float | None = None
    given: tuple[str, ...] = field(default=(), compare=False)  #: the keys the scene gave

    def to_dict(self) -> dict:
        return {"clearance_m": self.clearance_m, "distance_m": list(self.distance_m),
                "max_incidence_deg": float(np.degrees(self.max_incidence_rad)), "margin_px": self.margin_px,
                "max_joint_speed_deg_s": float(np.degrees(self.max_joint_speed_rad_s)),
                "move_step_deg": float(np.degrees(self.move_step_rad)),
                "link_radii_m": None if self.link_radii_m is None else list(self.link_radii_m),
                "tool_radius_m": self.tool_radius_m}


def read_obstacles(top: Section, Lf: float, Af: float, has_collision_model: bool, kind: str) -> tuple[Obstacle, ...]:
    """The scene's ``obstacles`` list (module docstring); ConfigError naming the file, the entry and the key."""
    if "obstacles" not in top or top.data["obstacles"] is None:
        return ()
    items = top.data["obstacles"]
    if not isinstance(items, list):
        raise top.error("obstacles", f"expected a list of obstacles ({{kind: {'|'.join(OBSTACLE_KINDS)}, ...}}), "
                                     f"got {items!r}")
    if items and not has_collision_model:
        raise top.error("obstacles", f"the {kind} robot kind has no collision model (the planner checks its "
                                     "visibility and reachability only): remove the obstacles")
    out, names = [], set()
    for i, item in enumerate(items):
        sec = Section(item, top.file, f"obstacles[{i}]")
        k = sec.get("kind", str, choices=OBSTACLE_KINDS)
        sec.check_known(("kind", "name", "xyz", "rpy", "quat") + OBSTACLE_KEYS[k])
        name = sec.get("name", str, f"{k}{i}")
        if name in names:
            raise sec.error("name", f"obstacle name {name!r} is used twice")
        names.add(name)
        T = transform_from(Section({n: sec.data[n] for n in ("xyz", "rpy", "quat") if n in sec}, top.file, sec.path),
                           Lf, Af)
        if k == "box":
            size = sec.floats("size", 3)
            if np.any(size <= 0):
                raise sec.error("size", f"expected 3 positive edge lengths, got {sec.data['size']!r}")
            dims = tuple(float(v) * Lf for v in size)
        elif k == "cylinder":
            dims = (sec.positive("radius") * Lf, sec.positive("length") * Lf)
        elif k == "sphere":
            dims = (sec.positive("radius") * Lf,)
        else:
            dims = ()
        out.append(Obstacle(k, name, T, dims))
    return tuple(out)


def read_planning(top: Section, Lf: float, Af: float, n_links: int | None, kind: str) -> PlanningSettings:
    """The scene's ``planning`` section (module docstring) in SI; ``n_links``: the robot's joint count when it has a
    collision model (``link_radii`` then needs n_links values), None otherwise (the collision keys refused)."""
    sec = top.section("planning", default={}).check_known(PLANNING_KEYS)
    if n_links is None:
        for k in COLLISION_KEYS:
            if k in sec:
                raise sec.error(k, f"the {kind} robot kind has no collision model (the planner checks its visibility "
                                   "and reachability only)")
    dist = DEFAULT_DISTANCE_M
    if "distance" in sec:
        d = sec.floats("distance", 2) * Lf
        if not 0 < d[0] < d[1]:
            raise sec.error("distance", f"expected [min, max] with 0 < min < max, got {sec.data['distance']!r}")
        dist = (float(d[0]), float(d[1]))
    radii = None
    if "link_radii" in sec:
        r = sec.floats("link_radii", n_links)
        if np.any(r < 0):
            raise sec.error("link_radii", f"expected {n_links} radii >= 0 (the base up to joint 1, then the link from "
                                          f"each joint to the next, the last to the flange), got {sec.data['link_radii']!r}")
        radii = tuple(float(v) * Lf for v in r)
    inc = sec.number("max_incidence", float, None, min=0.0, min_open=True, max=float(np.radians(90.0)) / Af)
    return PlanningSettings(
        clearance_m=float(sec.nonnegative("clearance", float, DEFAULT_CLEARANCE_M / Lf) * Lf),
        distance_m=dist,
        max_incidence_rad=float(np.radians(DEFAULT_MAX_INCIDENCE_DEG)) if inc is None else float(inc * Af),
        margin_px=float(sec.nonnegative("margin_px", float, DEFAULT_MARGIN_PX)),
        max_joint_speed_rad_s=float(sec.positive("max_joint_speed", float, np.radians(DEFAULT_JOINT_SPEED_DEG_S) / Af)
                                    * Af),
        move_step_rad=float(sec.number("move_step", float, float(np.radians(DEFAULT_MOVE_STEP_DEG)) / Af, min=0.0,
                                       min_open=True, max=float(np.radians(30.0)) / Af) * Af),
        link_radii_m=radii,
        tool_radius_m=None if "tool_radius" not in sec else float(sec.nonnegative("tool_radius") * Lf),
        given=tuple(str(k) for k in sec.keys()),
    )


__all__ = ["Obstacle", "PlanningSettings", "read_obstacles", "read_planning", "OBSTACLE_KINDS", "PLANNING_KEYS"]
