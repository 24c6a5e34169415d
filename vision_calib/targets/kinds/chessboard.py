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

Detection: ``cv2.findChessboardCornersSB`` on the whole board (all inner corners must be visible),
flags :data:`SB_FLAGS` (ACCURACY: the most accurate, and the slowest). Every frame is detected in full
(seeded batch mode included): cornerSubPix from a seed frame measured worse than the ACCURACY corners
(0.032 vs 0.020 px RMS, see :data:`SB_FLAGS`).
"""

from __future__ import annotations

import cv2
import numpy as np

from ...errors import ConfigError
from . import TargetKind
from ._grid import SquareCorners, apply_h, fit_homography, front_facing, sample_mean

#: findChessboardCornersSB flags, chosen by corner error vs the projected truth on polygon-renderer images
#: at the H4 geometry (1024 x 768, f 1013 px, 0.6-0.76 m, tilt <= 35 deg, SensorEffects() defaults,
#: chessboard_a4, 7 poses incl. one rolled 180 deg x 3 frames; RMS px, ms/frame on a shared 2-core machine):
#: 0: 0.032, 380 ms; ACCURACY: 0.020, 1480 ms; EXHAUSTIVE: 0.032; NORMALIZE_IMAGE: 0.102 (worse);
#: NORMALIZE|ACCURACY 0.095; flags 0 + cornerSubPix (win 5): 0.032, (win 3): 0.041.
SB_FLAGS = cv2.CALIB_CB_ACCURACY


class ChessboardKind(SquareCorners, TargetKind):
    name = "chessboard"
    keys = ("square_m", "allow_symmetric")
    required = ("square_m",)
    auto_extra_subpix = False
    info_model = "saddle"
    sb_flags = SB_FLAGS

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
        ok, corners = cv2.findChessboardCornersSB(img, (nc, nr), flags=self.sb_flags)
        if not ok or corners is None:
            return None, f"chessboard of {nc} x {nr} inner corners not found (the whole board must be visible)"
        G = corners.reshape(nr, nc, 2).astype(np.float64)
        G, why = self.orient(spec, img, G)
        if G is None:
            return None, why
        return np.arange(nr * nc), G.reshape(-1, 2)

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
        return None  # per-frame: cornerSubPix from a seed is less accurate than SB ACCURACY (SB_FLAGS)
