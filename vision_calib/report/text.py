"""Summary-text pieces shared by ``summary.txt`` (:mod:`.build`) and ``report.html`` (:mod:`.html`):
display units of parameter kinds, the one formatter of standard deviations (:func:`fmt_sig`), the one table of
what each figure key means (:data:`FIGURE_LABELS`, :func:`figure_label`), and the one-line summaries of the
lack-of-fit and method-check blocks.

Units a person reads: lengths in mm, angles in deg (SI keys such as ``V3_m`` or ``V1_rad`` are converted on
display), image figures in px."""

from __future__ import annotations

import math
import re

import numpy as np

#: rad -> deg
DEG = float(np.degrees(1.0))

#: display unit of a parameter kind in the summary's table: (unit, factor from SI)
KIND_UNITS = {"length": ("mm", 1e3, "12.4f"), "angle": ("deg", DEG, "12.5f")}

#: significant digits of every standard deviation shown (summary.txt, report.html)
STD_DIGITS = 2


def fmt_sig(x, digits: int = STD_DIGITS, missing: str = "n/a") -> str:
    """``x`` rounded to ``digits`` significant digits (0.0036123 -> '0.0036', 1.03 -> '1.0', 0.00996 -> '0.010'),
    fixed-point for 1e-4 <= |x| < 1e6, else in exponent form ('3.6e-07'); ``missing`` for None / NaN /
    non-numbers. The one formatter of standard deviations in summary.txt and report.html."""
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)) or not math.isfinite(x):
        return missing
    x = float(x)
    if x == 0:
        return "0"
    r = float(f"{x:.{digits - 1}e}")  # rounded to the significant digits first (0.00996 -> 0.010)
    e = math.floor(math.log10(abs(r)))
    if e < -4 or e >= 6:
        return f"{r:.{digits - 1}e}"
    return f"{r:.{max(0, digits - 1 - e)}f}"


def decimals_of(std, default: int, most: int = 6) -> int:
    """Decimal places :func:`fmt_sig` gives ``std`` (fixed-point), to print a value to the same place as its
    standard deviation; ``default`` without a usable std; at most ``most``."""
    s = fmt_sig(std)
    if s in ("n/a", "0") or "e" in s:
        return default
    return min(most, len(s.split(".")[1]) if "." in s else 0)


#: what each figure key of report.json that the reports show means: key -> (label, display unit, factor from the
#: key's own unit to the display unit). The keys carry their unit in their name (``V3_m``: metres); the display
#: unit is mm for lengths, deg for angles. The one table of html (validation tables, column heads) and text.
FIGURE_LABELS = {
    # validation accuracy (rig.base.Evaluation.to_dict; the model vs the truth on held-out poses), the held-out
    # k-fold residuals (experiment.holdout.holdout_validation) and the residual RMS per axis after the
    # fit (report.build.residual_stats): the table or line names which
    "position_mean_mm": ("position mean", "mm", 1.0),
    "position_rms_mm": ("position RMS", "mm", 1.0),
    "position_max_mm": ("position max", "mm", 1.0),
    "position_rms_registered_mm": ("position RMS after a rigid registration", "mm", 1.0),
    "position_p95_mm": ("position 95th percentile", "mm", 1.0),
    "rotation_p95_deg": ("rotation 95th percentile", "deg", 1.0),
    "position_median_mm": ("position std, median", "mm", 1.0),
    "rotation_mean_deg": ("rotation mean", "deg", 1.0),
    "rotation_rms_deg": ("rotation RMS", "deg", 1.0),
    "rotation_max_deg": ("rotation max", "deg", 1.0),
    "joint_mean_deg": ("joint mean", "deg", 1.0),
    "joint_rms_deg": ("joint RMS", "deg", 1.0),
    "joint_max_deg": ("joint max", "deg", 1.0),
    "translation_rms_mm": ("translation RMS", "mm", 1.0),
    "n_poses": ("poses", "", 1.0),
    # H4 criteria of the paper (rig.h4.H4Setup.evaluate; DESIGN.md section 4)
    "V1_rad": ("V1: mean joint residual", "deg", DEG),
    "V2_rad": ("V2: RMS joint residual", "deg", DEG),
    "V3_m": ("V3: straight-line deviation", "mm", 1e3),
    # per-pose final residuals (report.json pose_residuals) and their measurements
    "chi2": ("chi2", "", 1.0),
    "p_value": ("p-value", "", 1.0),
    "translation_mm": ("translation", "mm", 1.0),
    "rotation_deg": ("rotation", "deg", 1.0),
    "joint_deg": ("joint", "deg", 1.0),
    "reprojection_rms_px": ("reprojection RMS", "px", 1.0),
    "n_corners": ("corners", "", 1.0),
}

#: unit suffix of a key -> (display unit, factor): the fallback of keys without a label
_SUFFIX_UNITS = {"mm": ("mm", 1.0), "m": ("mm", 1e3), "um": ("mm", 1e-3), "deg": ("deg", 1.0), "rad": ("deg", DEG),
                 "mrad": ("deg", DEG * 1e-3), "px": ("px", 1.0), "s": ("s", 1.0)}


def figure_label(key: str) -> tuple[str, str, float]:
    """(label, display unit, factor from the key's unit) of a figure key: :data:`FIGURE_LABELS`, else a readable
    fallback from the key itself ('foo_bar_m' -> ('foo bar', 'mm', 1000.0): its unit suffix converted to the
    display unit, underscores to spaces)."""
    if key in FIGURE_LABELS:
        return FIGURE_LABELS[key]
    stem, _, suffix = str(key).rpartition("_")
    if stem and suffix in _SUFFIX_UNITS:
        unit, f = _SUFFIX_UNITS[suffix]
        return re.sub(r"_+", " ", stem).strip(), unit, f
    return re.sub(r"_+", " ", str(key)).strip(), "", 1.0


def figure_head(key: str) -> str:
    """'label [unit]' (or 'label' without a unit) of a figure key: a table's column head."""
    label, unit, _ = figure_label(key)
    return f"{label} [{unit}]" if unit else label


def figure_value(key: str, value):
    """A figure's value in its display unit (:func:`figure_label`'s factor; None / non-numbers unchanged)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return value
    return value * figure_label(key)[2]


def handeye_values(t: dict) -> tuple[list, list]:
    """([(x, std) mm text] * 3, [(angle, std) deg text] * 3) of a hand-eye transform dict (``report.handeye``):
    each std to 2 significant digits (:func:`fmt_sig`), its value to the same decimal place (1 decimal mm /
    2 decimals deg without a std); summary.txt and report.html print these."""
    def pairs(values, stds, f, default):
        out = []
        for v, s in zip(values, stds or [None] * len(values)):
            s = None if s is None else s * f
            out.append((f"{v * f:.{decimals_of(s, default)}f}", fmt_sig(s)))
        return out

    return (pairs(t["xyz_m"], t.get("std_xyz_m"), 1e3, 1),
            pairs(t.get("rpy_deg") or [], t.get("std_rot_deg"), 1.0, 2))


def lack_of_fit_line(lof: dict) -> str:
    """One summary line of an ``identify.lack_of_fit`` dict: what is flagged (or the smallest p-value) and the
    joint errors (2nd harmonic, best-worst phase) the tests would detect."""
    if lof.get("error"):
        return f"lack of fit: {lof['error']}"
    groups = [g for g in lof.get("groups", []) if g.get("p_value") is not None]
    if lof.get("significant"):
        head = f"lack of fit ({lof['test']} tests, level {lof['level']:g}): {lof['message']}"
    elif groups:
        g = min(groups, key=lambda g: g["p_value"])
        head = (f"lack of fit ({lof['test']} tests, level {lof['level']:g}): no dependence on the joints or the image "
                f"position (smallest p {g['p_value']:.2g}, {g['name']})")
    else:
        return "lack of fit: no test possible"
    det = []
    for g in groups:
        h = next((h for h in g.get("harmonics", []) if h["order"] == 2), None)
        lo, hi = (_meaningful(a) for a in (h["detectable_amplitude_deg"] if h else (None, None)))
        if lo is not None:
            det.append(f"{g['term']} {lo:.2g}-{'any' if hi is None else f'{hi:.2g}'}")
    return head + (f"; detectable joint error A sin(2q + phase), deg (best-worst phase; any: at some phase no amplitude "
                   f"is detectable, the parameters absorb it): {', '.join(det)}" if det else "")


def _meaningful(amp_deg):
    """A detectable amplitude [deg] of a lack-of-fit block, None where it is not meaningful: None already
    (``identify.lack_of_fit``: absorbed by the parameters), not finite, or above MAX_DETECTABLE_DEG (beyond the
    first-order analysis; reports written before that bound carried 1e+06 deg for an absorbed phase)."""
    from ..identify.lack_of_fit import MAX_DETECTABLE_DEG

    ok = isinstance(amp_deg, (int, float)) and math.isfinite(amp_deg) and 0 < amp_deg <= MAX_DETECTABLE_DEG
    return float(amp_deg) if ok else None


def method_check_line(check: dict) -> str:
    """'method check (a vs b on the same N poses): agree|DISAGREE at level L: chi2 .. on .. dof (p ..), max |z| ..'
    of the report's ``method_check`` block (``experiment.steps.method_check``)."""
    a, b = check["methods"]
    verdict = "agree" if check["verdict"] == "agree" else "DISAGREE"
    return (f"method check ({a} vs {b} on the same {check['n_poses']} poses): {verdict} at level {check['level']:g}: "
            f"chi2 {check['chi2']:.3g} on {check['dof']} dof (p {check['p_value']:.2g}"
            + (f"; {check['untested']} directions where they differ by < 3 % of a std untested" if check.get("untested")
               else "") + f"), max |z| {check['max_abs_z']:.2f} ({check['worst']})")
