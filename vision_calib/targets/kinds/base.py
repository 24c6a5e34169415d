"""The base class of a target kind (:class:`TargetKind`) and the memory guard its drawings use; the registry
of kinds is :mod:`vision_calib.targets.kinds`."""

from __future__ import annotations

import os

import numpy as np

from ...errors import ConfigError


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


def available_memory() -> int | None:
    """Bytes of memory available now (Linux MemAvailable), None where unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(nbytes: int, what: str, fraction: float = 0.5) -> None:
    """ConfigError before an allocation of ``nbytes`` larger than ``fraction`` of the available memory."""
    avail = available_memory()
    if avail is not None and nbytes > fraction * avail:
        raise ConfigError(f"{what} needs about {nbytes / 2**30:.3g} GiB of memory, more than {fraction:.0%} of the "
                          f"{avail / 2**30:.3g} GiB available; use a lower resolution (dpi)")
