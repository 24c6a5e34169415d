"""Seeded batch detection (``DetectConfig.batch == "seeded"``): detect once per pose, refine per frame.

The markers/board are detected on the first frame that gives a valid detection (the *seed*); every
other frame's corners are refined from the seed's corners with the per-frame estimator the target kind
names (``TargetKind.seeded_mode``; None -> every frame gets a full detection):
- "subpix" (ChArUco): ``cv2.cornerSubPix`` (window ``subpix_win``, eps 1e-4 px), the same estimator as the
  per-frame path's extra pass, started from the seed frame's refined corners instead of the frame's
  own OpenCV corners (it converges to the same point: poses equal within 1e-4 mm, measured);
- "tag_edges" (AprilTag grid): straight-edge fits of each tag's border (:func:`.tag_edges.refine_quads`); the seed
  frame and every fully detected frame are refined the same way (twice, from OpenCV's unrefined
  marker corners), so all frames of a pose share one estimator;
- "saddle" (chessboard): the saddle-point fit of :mod:`vision_calib.targets.kinds.saddle` (:func:`~vision_calib.targets.kinds.saddle.refine_saddles`, moves up to
  ``max_shift_px``, windows from the seed corners), the estimator the chessboard kind's full detection
  ends with (:func:`~vision_calib.targets.kinds.saddle.refine_detected`), so the seed frame shares it too.
Validity per frame: the frame's 1/8-scale image must correlate with the seed's (NCC >=
``min_view_ncc``), every corner must be refined and none may move more than ``max_shift_px`` from its
seed; else the frame gets a full detection (diagnostics "fallback": why). A full detection replaces the
seed while the seed has not yet been confirmed by a refined frame (so a first frame from another view
costs one extra detection, not N).
Frames drawn on demand (``sensor.pose_frames``, the simulated image chain): once a seed is set, the
later frames are asked for noise only on the pixels the per-frame estimator reads (``Refiner.read_mask``);
the other pixels hold the noise-free mean; such frames are one view by construction (``same_view``), so the
1/8-scale view check is skipped ("view_ncc" None); a frame that falls back to a full detection is drawn in full.
Diagnostics per frame: "batch" ("seeded" | "full"); seeded frames add "seed_frame", "view_ncc",
"max_shift_px" and the seed's "n_markers"/"marker_ids".
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np

from ..camera import CameraIntrinsics
from .detect import DetectConfig, Detection, detect, detect_gray, load_checked, subpix
from ..targets.kinds import saddle
from .tag_edges import read_mask, refine_quads

#: downscale factor of the image used for the same-view check
SMALL = 8


def _small(img: np.ndarray) -> np.ndarray:
    h, w = img.shape
    return cv2.resize(img, (max(1, w // SMALL), max(1, h // SMALL)), interpolation=cv2.INTER_AREA).astype(np.float64)


def _ncc(a: np.ndarray, b: np.ndarray) -> float:
    """Normalised cross-correlation of two equal-shape images (0 when either is flat)."""
    a = a - a.mean()
    b = b - b.mean()
    den = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
    return float(np.sum(a * b) / den) if den > 0 else 0.0


@dataclass
class _Seed:
    frame_index: int
    small: np.ndarray
    ids: np.ndarray
    uv: np.ndarray
    diag: dict
    confirmed: bool = False


class Refiner:
    """Per-frame corner estimator of a target kind started from a seed: refine(img, ids, uv, passes) -> (ids, uv,
    ok (K,) bool, edges) [px] (edges: the tag-edge fit's ``tag_edges.EdgeSamples`` of its last pass, else None);
    ``mode``: the kind's ``seeded_mode`` ("subpix" | "tag_edges" | "saddle"); read_mask: the
    pixels it reads."""

    def __init__(self, target, intrinsics: CameraIntrinsics | None, config: DetectConfig, mode: str):
        self.mode = mode
        self.win = config.subpix_win
        self.intr = intrinsics
        self.cells = target.kind_impl.tag_cells(target) if mode == "tag_edges" else 0
        self.max_move = config.max_shift_px
        self.refine = {"subpix": self._subpix, "tag_edges": self._tag_edges, "saddle": self._saddle}[mode]

    def _subpix(self, img, ids, uv, passes=1):
        out = subpix(img, uv, self.win)
        return ids, out, np.all(np.isfinite(out), axis=1), None

    def _saddle(self, img, ids, uv, passes=1):
        out, ok = saddle.refine_saddles(img, uv, self.max_move)
        return ids, out, ok, None

    def _tag_edges(self, img, ids, uv, passes=1):
        q = uv.reshape(-1, 4, 2)
        ok = np.ones(len(q), dtype=bool)
        for _ in range(passes):
            q, ok_p, edges = refine_quads(img, q, self.cells, self.intr, samples=True)
            ok &= ok_p
        return ids, q.reshape(-1, 2), np.repeat(ok, 4), edges

    def read_mask(self, uv, shape, max_shift_px: float) -> np.ndarray:
        """(H, W) bool: every pixel :meth:`refine` reads when started from the seed corners uv (N, 2).
        ``cv2.cornerSubPix`` samples a (2 win + 3)^2 patch bilinearly around its current estimate, which stays
        within ``max_shift_px`` of the seed in an accepted frame (+2 px for the iterations in between); the
        edge fits read fixed profiles across the seed quads' sides (:func:`.tag_edges.read_mask`); the saddle
        fit reads discs of radius 3 sigma + max_shift_px around the seeds (:func:`.saddle.read_mask`)."""
        if self.mode == "tag_edges":
            return read_mask(uv, self.cells, shape)
        if self.mode == "saddle":
            if max_shift_px != self.max_move:
                raise ValueError(f"read_mask: max_shift_px {max_shift_px} differs from the refiner's {self.max_move}")
            return saddle.read_mask(uv, shape, self.max_move)
        mask = np.zeros(shape, dtype=bool)
        r = self.win + 2 + int(np.ceil(max_shift_px)) + 2
        h, w = shape
        for x, y in np.round(np.asarray(uv, dtype=np.float64).reshape(-1, 2)).astype(int):
            mask[max(0, y - r):max(0, y + r + 1), max(0, x - r):max(0, x + r + 1)] = True
        return mask

    def full_post(self, img, ids, uv):
        """Refinement of a fully detected frame (AprilTag grids: markers that cannot be refined are dropped):
        (ids, uv, the kept markers' EdgeSamples or None)."""
        ids, uv, ok, edges = self.refine(img, ids, uv, passes=2)
        return ids[ok], uv[ok], None if edges is None else edges.take(ok[::4])


def _from_seed(img, size, source, i, seed: _Seed, ref: Refiner, config: DetectConfig, t0):
    """A Detection refined from the seed, or (None, why the frame needs a full detection). A seed without its
    small image (frames of one view by construction, ``same_view``) skips the view check."""
    ncc = None if seed.small is None else _ncc(_small(img), seed.small)
    if ncc is not None and not ncc >= config.min_view_ncc:
        return None, (f"view differs from seed frame {seed.frame_index} "
                      f"(1/{SMALL}-scale NCC {ncc:.3f} < {config.min_view_ncc})")
    try:
        ids, uv, ok, edges = ref.refine(img, seed.ids, seed.uv)
    except cv2.error as exc:
        return None, f"seeded refinement failed: {exc}".splitlines()[0]
    if not ok.all():
        return None, f"{int((~ok).sum())} corner(s) could not be refined from seed frame {seed.frame_index}"
    shift = float(np.max(np.linalg.norm(uv - seed.uv, axis=1))) if len(uv) else 0.0
    if not shift <= config.max_shift_px:
        return None, (f"a corner moved {shift:.2f} px > max_shift_px {config.max_shift_px} from seed frame "
                      f"{seed.frame_index}")
    diag = {"source": source, "batch": "seeded", "seed_frame": seed.frame_index, "view_ncc": ncc,
            "max_shift_px": shift, "n_markers": seed.diag.get("n_markers"),
            "marker_ids": list(seed.diag.get("marker_ids", [])), "n_corners": int(len(ids)),
            "time_s": time.perf_counter() - t0}
    return Detection(True, "", ids.copy(), uv, size, i, diag, edges), ""


def detect_seeded(images, target, intrinsics: CameraIntrinsics | None, config: DetectConfig) -> list[Detection]:
    """N Detections of one pose's frames (see the module docstring); never raises on a bad frame."""
    mode = target.kind_impl.seeded_mode(config)
    if mode is None:  # no per-frame estimator to seed: per-frame path
        return [detect(im, target, intrinsics, i, config) for i, im in enumerate(images)]
    ref = Refiner(target, intrinsics, config, mode)
    full_cfg = config.seed_config()
    post = ref.full_post if mode == "tag_edges" else None
    focus = getattr(images, "focus", None)  # frames drawn on demand (sensor.pose_frames): noise where we read
    same_view = bool(getattr(images, "same_view", False))  # ... of one simulated view: no view check needed
    seed, out = None, []
    for i, im in enumerate(images):
        t0 = time.perf_counter()
        img, size, source, bad = load_checked(im, intrinsics, i)
        if bad is not None:
            out.append(bad)
            continue
        why = ""
        if seed is not None:
            d, why = _from_seed(img, size, source, i, seed, ref, config, t0)
            if d is not None:
                seed.confirmed = True
                out.append(d)
                continue
            if focus is not None:  # a full detection reads the whole frame: draw all of it
                img = images.frame(i, full=True)
        d = detect_gray(img, size, source, target, i, full_cfg, t0, post=post, intrinsics=intrinsics)
        d.diagnostics["batch"] = "full"
        if why:
            d.diagnostics["fallback"] = why
        if d.valid and (seed is None or not seed.confirmed):
            seed = _Seed(i, None if same_view else _small(img), d.ids, d.uv_px, d.diagnostics)
            if focus is not None:
                focus(ref.read_mask(seed.uv, img.shape, config.max_shift_px))
        out.append(d)
    return out
