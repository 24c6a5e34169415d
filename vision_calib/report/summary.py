"""``summary.txt``, the one screen a run prints: the verdict line first (:func:`verdict_line`), then what was
run, measured, identified and how accurate (:func:`summary_text`), and the identified parameters' table
(:func:`parameter_table_text`). Figures in their display units (:mod:`.text`)."""

from __future__ import annotations

from pathlib import Path

from .text import KIND_UNITS, figure_label, fmt_sig, handeye_values, lack_of_fit_line, method_check_line


def parameter_table_text(rows: list[dict]) -> str:
    """The summary's parameter table of the identified (free) rows of :func:`.build.parameters_table`: name, unit,
    nominal, identified +- std (:func:`.text.fmt_sig`: 2 significant digits), and in simulation the true
    value and z = (identified - true) / std; lengths in mm, angles in deg (rows without a unit: SI). Empty when
    nothing was identified."""
    free = [r for r in rows if r.get("free")]
    if not free:
        return ""
    sim = any(r.get("true") is not None for r in free)
    head = f"{'parameter':<18} {'unit':>4} {'nominal':>12} {'identified':>12} {'+- std':>10}"
    head += f" {'true':>12} {'z':>6}" if sim else ""
    lines = ["identified parameters (" + ("simulation: true values and z = (identified - true) / std" if sim
                                         else "measured data") + "):", head]
    for r in free:
        unit = r.get("unit")
        kind = {"m": "length", "rad": "angle"}.get(unit)
        shown, f, fmt = KIND_UNITS.get(kind, (unit or "SI", 1.0, "12.6g"))
        std = r.get("std")
        line = (f"{r['name']:<18} {shown:>4} {r['nominal'] * f:{fmt}} {r['identified'] * f:{fmt}} "
                f"{fmt_sig(None if std is None else std * f):>10}")
        if sim:
            t = r.get("true")
            z = (r["identified"] - t) / std if t is not None and std else None
            line += f" {'n/a' if t is None else format(t * f, fmt):>12} {'n/a' if z is None else format(z, '+.2f'):>6}"
        lines.append(line)
    return "\n".join(lines)



def residuals_line(res: dict) -> str:
    """One summary line of a :func:`.build.residual_stats` block, each figure with what it is and its unit
    (:func:`.text.figure_label`)."""
    def part(k, vals):
        label, unit, f = figure_label(k)
        axes = "joints 1..n" if k.startswith("joint") else "x, y, z"
        return f"{label} {axes} " + ", ".join(f"{x * f:.4g}" for x in vals) + (f" {unit}" if unit else "")

    parts = [part(k, vals) for k, vals in res.items()]
    where = ("" if set(res) == {"joint_rms_deg"} else
             ", per axis of the measured transform's left frame")
    return f"residual RMS after the fit (measured - model{where}): " + "; ".join(parts)



def _what(report) -> str:
    src = report["source"]
    if "scene" in src:
        s = report["settings"]
        return (f"scene {src['scene']['name']}" + (f"  seed {report['seed']}" if "seed" in report else "")
                + f"  poses {s.get('poses')}" + (f"  frames {s['frames']}" if s.get("frames") else "")
                + f"  method {s.get('method')}")
    if "flange_csv" in src:  # a pose-pair file (process-poses, hand-eye)
        s = report["settings"]
        return (f"pose pairs {Path(str(src['file'])).name}  poses {s.get('poses')}  mount {s.get('mount')}  "
                f"noise {s.get('noise')}")
    return f"recording {Path(str(src.get('folder'))).name}"  # the folder's name: no absolute path in summary.txt


def verdict_line(v: dict) -> str:
    """First line of a summary: 'verdict: ok; ...', 'verdict: WARNING: model does not explain the data (...)'
    or 'verdict: NOT CONVERGED; ... -- why' (v: the report's ``verdict`` block)."""
    status = v.get("status", "ok" if v["ok"] else "failed")
    if status == "failed":
        state = (f"FAILED ({v['failure']})" if v.get("failure") else
                 "NOT FINITE" if not v.get("finite", True) else "NOT CONVERGED")
    else:
        state = "WARNING: " + v["message"] if status == "warning" else "ok"
    adequacy = f"; model adequacy: {v['adequacy']}" if v.get("adequacy") else ""
    note = f" (note: {v['note']})" if v.get("note") else ""
    if v.get("adequacy") == "consistent" and v.get("note"):  # which holds: the whole set; the note: some poses
        adequacy, note = "; model adequacy: consistent over all poses (chi2/dof in its band)", f"; but {v['note']}"
    return (f"verdict: {state}; {v['n_rejected_poses']} poses rejected ({v.get('n_outliers', 0)} as outliers)"
            f"{adequacy}{note}; {v['warnings']} warnings" + (f" -- {v['message']}" if status == "failed" and
                                                             v.get("message") else ""))


def summary_text(report: dict) -> str:
    """One screen: the verdict first, then what was run, measured, identified and how accurate."""
    v, ident = report["verdict"], report["identification"]
    lines = [verdict_line(v), _what(report)]
    m = report.get("measurements")
    if m:
        # no second rejected count: the verdict line gives it (measurement failures + outliers)
        lines.append(f"measurement: {m['n_valid']} of {m['n_poses']} poses measured"
                     + (f" ({m['n_rejected']} failed, below; counted in the verdict's rejected poses)"
                        if m["n_rejected"] else ""))
        lines += [f"  pose {rj['pose_id']}: {rj['reason']}" for rj in m["rejected"][:10]]
        if m.get("dropped_corners"):
            dc = m["dropped_corners"]
            lines.append(f"  {sum(len(d['corners']) for d in dc)} corners off the target-plane homography dropped "
                         f"in {len(dc)} views (first: pose {dc[0]['pose_id']} frame {dc[0]['frame_index']}, "
                         f"ids {[c['id'] for c in dc[0]['corners']]})")
        acc = m.get("accuracy_vs_truth")
        if acc:
            lines.append("  measured target pose vs truth, RMS per axis of the camera frame (x, y, z): t = "
                         + ", ".join(f"{x:.3f}" for x in acc["translation_rms_mm"]) + " mm; r = "
                         + ", ".join(f"{x:.4f}" for x in acc["rotation_rms_deg"]) + " deg")
    if "intrinsics" in report:
        lines.append(_intrinsics_line(report["intrinsics"]))
    lines += [f"warning: {w}" for w in report.get("warnings", [])]
    idf = report.get("identifiability")
    if idf:
        pri = idf.get("prior_parameters") or []
        lines.append(f"identifiability: {idf['n_params']} parameters"
                     + (f" ({len(pri)} with a prior: {', '.join(pri)})" if pri else "")
                     + f", rank {idf['rank']}"
                     + (f"; not identifiable: {', '.join(idf['non_identifiable'])}" if idf["non_identifiable"] else ""))
        lines.append(f"  condition number {idf['condition_number']:.3g}"
                     + (f" (of the {idf['condition_number_of']})" if idf.get("condition_number_of") else ""))
    lines.append(f"identification ({ident['method']}): converged={ident['converged']} iterations={ident['iterations']} "
                 f"cost {ident['cost_initial']:.4g} at the start -> {ident['cost_final']:.4g} (half the sum of squared "
                 "whitened residuals, no unit; about half the residual dof when the model fits)")
    check = method_check_line(report["method_check"]) if "method_check" in report else None
    given = set(report.get("warnings", []))  # printed above: once
    lines += [f"warning: {w}" for w in ident.get("warnings", []) if w != check and w not in given]  # check: below
    if check:
        lines.append(check)
    if report.get("lack_of_fit"):
        lines.append(lack_of_fit_line(report["lack_of_fit"]))
    largest = (report.get("intrinsics_sensitivity") or {}).get("largest")
    if largest:
        lines.append("intrinsics sensitivity (largest shift per px, in std): " + ", ".join(
            f"{k} -> {v['parameter']} {v['std_per_px']:+.3g}" for k, v in largest.items()))
    if "residuals" in report:
        lines.append(residuals_line(report["residuals"]))
    if "reprojection" in report:
        from ..measure.reprojection import reprojection_line

        lines.append(reprojection_line(report["reprojection"]))
    if "accuracy" in report:
        b, a = report["accuracy"]["before"], report["accuracy"]["after"]
        lines.append(f"validation ({b['n_poses']} poses, nominal -> identified): "
                     + ", ".join(_before_after(k, b, a, {"mm": ".3f", "deg": ".4f"}.get(figure_label(k)[1], ".4g"))
                                 for k in ("position_rms_mm", "position_max_mm", "rotation_rms_deg") if k in a))
        crit = [k for k in a if k not in _ACCURACY_SHOWN and k in b]  # the kind's criteria (H4: V1, V2, V3)
        if crit:
            vm = report.get("validation_measurements")
            kind = ((report.get("source") or {}).get("scene") or {}).get("robot_kind")
            how = [f"robot kind {kind}"] * bool(kind) + [f"V1/V2 from {vm['n_valid']} of {vm['n_poses']} validation "
                                                          "poses measured from images"] * bool(vm)
            parts = [_before_after(k, b, a, ".3g") + (f" ({100 * (1 - a[k] / b[k]):.1f} % better)"
                                                      if k == "V2_rad" and b[k] > 0 else "") for k in crit]
            lines.append("criteria" + (f" ({'; '.join(how)})" if how else "") + ": " + ", ".join(parts))
    if "synthetic_reference" in report:
        lines += _reference_lines(report)
    if "handeye" in report:
        lines += _handeye_lines(report)
    if "timings_s" in report and "total" in report["timings_s"]:
        lines.append(f"time: {report['timings_s']['total']:.1f} s")
    return "\n".join(lines)


#: accuracy keys of the summary's validation line (the rest of the block: the kind's criteria, their own line)
_ACCURACY_SHOWN = ("position_rms_mm", "position_max_mm", "rotation_rms_deg", "rotation_max_deg", "n_poses",
                   "position_rms_registered_mm")  # the last in report.json only (the audit reads it)


def _before_after(key: str, b: dict, a: dict, fmt: str) -> str:
    """'label b -> a unit' of one figure key of two dicts, in its display unit (:func:`.text.figure_label`)."""
    label, unit, f = figure_label(key)
    return f"{label} {b[key] * f:{fmt}} -> {a[key] * f:{fmt}}" + (f" {unit}" if unit else "")


def _reference_lines(report: dict) -> list[str]:
    """Summary lines of the ``synthetic_reference`` block (experiment.simulate): how it was drawn, the median
    and range over its draws of the validation position RMS (and V2 when the kind has it)."""
    r = report["synthetic_reference"]
    if "sigma_mm" in r:  # version-2.0 reports before the per-pose covariance draws: one draw, pooled sigma
        return [f"synthetic reference (no images, sigma {r['sigma_mm']:.3f} mm / {r['sigma_deg']:.4f} deg): "
                f"position RMS {r['accuracy_after']['position_rms_mm']:.3f} mm"]
    a, rg = r["accuracy_after"], r["range"]
    out = (f"synthetic reference (no images; noise drawn from each measured pose's covariance, {r['draws']} draws): "
           f"position RMS median {a['position_rms_mm']:.3f} mm (range {rg['position_rms_mm'][0]:.3f}-"
           f"{rg['position_rms_mm'][1]:.3f})")
    if "V2_rad" in a:
        label, unit, f = figure_label("V2_rad")
        out += (f", {label.split(':')[0]} median {a['V2_rad'] * f:.3g} {unit} (range {rg['V2_rad'][0] * f:.3g}-"
                f"{rg['V2_rad'][1] * f:.3g})")
    return [out]


def _intrinsics_line(block: dict) -> str:
    """One summary line of the ``intrinsics`` block (process: where the camera intrinsics came from)."""
    v, s = block["values"], block.get("std")
    names = list(v)
    if s is None:
        return (f"intrinsics ({block['source']}): " + ", ".join(f"{k} {v[k]:.2f}" for k in names[:4]) + " px; dist "
                + ", ".join(f"{v[k]:.4g}" for k in names[4:]))
    prop = block.get("propagated") or {}
    how = (f"; their uncertainty {'is included in the fit' if prop.get('in_fit') else 'is added to the std'} "
           f"({prop['n_directions']} directions)") if prop else ""
    views = (f", {block['n_views_used']} views, RMS {block['rms_px']:.3f} px"
             if block.get("n_views_used") is not None and block.get("rms_px") is not None else "")
    return (f"intrinsics ({block['source']}{views}): "
            + ", ".join(f"{k} {v[k]:.2f} ± {fmt_sig(s[k])}" for k in names[:4]) + " px; dist "
            + ", ".join(f"{k} {v[k]:.4g} ± {fmt_sig(s[k])}" for k in names[4:]) + how)


def _handeye_lines(report: dict) -> list[str]:
    he = report["handeye"]
    names = (he["A"], he["B"]) if report["settings"]["mount"] == "eye_in_hand" else ("T_base_cam", "T_flange_target")
    lines = []
    for name in names:
        t = he["transforms"][name]
        xyz, rpy = handeye_values(t)
        lines.append(f"{name}: xyz = " + ", ".join(x for x, _ in xyz) + " mm (std " + ", ".join(s for _, s in xyz)
                     + "); rpy = " + ", ".join(x for x, _ in rpy) + " deg (std " + ", ".join(s for _, s in rpy) + ")")
    rob = he.get("robot_pose_std")
    if rob:
        est = (f" ± {fmt_sig(rob['std_translation_mm'])}" if rob.get("std_translation_mm") is not None else "",
               f" ± {fmt_sig(rob['std_rotation_deg'])}" if rob.get("std_rotation_deg") is not None else "")
        tr = (f"{rob['translation_mm']:.3f}{est[0]} mm" if rob.get("translation_mm") is not None
              else "translation in the measured poses' std (not separable)")
        lines.append(f"robot pose error ({rob['source']}): {tr}, {rob['rotation_deg']:.4f}{est[1]} deg per axis "
                     "(in the weights)")
    mn = he.get("measured_noise")
    if mn:
        lines.append(f"measured poses' noise ({mn['source']}, std per axis of the {mn['frame']} frame): translation "
                     + ", ".join(f"{v:.3g} ± {fmt_sig(s)}" for v, s in
                                 zip(mn["translation_mm"], mn["std_translation_mm"]))
                     + " mm; rotation " + ", ".join(f"{v:.3g} ± {fmt_sig(s)}" for v, s in
                                                    zip(mn["rotation_deg"], mn["std_rotation_deg"])) + " deg")
    cf = he.get("closed_form_comparison")
    if cf:
        ok = {m: v for m, v in cf["methods"].items() if "cost" in v}
        if ok:
            best = min(ok, key=lambda m: ok[m]["cost"])
            lines.append(f"closed forms (OpenCV): started from {cf['start']}; cheapest {best}, cost "
                         f"{ok[best]['cost']:.4g} vs ours {cf['ours']:.4g}")
    return lines
