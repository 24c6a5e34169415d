"""Plain chessboard (``chessboard``): rows x cols squares of square_m, square (0, 0) black.

YAML keys: rows, cols (number of SQUARES along y and x), square_m, margin_m, allow_symmetric (optional).
Corners: the (rows - 1) x (cols - 1) inner corners, id = r * (cols - 1) + c at ((c + 1) square_m,
(r + 1) square_m, 0), like ChArUco's.

Orientation: the board looks the same after a 180-degree rotation iff rows + cols is even (the square
diagonally outside the last corner, (rows - 1, cols - 1), has the colour of square (0, 0)). For rows + cols
odd the detector ties the ids to the physical board: a mirrored point order (wrong handedness) is flipped,
then the square outside corner 0 must be darker than the one outside the last corner, else the order is
reversed. For rows + cols even the target is refused (ConfigError) unless ``allow_symmetric: true``; such a
board can then only serve intrinsics calibration (measure_pose refuses it).

Detection: the whole board (all inner corners must be visible) is found by ``cv2.findChessboardCorners``
(flags :data:`CLASSIC_FLAGS`, a few ms), else by ``cv2.findChessboardCornersSB`` (flags :data:`SB_FLAGS`,
~0.1 s: it finds the far and steeply tilted boards FAST_CHECK misses), else by the same on the image upsampled
2x (~0.3 s at 800 x 600: squares of ~6-12 px, tilted and blurred); the corners are then located by
the saddle-point fit of :mod:`.saddle`; corners it rejects are recaptured from farther (defocus: the detector's
corners 1-3 px off) where the image is point-symmetric about them, the others are dropped (a shadow edge
through the corner: no point-symmetric X-corner to locate). In the seeded
batch mode (measure/seeded.py, mode "saddle") every other frame of a pose is refined by the same fit from
the seed frame's corners. Measured figures: :data:`SB_FLAGS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ...errors import ConfigError
from .saddle import recapture, refine_detected
from .base import TargetKind, TargetSpec
from ._grid import SquareCorners, apply_h, fit_homography, front_facing, sample_mean

#: Detectors, measured on polygon-renderer images at the H4 geometry (1024 x 768, f 1013 px, chessboard_a4,
#: SensorEffects() defaults unless said, half the views rolled 180 deg; one thread on a shared 2-core machine).
#: Found / 12 views and ms per view, classic = findChessboardCorners(CLASSIC_FLAGS), SB = ...SB(flags):
#: 0.5-0.8 m tilt <= 35 deg, also with blur 1.5 / 2.5 / 4 px, read noise 8 / 16 / 30 grey or exposure 0.25:
#: classic 12/12, 3-11 ms (60 ms at noise 30); SB 0: 12/12, 100-160 ms; SB ACCURACY: 12/12, ~500 ms.
#: Tilt 60-70 deg: classic 10/12, SB 0 11/12, SB ACCURACY 11/12, classic then SB 0: 12/12 (25 ms).
#: 1.6 m (13 px squares): classic 1/12, SB 0 and ACCURACY 12/12. Classic without FAST_CHECK finds all these
#: but takes 2-3 s on a frame without the board (FAST_CHECK 6-300 ms, SB 0 90 ms).
#: Corner error vs the projected truth (16 views at 0.6-0.76 m x 4 frames; RMS per coordinate, px):
#: bias / scatter: SB ACCURACY 0.018 / 0.006 (read noise 8: 0.019 / 0.017), 490 ms;
#: classic + saddle fit 0.006 / 0.004 (0.010 / 0.017), 4 + 12 ms; the raw corners: classic 0.069, SB 0 0.041.
#: At 1.6 m / 2.2 m / tilt 50-65 deg / blur 2 px: ACCURACY 0.026 / 0.124 / 0.139 / 0.026, saddle fit 0.013 /
#: 0.024 / 0.011 / 0.015 px. Whole detection (benchmarks/bench_detect.py --targets chessboard --poses 8 --seeds 2
#: --frames 5, H4 geometry; ms/frame, corner bias / scatter px, pose systematic t mm / r deg):
#: SB ACCURACY per frame 580 ms, 0.020 / 0.007, 0.058 / 0.009; this kind per frame 21 ms, 0.003 / 0.0045,
#: 0.002 / 0.001; seeded 14 ms, same figures; at read noise 8: 0.020 / 0.018, 0.061 / 0.010 vs 0.006 / 0.017,
#: 0.006 / 0.003.
CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
SB_FLAGS = 0
#: largest move of a detector corner in the saddle-point fit [px] (the raw corners are within ~0.3 px)
MAX_MOVE_PX = 1.0
#: corners the fit rejects are recaptured (:func:`.saddle.recapture`) from up to RECAPTURE_SHARE of the corner
#: spacing, at most RECAPTURE_MAX_PX, where the image is point-symmetric about the result (asymmetry below
#: MAX_ASYM). Measured (benchmarks/bench_target_photos.py, 12-40 px squares): with a defocus of sigma 2 px the
#: detector's corners are up to 1-3 px off and the fit from there lands within 0.04 px of the truth; a shadow
#: edge through a corner's window biases the fit by 1-2 px (asymmetry 0.16-0.6: rejected).
RECAPTURE_SHARE, RECAPTURE_MAX_PX, MAX_ASYM = 0.2, 4.0, 0.15


@dataclass(frozen=True)
class ChessboardSpec(TargetSpec):
    """Chessboard: square_m [m]; allow_symmetric: accept a 180-degree-symmetric board (rows + cols even;
    intrinsics calibration only)."""

    square_m: float = 0.0
    allow_symmetric: bool = False


class ChessboardKind(SquareCorners, TargetKind):
    name = "chessboard"
    spec_class = ChessboardSpec
    required = ("square_m",)
    auto_extra_subpix = False
    detect_uses_intrinsics = False
    sb_flags = SB_FLAGS
    classic_flags = CLASSIC_FLAGS

    def validate(self, spec, where):
        if spec.rows < 2 or spec.cols < 2 or spec.rows * spec.cols < 6:
            raise ConfigError(f"{where}: chessboard keys 'rows' and 'cols' (squares) must be >= 2 with at least "
                              f"2 x 3 squares, got {spec.rows}x{spec.cols}")
        self.positive(spec, where, "square_m")
        self.refuse_symmetric(spec, where, "corner ids", "Use rows + cols odd (e.g. 8 x 11 squares)")

    def symmetric(self, spec):
        if (spec.rows + spec.cols) % 2 == 0:
            return (f"chessboard of {spec.rows} x {spec.cols} squares looks the same after a 180-degree "
                    "rotation (rows + cols even)")
        return ""

    def black_rects(self, spec):
        s = spec.square_m
        return [(c * s, r * s, (c + 1) * s, (r + 1) * s)
                for r in range(spec.rows) for c in range(spec.cols) if (r + c) % 2 == 0]

    def find_corners(self, spec, det, img, config, diag, intrinsics=None):
        nr, nc = spec.rows - 1, spec.cols - 1
        ok, corners = cv2.findChessboardCorners(img, (nc, nr), flags=self.classic_flags)
        diag["chessboard_detector"] = "classic"
        if not ok or corners is None:
            ok, corners = cv2.findChessboardCornersSB(img, (nc, nr), flags=self.sb_flags)
            diag["chessboard_detector"] = "sb"
        if not ok or corners is None:  # small squares, tilted and blurred: SB on the image upsampled 2x (bicubic)
            big = cv2.resize(img, None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC)
            ok, corners = cv2.findChessboardCornersSB(big, (nc, nr), flags=self.sb_flags)
            corners = None if corners is None else (corners + 0.5) / 2 - 0.5
            diag["chessboard_detector"] = "sb upsampled 2x"
        if not ok or corners is None:
            return None, f"chessboard of {nc} x {nr} inner corners not found (the whole board must be visible)"
        G = corners.reshape(nr, nc, 2).astype(np.float64)
        G, why = self.orient(spec, img, G)
        if G is None:
            return None, why
        uv, ok = refine_detected(img, G.reshape(-1, 2), MAX_MOVE_PX)
        if not ok.all():  # a defocused board: the detector's corners can be beyond MAX_MOVE_PX
            step = np.linalg.norm(np.diff(G, axis=1), axis=2).min() if nc > 1 else np.inf
            step = min(step, np.linalg.norm(np.diff(G, axis=0), axis=2).min() if nr > 1 else np.inf)
            move = float(np.clip(RECAPTURE_SHARE * step, MAX_MOVE_PX, RECAPTURE_MAX_PX))
            start, got = recapture(img, G.reshape(-1, 2), ok, move, MAX_ASYM)
            if got.any():
                uv, ok = refine_detected(img, start, MAX_MOVE_PX)
            diag["saddle_recaptured"] = int((got & ok).sum())
        diag["saddle_rejected"] = int((~ok).sum())
        if not ok.any():
            return None, "no chessboard corner passed the saddle-point fit (targets/kinds/saddle.py)"
        return np.flatnonzero(ok), uv[ok]

    def orient(self, spec, img, G):
        """Detected corners G (nr, nc, 2) in OpenCV's order -> the order of the physical ids (module
        docstring), or (None, reason)."""
        nr, nc = G.shape[:2]
        c, r = np.meshgrid(np.arange(nc, dtype=float), np.arange(nr, dtype=float))
        idx = np.column_stack([c.ravel(), r.ravel()])
        H = fit_homography(idx, G.reshape(-1, 2))
        if H is None:
            return None, "degenerate chessboard corner grid"
        if not front_facing(H, [(nc - 1) / 2, (nr - 1) / 2]):
            G = G[:, ::-1]
            H = fit_homography(idx, G.reshape(-1, 2))
        if self.symmetric(spec):
            return G, ""  # any order is a valid labelling of a symmetric board (intrinsics only)
        d = np.array([[-0.2, -0.2], [0.2, -0.2], [0.2, 0.2], [-0.2, 0.2], [0, 0]])
        first = sample_mean(img, apply_h(H, np.array([-0.5, -0.5]) + d))
        last = sample_mean(img, apply_h(H, np.array([nc - 0.5, nr - 0.5]) + d))
        if abs(first - last) < 10.0:
            return None, (f"chessboard orientation unresolved: the squares outside the first and last corners "
                          f"have grey {first:.0f} and {last:.0f}")
        return (G if first < last else G[::-1, ::-1]), ""

    def seeded_mode(self, config):
        return "saddle"
