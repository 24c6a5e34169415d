"""Gross input errors in the hand-eye route (flange poses known), as :mod:`.gross` does for the robot chain:
failures, not warnings (issue 28 item 3).

The hand-eye fit estimates the robot's pose error from the data by default; a gross input error then does not
show as a huge chi2/dof: the estimated robot error swallows it (a board twice its size: residuals 15-211 mm read
as a robot error, "ok"). So the diagnosis reads the data themselves, with the closed form of each alternative
reading of the input and its translation misfit ``RMS |t(A G_k B) - t(M_k)|`` (no weights, no robot error):

- **the board's scale** (target square / marker size, a ``--square-m`` or a unit): PnP translations scale with
  the board, rotations do not. The misfit of the measured translations scaled by s, divided by s, is profiled
  over s in [0.05, 20] (log grid, then refined): a best s outside [1 / (1 + :data:`SCALE_TOL`), 1 + SCALE_TOL]
  that cuts the misfit by :data:`FIT_GAIN` is a failure naming the factor;
- **other readings** the caller can build from its raw input (e.g. flange quaternions scalar-first, the other
  camera mount): each refitted the same way; one whose misfit is :data:`FIT_GAIN` times lower, and below the
  misfit the estimated robot error explains, is a failure naming it;
- **a fit far beyond its noise** (``gross.GROSS_CHI2_DOF``) is a failure by itself (robot error given or exact),
  and so is an estimated robot pose error above :data:`IMPLAUSIBLE_MM` / :data:`IMPLAUSIBLE_DEG` per axis.

:func:`alternative_readings` builds the readings both routes test (``process`` of a flange-pose recording,
``process-poses`` of pose pairs): scalar-first quaternions, rotation vectors in degrees, the other mount, the
images paired one row off.

Only run when something is suspicious: chi2/dof above ``GROSS_CHI2_DOF``, or an estimated robot pose error above
:data:`SUSPECT_MM` / :data:`SUSPECT_DEG` per axis (industrial arms: tenths of a mm; a few mm when uncalibrated).
"""

from __future__ import annotations

import numpy as np

from ..errors import DataError, VisionCalibError
from ..identify.handeye_problem import handeye_initial_guess, mount_G
from .gross import GROSS_CHI2_DOF

#: the board's scale is wrong when the best s is further than this (relative) from 1
SCALE_TOL = 0.05
#: an alternative reading fits when its translation misfit is this many times lower
FIT_GAIN = 5.0
#: an estimated robot pose error above these (per axis) makes the diagnosis run
SUSPECT_MM, SUSPECT_DEG = 2.0, 0.5
#: ... and above these it is a failure by itself: no arm reports its flange that far off (uncalibrated arms: a few
#: mm, a few tenths of a degree); the data do not pair the images with their flange poses as the model reads them
IMPLAUSIBLE_MM, IMPLAUSIBLE_DEG = 50.0, 10.0


def translation_misfit(F: np.ndarray, M: np.ndarray, mount: str) -> float:
    """RMS [m] over the poses of |t(A G_k B) - t(M_k)| at the closed form (A, B) of (F, M) (numpy Shah); inf when
    the closed form fails (degenerate motions)."""
    try:
        with np.errstate(all="ignore"):
            A, B = handeye_initial_guess(F, M, mount)
            P = A @ mount_G(F, mount) @ B
    except (VisionCalibError, np.linalg.LinAlgError, ValueError):
        return float("inf")
    d = np.linalg.norm(P[:, :3, 3] - M[:, :3, 3], axis=1)
    v = float(np.sqrt(np.mean(d**2)))
    return v if np.isfinite(v) else float("inf")


def board_scale(F: np.ndarray, M: np.ndarray, mount: str) -> tuple[float, float, float]:
    """(best s, misfit at s = 1 [m], misfit at the best s, in the board's true unit [m]): the measured
    translations scaled by s (module docstring)."""
    def cost(s):
        Ms = M.copy()
        Ms[:, :3, 3] *= s
        return translation_misfit(F, Ms, mount) / s

    grid = np.exp(np.linspace(np.log(0.05), np.log(20.0), 61))
    vals = np.array([cost(s) for s in grid])
    i = int(np.argmin(vals))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    for _ in range(40):  # golden-section refinement in log s
        a, b = np.exp(np.log(lo) + 0.382 * np.log(hi / lo)), np.exp(np.log(lo) + 0.618 * np.log(hi / lo))
        if cost(a) < cost(b):
            hi = b
        else:
            lo = a
    s = float(np.sqrt(lo * hi))
    return s, float(cost(1.0)), float(cost(s))


def handeye_gross_failure(F, M, mount: str, ident, where: str, alternatives: dict | None = None) -> dict | None:
    """None, or the report's ``failure`` {kind, tests, message} (module docstring). F, M (N, 4, 4) [m] as fitted;
    ``ident``: the ``handeye_step.HandeyeIdentified``; alternatives: {what: (F, M, mount)} other readings of the
    raw input."""
    F, M = np.asarray(F, float), np.asarray(M, float)
    chi2 = float(ident.result.chi2_dof)
    robot = ident.fit.robot
    est = robot.get("source") == "estimated"
    t_mm, r_deg = (robot.get("translation_mm") or 0.0, robot.get("rotation_deg") or 0.0) if est else (0.0, 0.0)
    noise = ident.fit.noise or {}  # pose pairs: the measured poses' estimated per-axis noise swallows as much
    n_mm, n_deg = max(noise.get("translation_mm") or [0.0]), max(noise.get("rotation_deg") or [0.0])
    suspect = ((np.isfinite(chi2) and chi2 > GROSS_CHI2_DOF) or max(t_mm, n_mm) > SUSPECT_MM
               or max(r_deg, n_deg) > SUSPECT_DEG)
    if not suspect:
        return None
    base = translation_misfit(F, M, mount)
    tests = []
    s, c1, cs = board_scale(F, M, mount)
    scale_wrong = bool(abs(np.log(s)) > np.log1p(SCALE_TOL) and cs * FIT_GAIN < c1)
    tests.append({"candidate": f"the board's size off by {1 / s:.3g} x (the measured motions {1 / s:.3g} x the "
                               "robot's)", "misfit_mm": cs * 1e3, "fits": scale_wrong, "scale": 1 / s})
    for what, (Fa, Ma, ma) in (alternatives or {}).items():
        try:
            c = translation_misfit(np.asarray(Fa, float), np.asarray(Ma, float), ma)
        except DataError:
            c = float("inf")
        tests.append({"candidate": what, "misfit_mm": c * 1e3 if np.isfinite(c) else None,
                      "fits": bool(np.isfinite(c) and c * FIT_GAIN < base)})
    hits = [t for t in tests if t["fits"]]
    gross = np.isfinite(chi2) and chi2 > GROSS_CHI2_DOF
    absurd = t_mm > IMPLAUSIBLE_MM or r_deg > IMPLAUSIBLE_DEG
    if not hits and not gross and not absurd:
        return None
    shown = "; ".join(f"{t['candidate']}: misfit {t['misfit_mm']:.3g} mm" + (" -- this fits" if t["fits"] else "")
                      if t["misfit_mm"] is not None else f"{t['candidate']}: no closed form" for t in tests)
    rob = (f", read by the fit as a robot pose error of {t_mm:.3g} mm / {r_deg:.3g} deg per axis" if est else "")
    if hits:
        head = (f"{where}: {hits[0]['candidate']}: that reading of the input fits (translation misfit "
                f"{hits[0]['misfit_mm']:.3g} mm against {base * 1e3:.3g} mm as read{rob}): a gross error in the input, "
                "not a calibration")
    elif gross:
        head = (f"{where}: the hand-eye fit is far beyond the noise model: chi2/dof {chi2:.3g} (above "
                f"{GROSS_CHI2_DOF:g}): a gross error in the input, not a calibration")
    else:
        head = (f"{where}: the fit reads the data as a robot pose error of {t_mm:.3g} mm / "
                f"{r_deg:.3g} deg per axis (above {IMPLAUSIBLE_MM:g} mm / {IMPLAUSIBLE_DEG:g} deg: no "
                "arm reports its flange that far off): the images and the flange poses do not belong together as "
                "read (pairing, units, frames), not a calibration")
    return {"kind": "gross input error (hand-eye)", "chi2_dof": chi2 if np.isfinite(chi2) else None,
            "translation_misfit_mm": base * 1e3, "tests": tests,
            "message": f"{head}. Readings tested with their closed form: {shown}" + ("" if hits else " (none fits)")}


def rotation_vectors_in_degrees(F: np.ndarray) -> np.ndarray:
    """The flange poses F (N, 4, 4) re-read as if their rotation vectors (theta-u, as ViSP and many pose files
    write them) had been written in degrees and read as radians: each rotation vector scaled by pi / 180."""
    from scipy.spatial.transform import Rotation

    out = F.copy()
    out[:, :3, :3] = Rotation.from_rotvec(np.radians(Rotation.from_matrix(F[:, :3, :3]).as_rotvec())).as_matrix()
    return out


def alternative_readings(F: np.ndarray, M: np.ndarray, mount: str, mount_source: str, measured: str = "images") -> dict:
    """{what: (F, M, mount)}: the other readings of a hand-eye input that users' damage produces
    (:func:`handeye_gross_failure`'s ``alternatives``): flange quaternions scalar-first, rotation vectors in
    degrees, the other camera mount (``mount_source``: where the mount was declared, named in the text), and the
    images (``measured``: what the camera side is called) paired one row off with the flange poses (each with the
    next / the previous row's pose)."""
    other = "fixed" if mount == "eye_in_hand" else "eye_in_hand"
    out = {"the flange quaternions read scalar-first (w, x, y, z written under qx, qy, qz, qw)":
           (quaternion_scalar_first(F), M, mount),
           "the flange rotation vectors read as degrees (theta-u written in degrees)":
           (rotation_vectors_in_degrees(F), M, mount),
           f"the camera mount {other} (read as {mount} from {mount_source})": (F, M, other)}
    if len(F) >= 4:
        for side, Fa, Ma in (("NEXT", F[1:], M[:-1]), ("PREVIOUS", F[:-1], M[1:])):
            out[f"the {measured} paired one row off (each with the {side} row's flange pose)"] = (Fa, Ma, mount)
    return out


def quaternion_scalar_first(F: np.ndarray) -> np.ndarray:
    """The flange poses F (N, 4, 4) re-read as if the file's qx,qy,qz,qw columns held w,x,y,z (scalar first)."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(F[:, :3, :3]).as_quat()  # columns as read: (a, b, c, d) = (x, y, z, w)
    out = F.copy()
    out[:, :3, :3] = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()  # truth (w, x, y, z) = (a, b, c, d)
    return out


__all__ = ["handeye_gross_failure", "board_scale", "translation_misfit", "quaternion_scalar_first",
           "rotation_vectors_in_degrees", "alternative_readings", "SCALE_TOL", "IMPLAUSIBLE_MM", "IMPLAUSIBLE_DEG"]
