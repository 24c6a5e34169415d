"""Summary-text pieces shared by ``summary.txt`` (:mod:`.report`) and ``report.html`` (:mod:`.report_html`):
display units of parameter kinds and the one-line summaries of the lack-of-fit and method-check blocks."""

from __future__ import annotations

import numpy as np

#: display unit of a parameter kind in the summary's table: (unit, factor from SI)
KIND_UNITS = {"length": ("mm", 1e3, "12.4f"), "angle": ("deg", float(np.degrees(1.0)), "12.5f")}


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
        if h and h["detectable_amplitude_deg"][0] is not None:
            lo, hi = h["detectable_amplitude_deg"]
            det.append(f"{g['term']} {lo:.2g}-{'any' if hi is None else f'{hi:.2g}'}")
    return head + (f"; detectable joint error A sin(2q + phase), deg (best-worst phase; any: a phase the parameters "
                   f"absorb): {', '.join(det)}" if det else "")


def method_check_line(check: dict) -> str:
    """'method check (a vs b on the same N poses): agree|DISAGREE at level L: chi2 .. on .. dof (p ..), max |z| ..'
    of the report's ``method_check`` block (``experiment.steps.method_check``)."""
    a, b = check["methods"]
    verdict = "agree" if check["verdict"] == "agree" else "DISAGREE"
    return (f"method check ({a} vs {b} on the same {check['n_poses']} poses): {verdict} at level {check['level']:g}: "
            f"chi2 {check['chi2']:.3g} on {check['dof']} dof (p {check['p_value']:.2g}"
            + (f"; {check['untested']} directions where they differ by < 3 % of a std untested" if check.get("untested")
               else "") + f"), max |z| {check['max_abs_z']:.2f} ({check['worst']})")
