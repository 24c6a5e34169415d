"""H4 model conversion (model 12 -> 31) and the seed's table-2 variants A-H (free masks).
Functions of an :class:`~.h4.H4Robot` (split from :mod:`.h4`, which they import, never the reverse)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import ParameterError
from .h4 import EPS_D, EPS_H, EXTERNAL_NAMES, TILT_NAMES, H4Robot, param_kind, model31_names
from .params import ParameterSet


def to_model31(robot: H4Robot, x=None) -> H4Robot:
    """Exact model-31 description of a model-12 robot (at x, default nominal); d = d12.
    Free mask: variant H (d and B_T_C.theta fixed as well as M_T_E.z)."""
    if robot.model == "31":
        return robot
    if robot.tilt_params:
        v = robot.params.values(robot._x(x))
        out = to_model31(without_tilt_params(robot, fold=False), robot._x(x)[: -len(TILT_NAMES)])
        return with_tilt_params(out, [v[n] for n in TILT_NAMES], free=[robot.params.free[robot.params.index(n)]
                                                                         for n in TILT_NAMES])
    v = robot.params.values(robot._x(x))
    names = model31_names(False)
    val = {}
    for i in range(4):
        j = i + 1
        al = v[f"h4.alpha{j}"]
        P = [EPS_H[i] * v["h4.h"] + v["h4.R"] * np.cos(al), EPS_D[i] * robot.d12 + v["h4.R"] * np.sin(al), 0.0]
        if j > 1:
            val.update({f"h4.x{j}": P[0], f"h4.y{j}": P[1], f"h4.z{j}": P[2]})
        else:
            P1 = np.array(P)
        val.update({f"h4.psi{j}": al, f"h4.beta{j}": -np.pi / 2, f"h4.L{j}": v["h4.L"], f"h4.l{j}": v["h4.l"],
                    f"q0_{j}": v[f"q0_{j}"]})  # fmt: skip
    val.update({"h4.h": v["h4.h"], "h4.d": robot.d12})
    geo = [val[nm] for nm in names]
    ext = [v[nm] for nm in EXTERNAL_NAMES]
    all_names = names + EXTERNAL_NAMES
    sc_len, sc_ang = robot.params.scale[robot.params.index("h4.L")], robot.params.scale[robot.params.index("h4.alpha1")]
    ext_scale = dict(zip(robot.params.names, robot.params.scale))
    sc = [ext_scale.get(nm, sc_ang if param_kind(nm) == "angle" else sc_len) for nm in all_names]
    ps = ParameterSet.from_lists(all_names, geo + ext, [param_kind(n) for n in all_names], scale=sc)
    r = replace(robot, model="31", params=ps, P1=P1, shared_L=False)
    return variant(r, "H")

def variant(robot: H4Robot, letter: str) -> H4Robot:
    """Seed table 2 variant: same values, free mask (and arm-length sharing for E) set.
    A-D (model 12; M_T_E.z fixed): A fixes h and l, B fixes h, C fixes l, D fixes none
    (17, 18, 18, 19 free). E-H (model 31; M_T_E.z, d and B_T_C.theta fixed -- the two
    couplings of the base-frame form, see module doc): H none (36 free), G fixes l1..4 (32),
    F fixes h and l1..4 (31), E also shares one arm length h4.L (28). A model-12 robot
    asked for E-H is converted with :func:`to_model31` first."""
    letter = str(letter).upper()
    if robot.tilt_params:  # the variant's mask on the rest; the tilts keep theirs
        free = [robot.params.free[robot.params.index(n)] for n in TILT_NAMES]
        tv = [robot.params.values()[n] for n in TILT_NAMES]
        return with_tilt_params(variant(without_tilt_params(robot, fold=False), letter), tv, free)
    if letter in "ABCD" and len(letter) == 1:
        if robot.model != "12":
            raise ParameterError(f"H4 variant {letter} is built on model 12, this robot is model {robot.model}")
        fixed = {"A": ["h4.h", "h4.l"], "B": ["h4.h"], "C": ["h4.l"], "D": []}[letter] + ["M_T_E.z"]
        return replace(robot, params=robot.params.with_free(robot.names, True).fix(fixed))
    if letter in "EFGH" and len(letter) == 1:
        if robot.model == "12":
            return variant(to_model31(robot), letter)
        r = robot
        if letter == "E" and not robot.shared_L:
            r = _share_L(r)
        elif letter != "E" and robot.shared_L:
            raise ParameterError(f"H4 variant {letter} needs per-arm lengths; this robot shares h4.L")
        ls = [f"h4.l{i}" for i in range(1, 5)]
        fixed = {"E": ["h4.h"] + ls, "F": ["h4.h"] + ls, "G": ls, "H": []}[letter]
        fixed += ["M_T_E.z", "h4.d", "B_T_C.theta"]
        return replace(r, params=r.params.with_free(r.names, True).fix(fixed))
    raise ParameterError(f"unknown H4 variant {letter!r} (expected one of A-H)")

def _share_L(robot: H4Robot) -> H4Robot:
    p = robot.params
    Ls = [p.index(f"h4.L{i}") for i in range(1, 5)]
    keep = [i for i in range(len(p)) if i not in Ls[1:]]
    names = list(p.names[i] for i in keep)
    nominal = p.nominal[keep].copy()
    nominal[names.index("h4.L1")] = p.nominal[Ls].mean()
    names[names.index("h4.L1")] = "h4.L"
    ps = ParameterSet(tuple(names), nominal, tuple(p.kinds[i] for i in keep), p.free[keep], p.scale[keep])
    return replace(robot, params=ps, shared_L=True)



def with_tilt_params(robot: H4Robot, values=(0.0, 0.0, 0.0, 0.0), free=(False, False, False, False)) -> H4Robot:
    """Copy of robot with the four tilt parameters TILT_NAMES (camera tilt about camera x/y, target tilt
    about target x/y, rad; see :mod:`.h4`) appended: nominal ``values`` (4,), free mask ``free`` (4,);
    scale that of the robot's angles. R_BC0 / R_ME0 unchanged (the tilts are relative to them).
    A robot that has them already gets the new values / mask."""
    if robot.tilt_params:
        robot = without_tilt_params(robot, fold=False)
    p = robot.params
    ang = [s for s, k in zip(p.scale, p.kinds) if k == "angle"]
    sc = ang[0] if ang else 1e-3
    ps = ParameterSet(tuple(p.names) + TILT_NAMES, np.concatenate([p.nominal, np.asarray(values, float)]),
                      tuple(p.kinds) + ("angle",) * 4, np.concatenate([p.free, np.asarray(free, bool)]),
                      np.concatenate([p.scale, np.full(4, sc)]))
    return replace(robot, params=ps, tilt_params=True)


def without_tilt_params(robot: H4Robot, x=None, fold: bool = True) -> H4Robot:
    """Copy of robot without the tilt parameters; with ``fold`` their values (at x (n,), default nominal)
    go into the fixed tilts: R_BC0 <- R_BC0 so3_exp(w), R_ME0 <- Rz(-th) so3_exp(u) Rz(th) R_ME0 (th =
    M_T_E.theta), so that the robot's camera and target frames are unchanged."""
    from ..frames import rot_z, so3_exp

    if not robot.tilt_params:
        return robot
    p, n = robot.params, len(robot.params) - len(TILT_NAMES)
    x = p.nominal if x is None else np.asarray(x, float)
    ps = ParameterSet(tuple(p.names[:n]), x[:n].copy(), tuple(p.kinds[:n]), p.free[:n].copy(), p.scale[:n].copy())
    out = replace(robot, params=ps, tilt_params=False)
    if fold:
        v = p.values(x)
        w, u = robot._tilts(v)
        th = v["M_T_E.theta"]
        out = replace(out, R_BC0=robot.R_BC0 @ so3_exp(w), R_ME0=rot_z(-th) @ so3_exp(u) @ rot_z(th) @ robot.R_ME0)
    return out
