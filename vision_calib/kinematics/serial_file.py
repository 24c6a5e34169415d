"""Reading a serial robot file (``scenes/robots/*.yaml``; schema in the comment at the top of
``scenes/robots/rx90.yaml``) into a :class:`~vision_calib.kinematics.serial.SerialChain`."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from .serial import KNOWN_LEFT, KNOWN_RIGHT, SerialChain

_TOP_KEYS = ("name", "description", "source", "notes", "units", "joints", "mounts", "joint_limits",
             "configurations", "trials")
_JOINT_KEYS = ("alpha", "a", "theta", "d", "beta", "l")
_CONF_KEYS = ("q", "description", "thesis_positions", "thesis_measured_positions")
_TRIAL_KEYS = ("description", "configurations", "units", "deviation", "reported")


def _check_keys(sec, allowed):
    sec.check_known(allowed)  # ConfigError naming file and key, closest allowed key suggested


def _array(sec, key, ndim, last, what, default=None):
    """Float array with ``ndim`` dimensions and last dimension ``last`` from a (nested) list;
    ConfigError naming the file and the key otherwise."""
    if default is not None and key not in sec:
        return default
    val = sec.get(key, list)
    try:
        arr = np.asarray(val, dtype=float)
    except (TypeError, ValueError):
        raise sec.error(key, f"expected {what}, got {val!r}") from None
    if arr.ndim != ndim or arr.shape[-1] != last:
        raise sec.error(key, f"expected {what}, got an array of shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise sec.error(key, f"expected {what} (finite numbers)")
    return arr


def _mount_from_section(sec, default_name, known, Lf, Af) -> tuple[str, np.ndarray]:
    """Nominal mount (name, (4, 4) in m) from ``{name, xyz, rpy}`` (R = Rz(yaw) Ry(pitch) Rx(roll)) or
    ``{name, xyz, quat: [qx, qy, qz, qw]}`` (:func:`vision_calib.config.transform_from`)."""
    from ..config import transform_from

    name = sec.get("name", str, default_name)
    if name not in known:
        raise sec.error("name", f"expected one of {', '.join(known)}, got {name!r}")
    return name, transform_from(sec, Lf, Af, extra=("name",))


def load_serial_robot(path: str | os.PathLike) -> SerialChain:
    """Load a robot file (schema in the comment at the top of ``scenes/robots/rx90.yaml``).

    Lengths/angles are in the file's ``units`` ({length: m|cm|mm, angle: rad|deg}, default m/rad)
    and converted to m/rad. The chain's ``meta`` receives ``source``, ``description``, ``notes``,
    ``configurations`` {name: {"q": (k, n) rad, "description", optional "thesis_positions" /
    "thesis_measured_positions" (k, 3) m}} and ``trials`` {name: {"description", "configurations"
    (name or None), "deviation" / "reported" {param name: SI value}}}.
    Errors: :class:`ConfigError` naming the file and the key.
    Longer than 80 lines: a flat, key-by-key validation of the robot file (each error names its key).
    """
    from ..config import Section, load_yaml

    path = Path(path)
    top = Section(load_yaml(path), path)
    _check_keys(top, _TOP_KEYS)
    name = top.get("name", str)
    Lf, Af = top.units(default_length="m", default_angle="rad")
    joints = top.get("joints", list)
    if not joints:
        raise top.error("joints", "expected a non-empty list of joints")
    n = len(joints)
    dh = np.zeros((n, 4))
    pre_z, hayati = {}, []
    for i, j in enumerate(joints, start=1):
        if not isinstance(j, dict):
            raise top.error(f"joints[{i - 1}]", f"expected a mapping with alpha, a, theta, d, got {j!r}")
        js = Section(j, path, f"joints[{i - 1}]")
        _check_keys(js, _JOINT_KEYS)
        dh[i - 1] = [js.get("alpha", float) * Af, js.get("a", float) * Lf,
                     js.get("theta", float, 0.0) * Af, js.get("d", float) * Lf]
        if "beta" in js:
            if js.get("beta", float) != 0.0:
                raise js.error("beta", "the nominal Hayati beta must be 0 (put deviations in trials)")
            if i == 1:
                raise js.error("beta", "joint 1 cannot be a Hayati joint (its predecessor is the base mount)")
            hayati.append(i)
        if "l" in js:
            pre_z[i] = js.get("l", float) * Lf
    mounts = top.section("mounts", default={})
    _check_keys(mounts, ("left", "right"))
    left, TL = _mount_from_section(mounts.section("left", default={}), "T_world_base", KNOWN_LEFT, Lf, Af)
    right, TR = _mount_from_section(mounts.section("right", default={}), "T_flange_tool", KNOWN_RIGHT, Lf, Af)
    limits = None
    if "joint_limits" in top:
        limits = _array(top, "joint_limits", 2, 2, "a list of [min, max] pairs, one per joint") * Af
        if limits.shape != (n, 2):
            raise top.error("joint_limits", f"expected {n} [min, max] pairs (one per joint), got shape {limits.shape}")
        if np.any(limits[:, 0] > limits[:, 1]):
            raise top.error("joint_limits", "expected min <= max for every joint")
    units_sec = top.section("units", default={})
    meta = {k: top.get(k, str, "") for k in ("source", "description", "notes")}
    meta["file"] = str(path)
    meta["units_in_file"] = {"length": units_sec.get("length", str, "m"), "angle": units_sec.get("angle", str, "rad")}
    chain = SerialChain.build(name, dh, hayati=hayati, pre_z=pre_z, left=left, right=right, T_left_base=TL,
                              T_flange_right=TR, joint_limits=limits, meta=meta)
    meta = chain.meta  # filled below (the chain holds its own copy)
    # configurations (joint sets in the file's angle unit)
    confs = {}
    cs = top.section("configurations", default={})
    for cname in list(cs.keys()):
        c = cs.section(cname)
        _check_keys(c, _CONF_KEYS)
        q = _array(c, "q", 2, n, f"a list of joint sets of {n} numbers")
        entry = {"q": q * Af, "description": c.get("description", str, "")}
        for key in ("thesis_positions", "thesis_measured_positions"):
            if key in c:
                pos = _array(c, key, 2, 3, "a list of [x, y, z] positions")
                if pos.shape != (q.shape[0], 3):
                    raise c.error(key, f"expected {q.shape[0]} [x, y, z] rows (one per joint set), got {pos.shape}")
                entry[key] = pos * Lf
        confs[str(cname)] = entry
    meta["configurations"] = confs
    # trials: named deviation vectors (true X) and the thesis' reported estimates, in their own units
    trials = {}
    ts = top.section("trials", default={})
    for tname in list(ts.keys()):
        t = ts.section(tname)
        _check_keys(t, _TRIAL_KEYS)
        tLf, tAf = t.units(default_length=meta["units_in_file"]["length"], default_angle=meta["units_in_file"]["angle"])
        conf = t.get("configurations", str, None)
        if conf is not None and conf not in confs:
            raise t.error("configurations", f"unknown configuration set {conf!r} (known: {', '.join(sorted(confs))})")
        out = {"description": t.get("description", str, ""), "configurations": conf}
        for key in ("deviation", "reported"):
            if key not in t:
                continue
            dv = t.section(key)
            vals = {}
            for pname in list(dv.keys()):
                try:
                    k = chain.params.index(str(pname))
                except ParameterError as exc:
                    raise dv.error(str(pname), str(exc)) from None
                vals[str(pname)] = dv.get(pname, float) * (tLf if chain.params.kinds[k] == "length" else tAf)
            out[key] = vals
        trials[str(tname)] = out
    meta["trials"] = trials
    return chain
