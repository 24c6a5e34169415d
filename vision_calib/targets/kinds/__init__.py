"""The target-kind registry: THE one place that knows which calibration target kinds exist.

A target kind is a :class:`TargetKind` subclass (instantiated once) that owns everything that differs
between kinds: its YAML keys and their validation, the pattern geometry (corner ids and 3-D points), the
black shapes the texture and the coverage renderer draw, OpenCV board objects, the detector, the seeded
batch refinement it supports and the image model of its corner error (measure/covariance.py).
:class:`~vision_calib.targets.spec.TargetSpec` and :mod:`vision_calib.measure` call these methods and
never branch on the kind's name.

Adding a kind = writing that class and registering it (for the shipped kinds: the lines at the end).
"""

from __future__ import annotations

import numpy as np

from ...errors import ConfigError

KINDS: dict = {}


class TargetKind:
    """Base class of a target kind. ``spec`` arguments are TargetSpec instances (lengths in m).

    Class attributes:
    - name: the YAML ``kind`` value; keys: kind-specific TargetSpec fields it uses (besides kind, name,
      rows, cols, margin_m); required: those a YAML file must give;
    - auto_refine: DetectConfig.refine "auto" -> this marker refinement (ArUco kinds);
    - auto_extra_subpix: whether DetectConfig.extra_subpix None (auto) runs the cornerSubPix pass;
    - info_model: image model of a corner's Fisher information in measure/covariance.py
      ("saddle" | "tag_edge" | "circle"); bias_model: detector-bias columns there (None | "apriltag");
      phase_model: the pixel-phase-locked share of the systematic corner error there (None | "subpix").
    """

    name = ""
    keys: tuple = ()
    required: tuple = ()
    auto_refine = "none"
    auto_extra_subpix = False
    info_model = "saddle"
    bias_model = None
    phase_model = None

    # ---------------------------------------------------------------- spec
    def validate(self, spec, where: str) -> None:
        """ConfigError naming ``where`` and the key for kind-specific bad values (common keys are checked
        by TargetSpec)."""

    def positive(self, spec, where, *keys) -> None:
        """ConfigError unless every key is > 0."""
        for key in keys:
            if getattr(spec, key) <= 0:
                raise ConfigError(f"{where}: key {key!r} must be > 0 [m], got {getattr(spec, key)}")

    def refuse_symmetric(self, spec, where, what: str, advice: str) -> None:
        """ConfigError when the pattern is 180-degree symmetric (:meth:`symmetric`) and the spec does not set
        ``allow_symmetric``; ``what``: "corner ids" / "ids", ``advice``: the layout to use instead."""
        why = self.symmetric(spec)
        if why and not spec.allow_symmetric:
            raise ConfigError(f"{where}: {why}; its {what} cannot be tied to the physical board, so poses "
                              f"cannot be measured with it. {advice}, or set 'allow_symmetric: true' to use it "
                              "for intrinsics calibration only")

    def symmetric(self, spec) -> str:
        """Why the pattern looks the same after a 180-degree rotation ("" when it does not): the detected
        ids then cannot be tied to the physical board, so poses cannot be measured with it."""
        return ""

    # ---------------------------------------------------------------- geometry
    def pattern_size_m(self, spec) -> tuple[float, float]:
        """(width, height) [m] of the pattern without margin."""
        raise NotImplementedError

    def corner_points(self, spec) -> tuple[np.ndarray, np.ndarray]:
        """ids (K,) int, p_target (K, 3) float64 [m], sorted by id."""
        raise NotImplementedError

    def n_corners(self, spec) -> int:
        return len(self.corner_points(spec)[0])

    def black_rects(self, spec) -> list:
        """Non-overlapping black axis-aligned rectangles (x0, y0, x1, y1) [m, target frame]."""
        return []

    def black_polygons(self, spec) -> np.ndarray:
        """(M, V, 2) further black polygons [m, target frame], vertices in the order TL -> TR -> BR -> BL
        (increasing angle in the target frame), not overlapping each other or the rectangles."""
        return np.zeros((0, 4, 2))

    def cv_board(self, spec):
        raise ConfigError(f"target {spec.name!r}: kind {self.name!r} has no OpenCV board object")

    # ---------------------------------------------------------------- detection
    def make_detector(self, spec, config):
        """The (cached by measure/detect.py) detector object passed to :meth:`find_corners`."""
        return None

    def find_corners(self, spec, det, img, config, diag: dict, intrinsics=None):
        """(ids (K,), uv (K, 2) float64 distorted px) or (None, reason) on a grey uint8 image; may fill diag."""
        raise NotImplementedError

    def seeded_mode(self, config) -> str | None:
        """measure/seeded.py refinement from a seed frame: "subpix" | "tag_edges" | "saddle" | None (per-frame)."""
        return None


def register(kind: TargetKind) -> TargetKind:
    """Register a target kind instance under ``kind.name``."""
    KINDS[kind.name] = kind
    return kind


def unregister(name: str) -> None:
    KINDS.pop(name, None)


def get_kind(name, where: str = "target") -> TargetKind:
    """The TargetKind of a name; ConfigError naming ``where`` and the known kinds."""
    try:
        return KINDS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"{where}: key 'kind' must be one of {tuple(KINDS)}, got {name!r}") from None


def _register_shipped() -> None:
    from .aruco import AprilTagGridKind, CharucoKind
    from .chessboard import ChessboardKind
    from .circles import AsymmetricCirclesKind, ModifiedCircleGridKind

    for cls in (CharucoKind, AprilTagGridKind, ChessboardKind, AsymmetricCirclesKind, ModifiedCircleGridKind):
        register(cls())


_register_shipped()
