"""What the identification and the rig ask of a joint-commanded chain, as explicit interfaces (``isinstance``
checks, no attribute probing): :class:`ChainModel` (serial MDH ``SerialChain``, URDF ``URDFChain``) and the
optional capabilities :class:`Remountable` and :class:`PrismaticJoints`. numpy only."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from .params import ParameterSet


@runtime_checkable
class ChainModel(Protocol):
    """A serial chain with mounts: name, ``params`` (ParameterSet: arm + mount parameters, SI units),
    ``forward(q, x) -> (N, 4, 4)`` the measured transform (left mount . arm . right mount) for joints q (N, n)
    rad, ``pose_jacobian(q, x) -> (N, 6, p)`` its parameter Jacobian in the ``frames.pose_error`` convention
    (``pose_and_jacobian(q, x)``: both from one walk),
    ``check_joints(q) -> (N, n)`` (DataError naming the bad value), ``redundant_pairs()`` the exactly redundant
    parameter pairs (name, name, why). ``n_joints``: n; ``joint_limits``: (n, 2) [min, max] (rad, or m for a
    prismatic joint) or None (no limits)."""

    name: str
    params: ParameterSet
    n_joints: int
    joint_limits: np.ndarray | None

    def forward(self, q, x=None) -> np.ndarray: ...

    def pose_jacobian(self, q, x=None) -> np.ndarray: ...

    def pose_and_jacobian(self, q, x=None) -> tuple[np.ndarray, np.ndarray]: ...

    def check_joints(self, q) -> np.ndarray: ...

    def redundant_pairs(self) -> list[tuple[str, str, str]]: ...


@runtime_checkable
class WalkFrames(Protocol):
    """Optional capability of a chain: ``walk_frames(q, x) -> (k, N, 4, 4)`` the frames of one walk (the last one
    is ``forward(q, x)``), which ``pose_and_jacobian(q, x, frames=...)`` takes instead of walking again
    (``SerialChain``): a solver that evaluated the residual at x gets the Jacobian there without a second walk."""

    def walk_frames(self, q, x=None) -> np.ndarray: ...


@runtime_checkable
class Remountable(Protocol):
    """Optional capability of a chain: the same arm with other mounting transforms (``URDFChain``); a chain
    without it is rebuilt from its MDH table (``rig.serial.remount_chain``)."""

    def remounted(self, left: str, right: str, T_left_base=None, T_flange_right=None): ...


@runtime_checkable
class PrismaticJoints(Protocol):
    """Optional capability of a chain: some joints translate (``URDFChain``). ``prismatic``: (n,) bool, True for
    a joint whose value is a length (m); a chain without it has revolute joints only (rad)."""

    prismatic: np.ndarray


@runtime_checkable
class JointOffsetForm(Protocol):
    """Optional capability of a robot model: the joint zero offsets a controller can take. ``joint_offset_form(x)
    -> (x_equiv (n_params,), offsets (n_joints,))``: x_equiv gives the same kinematics as x (every prediction
    equal to rounding) with all of a joint's motion about (revolute, rad) or along (prismatic, m) its own axis
    at its origin carried by its joint-offset parameter; offsets: that parameter's value per joint (SerialChain:
    theta_i; URDFChain: q0_i; H4Robot: q0_i), the model's joint value being reading + offset."""

    def joint_offset_form(self, x=None) -> tuple[np.ndarray, np.ndarray]: ...
