"""The cause of a large reprojection error tested, not guessed (issue 28): given intrinsics + robot pose error
against intrinsics refined from the same images + robot pose error.

When ``process`` ran with intrinsics given (recording.yaml) and the chain's reprojection is far above what its
noise model predicts (``reprojection_check.reprojection_noise_check``: the ratio, or, with a robot pose error estimated
by the hand-eye fit, the ratio to the corner noise alone, above ``REPROJECTION_K``), both hypotheses are fitted
and compared on what both predict: the image corners. Each hypothesis h gives a per-coordinate corner variance
``s_h^2 = sigma_c^2 + robot_px_h^2 / 2`` (corner noise, and its own robot pose error in pixels) and residuals of
RMS ``rms_h`` over n corners; its Gaussian log-likelihood of the 2n coordinates and its parameter count p_h (the
model's free parameters, + the intrinsics refined) give ``BIC_h = -2 log L_h + p_h log(2n)``. The refined
hypothesis is applied when its BIC is lower by more than :data:`DECISIVE_BIC` ("very strong" evidence, Kass &
Raftery 1995) and its k-fold held-out prediction (the runs' ``holdout`` blocks: each hypothesis against its own
measurements) is not worse, else the given intrinsics stay, and the report shows both. The held-out folds of
both are fitted only when the BIC is decisive (``compare(holdout=)``): the decision reads them only then.
"""

from __future__ import annotations

import numpy as np

#: BIC difference taken as decisive
DECISIVE_BIC = 10.0


def cause_test_applies(report: dict) -> bool:
    """Whether ``report`` (a ``process`` run with intrinsics given) calls for the test (module docstring)."""
    nc = (report.get("reprojection") or {}).get("noise_check") or {}
    v = report["verdict"]
    if not (v.get("converged") and v.get("finite", True)) or not nc.get("intrinsics_given"):
        return False  # a run that failed on its held-out prediction still calls for it: wrong intrinsics do that
    robot = ((report.get("handeye") or {}).get("robot_pose_std") or {})
    k = float(nc.get("limit") or np.inf)
    return bool(nc.get("ratio", 0) > k or (robot.get("source") == "estimated" and nc.get("ratio_corner_noise", 0) > k))


def hypothesis(report: dict, name: str) -> dict:
    """One hypothesis' figures from its report: reprojection RMS over n corners, corner noise and robot pose error
    in px, parameter count, the robot pose error estimate, BIC (module docstring)."""
    rp = report.get("reprojection") or {}
    nc = rp.get("noise_check") or {}
    n = int(rp.get("n_corners") or 0)
    rms, sc, rpx = float(rp["rms_px"]), float(nc.get("corner_noise_px") or 0.0), float(nc.get("robot_px") or 0.0)
    var = max(sc**2 + rpx**2 / 2, 1e-12)  # per coordinate
    ss = n * rms**2  # sum of squared 2-D corner errors
    m2 = 2 * n
    nll2 = m2 * np.log(2 * np.pi * var) + ss / var
    p = sum(1 for q in report.get("parameters", []) if q.get("free"))
    robot = (report.get("handeye") or {}).get("robot_pose_std") or {}
    p += 2 if robot.get("source") == "estimated" else 0
    intr = report.get("intrinsics") or {}
    n_intr = sum(1 for v in (intr.get("std") or {}).values() if isinstance(v, (int, float)) and np.isfinite(v) and v > 0) \
        if intr.get("source") != "recording.yaml" else 0
    p += n_intr
    out = {"name": name, "rms_px": rms, "n_corners": n, "corner_noise_px": sc, "robot_px": rpx, "n_params": int(p),
           "n_intrinsics_refined": int(n_intr), "minus_2_log_likelihood": float(nll2),
           "bic": float(nll2 + p * np.log(max(m2, 2)))}
    if robot.get("source") == "estimated":
        out["robot_pose_std"] = {"translation_mm": robot.get("translation_mm"), "rotation_deg": robot.get("rotation_deg")}
    held = held_out_figures(report.get("holdout"))
    if held:
        out["holdout"] = held
    return out


def held_out_figures(block: dict | None) -> dict | None:
    """{residual_of, position_rms_mm, rotation_rms_deg} of a report's ``holdout`` block (its k-fold prediction of
    the hypothesis' own measurements, ``overall.after``), None without one."""
    o = (block or {}).get("overall")
    if not o:
        return None
    return {"residual_of": block.get("residual_of") or block.get("residual_kind"),
            "position_rms_mm": o["after"]["position_rms_mm"], "rotation_rms_deg": o["after"].get("rotation_rms_deg")}


def compare(given: dict, refined: dict | None, refined_error: str | None = None, holdout=None) -> dict:
    """The report's ``cause`` block from the two runs' reports (``refined`` None: the views could not calibrate
    the intrinsics, ``refined_error`` says why). holdout: () -> (given's ``holdout`` block, refined's), asked for
    only when the BIC favours the refined intrinsics decisively (the one case whose decision reads them; the
    hypotheses then carry their figures); None: the reports' own blocks, when they have them."""
    g = hypothesis(given, "intrinsics given + robot pose error")
    if refined is None:
        return {"hypotheses": [g], "chosen": "given", "decisive": False,
                "message": f"the cause could not be tested: the views cannot calibrate the intrinsics ({refined_error})"}
    r = hypothesis(refined, "intrinsics refined from these images + robot pose error")
    d = g["bic"] - r["bic"]
    if holdout is not None and d > DECISIVE_BIC:
        for h, block in zip((g, r), holdout()):
            fig = held_out_figures(block)
            if fig:
                h["holdout"] = fig
    hg, hr = g.get("holdout"), r.get("holdout")
    held = None if not (hg and hr) else hr["position_rms_mm"] <= hg["position_rms_mm"]
    chosen = "refined" if d > DECISIVE_BIC and held is not False else "given"
    def rob(h):
        s = h.get("robot_pose_std")
        return f", robot pose error {s['translation_mm']:.3g} mm / {s['rotation_deg']:.3g} deg per axis" if s else ""
    msg = (f"cause tested: reprojection {g['rms_px']:.3g} px with the given intrinsics{rob(g)} against "
           f"{r['rms_px']:.3g} px with {r['n_intrinsics_refined']} intrinsics refined from these images{rob(r)}; "
           f"BIC {g['bic']:.1f} vs {r['bic']:.1f} (difference {d:+.1f}; decisive above {DECISIVE_BIC:g})")
    if held is not None:
        msg += (f"; held-out position RMS {hg['position_rms_mm']:.3g} vs {hr['position_rms_mm']:.3g} mm "
                f"(k-fold, each against its own measurements)")
    msg += ": " + ("the intrinsics were wrong: the refined ones are applied (the result below)" if chosen == "refined"
                   else "the held-out prediction contradicts the likelihood: the given intrinsics are kept"
                   if d > DECISIVE_BIC else
                   "the likelihood favours the given intrinsics decisively: they are kept" if d < -DECISIVE_BIC else
                   "the evidence does not favour refining the intrinsics decisively: the given ones are kept")
    return {"hypotheses": [g, r], "chosen": chosen, "decisive": bool(abs(d) > DECISIVE_BIC), "delta_bic": float(d),
            "holdout_agrees": held, "message": msg}


__all__ = ["DECISIVE_BIC", "cause_test_applies", "hypothesis", "held_out_figures", "compare"]
