"""report.html: the run's report as one self-contained page (no network, no sibling file needed: CSS inline,
images as base64 data URIs, no script; the files beside it are linked only as optional downloads), built from the
report.json dict (:mod:`.report`) beside which it is written. Each overlay opens at full size on the page itself
(a CSS ``:target`` lightbox holding the full-size image). Units a person reads: lengths in mm, angles in deg;
figure keys by their labels (:data:`.text.FIGURE_LABELS`); standard deviations to 2 significant digits
(:func:`.text.fmt_sig`).

Order: the verdict (ok / warning / failed, and the warnings in words), the parameter table, identifiability
(rank, what cannot be identified and what it is coupled with, the condition number and what it is computed
on), the adequacy test in words, the per-pose residuals worst first and the rejected poses, the plots, the
overlays of what the detector found on the worst and the rejected poses (:mod:`.overlay`), then the rest
(validation accuracy, camera, summary text). The page helpers (:func:`page`, :func:`table`, :func:`png_img`)
also build the study page (``study/page.py``)."""

from __future__ import annotations

import base64
import html
import math
import re
from pathlib import Path

from ..serialize import write_text_atomic
from .accuracy_map_page import accuracy_map_section
from .text import (KIND_UNITS, figure_head, figure_label, fmt_sig, handeye_values, lack_of_fit_line,
                          method_check_line)

#: the file name beside report.json
HTML_NAME = "report.html"

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0 auto;max-width:1180px;padding:16px 24px;
color:#1d2329;line-height:1.4}
h1{font-size:1.45em;margin:.2em 0 .1em}h2{font-size:1.2em;margin-top:1.6em;border-bottom:1px solid #ccd;padding-bottom:3px}
.sub{color:#566;margin:0 0 12px}
.verdict{border-radius:8px;padding:12px 16px;margin:10px 0 6px;border:2px solid}
.verdict .state{font-size:1.35em;font-weight:700}
.ok{background:#e8f6ea;border-color:#2e8b3d}.warning{background:#fff5de;border-color:#d08a00}
.failed{background:#fde8e8;border-color:#c62828}
table{border-collapse:collapse;margin:6px 0 10px;font-size:.92em}
th,td{border:1px solid #d5dae0;padding:3px 8px;text-align:right;white-space:nowrap}
th{background:#f0f3f6}td.l,th.l{text-align:left;white-space:normal}
tr.bad td{background:#fdecec}tr.warn td{background:#fff8e6}
.num{font-variant-numeric:tabular-nums}
figure{margin:8px 0 18px}figure img{max-width:100%;height:auto;border:1px solid #dde}
figcaption{color:#444;font-size:.9em;margin-top:3px}
.grid{display:flex;flex-wrap:wrap;gap:14px}.grid figure{flex:0 1 560px;margin:0}
pre{background:#f6f8fa;padding:8px;overflow-x:auto;font-size:.85em}
.muted{color:#667}ul.w li{margin:2px 0}
a.zoom{cursor:zoom-in}
.lightbox{display:none}
.lightbox:target{display:block;position:fixed;inset:0;z-index:10;overflow:auto;padding:10px 14px;
background:#15191d;color:#eee}
.lightbox img{max-width:none;height:auto;border:0;display:block}
.lightbox p{margin:0 0 8px;font-size:.9em}
.lightbox a.close{position:sticky;top:0;float:right;background:#fff;color:#111;font-weight:700;padding:3px 10px;
border-radius:4px;text-decoration:none}
"""


def esc(x) -> str:
    """HTML-escaped text of any value."""
    return html.escape("" if x is None else str(x))


def num(v, fmt: str = ".4g", missing: str = "n/a") -> str:
    """A number formatted with ``fmt`` (``missing`` for None / NaN / non-numbers)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (isinstance(v, float) and not math.isfinite(v)):
        return missing
    return format(v, fmt)


def data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64," + base64.b64encode(data).decode("ascii")


def png_img(path, alt: str, cls: str = "") -> str:
    """<img> of a PNG file inlined as a data URI ('' when the file cannot be read)."""
    try:
        data = Path(path).read_bytes()
    except OSError:
        return ""
    return f'<img src="{data_uri(data, "image/png")}" alt="{esc(alt)}"' + (f' class="{cls}"' if cls else "") + ">"


LEFT = ' class="l"'


def table(head, rows, left=(0,), row_classes=None) -> str:
    """<table> of ``head`` (strings) and ``rows`` (lists of already-escaped HTML cells); columns in ``left``
    left-aligned; row_classes: a CSS class per row ('' for none)."""
    def cell(tag, j, v):
        return f"<{tag}{LEFT if j in left else ''}>{v}</{tag}>"

    out = ["<table><thead><tr>" + "".join(cell("th", j, esc(h)) for j, h in enumerate(head)) + "</tr></thead><tbody>"]
    for i, r in enumerate(rows):
        c = (row_classes or [""] * len(rows))[i]
        out.append("<tr" + (f' class="{c}"' if c else "") + ">" + "".join(cell("td", j, v) for j, v in enumerate(r))
                   + "</tr>")
    return "\n".join(out) + "</tbody></table>"


def page(title: str, body: str) -> str:
    """A complete self-contained HTML document."""
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{esc(title)}</title><style>{CSS}</style></head>\n<body>\n{body}\n</body></html>\n")


# ----------------------------------------------------------------------------------------------- sections
STATE_WORDS = {"ok": "OK", "warning": "WARNING", "failed": "FAILED"}


def _what(report: dict) -> str:
    src, s = report.get("source") or {}, report.get("settings") or {}
    parts = [{"simulation": "simulated experiment", "process": "recorded folder, robot chain",
              "process_handeye": "recorded folder, hand-eye (flange poses given)",
              "process_poses": "measured-pose file",
              "process_pose_pairs": "pose-pair file, hand-eye (flange poses given)"}.get(report.get("kind"), str(report.get("kind")))]
    if "scene" in src:
        parts.append(f"scene {src['scene'].get('name')}")
    if "folder" in src:
        parts.append(f"recording {Path(str(src['folder'])).name}")
    if "seed" in report:
        parts.append(f"seed {report['seed']}")
    parts += [f"{k} {s[k]}" for k in ("poses", "frames", "method", "residual") if s.get(k) is not None]
    return " · ".join(parts)


def verdict_section(report: dict) -> str:
    v = report["verdict"]
    status = v.get("status", "ok" if v.get("ok") else "failed")
    state = STATE_WORDS.get(status, esc(status))
    if status == "failed":  # as report.summary.verdict_line names it
        state += (f" ({esc(v['failure'])})" if v.get("failure") else ": not finite" if not v.get("finite", True)
                  else ": not converged")
    counts = (f"{v.get('n_rejected_poses', 0)} poses rejected ({v.get('n_outliers', 0)} as outliers); model "
              f"adequacy: {v.get('adequacy') or 'n/a'}; {v.get('warnings', 0)} warnings")
    items = []
    if v.get("message"):
        items.append(v["message"])
    if report.get("failure") and report["failure"].get("message") != v.get("message"):
        items.append(f"gross input error ({report['failure'].get('kind')}): {report['failure'].get('message', '')}")
    if v.get("note"):
        items.append("note: " + v["note"])
    warn = list(report.get("warnings") or []) + list((report.get("identification") or {}).get("warnings") or [])
    items += [f"warning: {w}" for w in dict.fromkeys(warn)]  # each once
    use = ("a calibrated model was written (calibrated_model.yaml)" if v.get("usable") and
           (report.get("files") or {}).get("model") else
           "no calibrated model was written" if not v.get("usable") else "")
    body = "".join(f"<li>{esc(t)}</li>" for t in items) or "<li>no warnings</li>"
    return (f'<section id="verdict" class="verdict {status}"><div class="state">Verdict: {state}</div>'
            f'<div class="num">{esc(counts)}</div>'
            + (f"<div>{esc(use)}</div>" if use else "") + f'<ul class="w">{body}</ul></section>')


def _display(row: dict):
    """(unit shown, factor from SI, format) of a parameter row (lengths mm, angles deg, else SI)."""
    kind = {"m": "length", "rad": "angle"}.get(row.get("unit"))
    return KIND_UNITS.get(kind, (row.get("unit") or "SI", 1.0, ".6g"))


def parameters_section(report: dict) -> str:
    rows = report.get("parameters")
    if not rows:
        return handeye_section(report) if "handeye" in report else ""
    free = [r for r in rows if r.get("free")]
    sim = any(r.get("true") is not None for r in free)
    head = ["parameter", "unit", "nominal", "identified", "± std", "identified − nominal"]
    head += ["true", "z = (identified − true) / std"] if sim else []
    body, cls = [], []
    for r in free:
        unit, f, fmt = _display(r)
        fmt = fmt.lstrip("0123456789") or ".6g"
        std = r.get("std")
        line = [esc(r["name"]), esc(unit), num(r["nominal"] * f, fmt), num(r["identified"] * f, fmt),
                fmt_sig(None if std is None else std * f), num((r["identified"] - r["nominal"]) * f, "+.4g")]
        z = None
        if sim:
            t = r.get("true")
            z = (r["identified"] - t) / std if t is not None and std else None
            line += [num(None if t is None else t * f, fmt), num(z, "+.2f")]
        body.append(line)
        cls.append("bad" if z is not None and abs(z) > 3 else "warn" if z is not None and abs(z) > 2 else "")
    fixed = [r for r in rows if not r.get("free")]
    out = [f'<section id="parameters"><h2>Identified parameters ({len(free)} free)</h2>',
           '<p class="muted">lengths in mm, angles in deg; ± one standard deviation (2 significant digits)'
           + (" (from the measurement covariance; the z-score compares the estimate with the simulation's truth: "
              "|z| &gt; 2 shaded, |z| &gt; 3 red)" if sim else "") + ".</p>",
           table(head, body, left=(0,), row_classes=cls)]
    if fixed:
        fb = []
        for r in fixed:
            unit, f, fmt = _display(r)
            fb.append([esc(r["name"]), esc(unit), num(r["nominal"] * f, fmt.lstrip("0123456789") or ".6g")])
        out.append(f"<details><summary>{len(fixed)} parameters fixed at their nominal value</summary>"
                   + table(["parameter", "unit", "nominal"], fb) + "</details>")
    return "\n".join(out) + "</section>"


def handeye_section(report: dict) -> str:
    he = report["handeye"]
    tf = he.get("transforms") or {}
    # the two transforms the summary names (report.summary: the identified A, B for eye-in-hand; else the base-camera
    # and flange-target ones); the inverses stay in report.json
    names = ((he.get("A"), he.get("B")) if (report.get("settings") or {}).get("mount") == "eye_in_hand"
             else ("T_base_cam", "T_flange_target"))
    body = []
    for name in [n for n in names if n in tf] or list(tf):
        t = tf[name]
        if not isinstance(t, dict) or "xyz_m" not in t:
            continue
        xyz, rpy = handeye_values(t)
        body.append([esc(name)] + [f"{esc(v)} ± {esc(sd)}" for v, sd in xyz + rpy])
    return ('<section id="parameters"><h2>Identified transforms (hand-eye)</h2>'
            '<p class="muted">± one standard deviation (2 significant digits); each value to the same decimal place.'
            '</p>' + table(["transform", "x [mm]", "y [mm]", "z [mm]", "roll [deg]", "pitch [deg]", "yaw [deg]"], body)
            + "</section>")


def identifiability_section(report: dict) -> str:
    idf = report.get("identifiability")
    corr = (report.get("identification") or {}).get("correlation_warnings") or []
    if not idf:
        return ('<section id="identifiability"><h2>Identifiability</h2><p>No identifiability analysis in this run'
                + (" (hand-eye: the two mounting transforms only)" if report.get("kind") in ("process_handeye",
                                                                                           "process_pose_pairs") else "")
                + ".</p></section>")
    full = idf["rank"] == idf["n_params"]
    out = ['<section id="identifiability"><h2>Identifiability</h2>',
           f"<p><b>rank {idf['rank']} of {idf['n_params']}</b> free parameters "
           f"({idf.get('n_equations', '?')} equations from {idf.get('n_obs', '?')} poses): "
           + ("every free parameter is identifiable from these poses." if full else
              f"{idf['n_params'] - idf['rank']} combinations cannot be identified from these poses.") + "</p>",
           f"<p><b>condition number {num(idf['condition_number'], '.4g')}</b>: largest / smallest singular value "
           "over the identifiable (base) parameters of the Jacobian " + esc(idf.get("scaling", "")) + ". A large value "
           "means some combination of parameters is barely seen by these poses (its std is large).</p>"]
    if idf.get("prior_parameters"):
        out.append("<p>identified partly from a prior: " + esc(", ".join(idf["prior_parameters"])) + "</p>")
    if idf.get("couplings"):
        shown = {r["name"]: _display(r)[:2] for r in report.get("parameters") or []}
        body = []
        for c in idf["couplings"]:
            unit, fp = shown.get(c["parameter"], ("SI", 1.0))
            # 1 SI unit of the parameter ~ v SI units of k: 1 display unit of it ~ v * f_k / f_p display units of k
            comb = " ".join(f"{v * shown.get(k, ('SI', 1.0))[1] / fp:+.4g} {shown.get(k, ('SI', 1.0))[0]} of {k}"
                            for k, v in (c.get("combination_si") or {}).items())
            body.append([esc(c["parameter"]), esc(f"1 {unit} ~ {comb}" if comb else "0 (no effect on the measurements)"),
                         num(c.get("fit_residual"), ".2g")])
        out.append("<p>not identifiable, and the identifiable parameters it is coupled with (a deviation of it has the "
                   "effect of this combination; lengths in mm, angles in deg):</p>"
                   + table(["parameter", "equivalent combination", "fit residual"], body, left=(0, 1)))
    elif idf.get("non_identifiable"):
        out.append("<p>not identifiable: " + esc(", ".join(idf["non_identifiable"])) + "</p>")
    if corr:
        out.append("<p>strongly correlated estimates: " + esc("; ".join(corr)) + "</p>")
    return "\n".join(out) + "</section>"


ADEQUACY_MEANING = {
    "consistent": "The residuals are as large as the measurement noise predicts: the model explains the data, "
                  "and the stated standard deviations can be trusted.",
    "too large": "The residuals are larger than the measurement noise predicts: something the model does not "
                 "contain (a missing parameter, a wrong structure), outlier poses, or an optimistic measurement "
                 "covariance. The calibrated model may still be better than the nominal one; look at the worst "
                 "poses below.",
    "too small": "The residuals are smaller than the measurement noise predicts: the noise was overestimated; "
                 "the standard deviations are pessimistic, not wrong in the dangerous direction.",
    "not available": "No test possible (no redundancy in the data).",
}


def adequacy_section(report: dict) -> str:
    a = report.get("adequacy")
    out = ['<section id="adequacy"><h2>Does the model explain the data? (chi-square adequacy test)</h2>']
    if a:
        lo, hi = a.get("expected_chi2_dof") or (None, None)
        out.append(f"<p><b>{esc(a.get('verdict'))}</b>: {esc(a.get('explanation', ''))}</p>")
        out.append(f"<p>{esc(ADEQUACY_MEANING.get(a.get('verdict'), ''))}</p>")
        out.append(table(["chi2", "dof", "chi2/dof", "expected chi2/dof", "p-value (two-sided)", "level"],
                         [[num(a.get("chi2"), ".4g"), esc(a.get("dof")), num(a.get("chi2_dof"), ".3g"),
                           f"{num(lo, '.3g')} – {num(hi, '.3g')}", num(a.get("p_value"), ".3g"),
                           num(a.get("level"), "g")]], left=()))
        if report.get("variance_factor") is not None:
            out.append(f"<p class=\"muted\">variance factor (chi2/dof of the final fit): "
                       f"{num(report['variance_factor'], '.3g')}</p>")
    else:
        ident = report.get("identification") or {}
        out.append(f"<p>No adequacy block in this report; chi2/dof of the fit: {num(ident.get('chi2_dof'), '.3g')}"
                   "</p>")
    if report.get("lack_of_fit"):
        out.append(f"<p>{esc(lack_of_fit_line(report['lack_of_fit']))}</p>")
    if report.get("method_check"):
        out.append(f"<p>{esc(method_check_line(report['method_check']))}</p>")
    return "\n".join(out) + "</section>"


def residuals_section(report: dict, shown: int = 15) -> str:
    pr = report.get("pose_residuals")
    m = report.get("measurements") or {}
    meas = {str(p["pose_id"]): p for p in m.get("poses", [])}
    out = ['<section id="poses"><h2>Per-pose residuals, worst first</h2>']
    if pr and pr.get("poses"):
        keys = [k for k in ("translation_mm", "rotation_deg", "joint_deg") if k in pr["poses"][0]]
        head = ["pose"] + [figure_head(k) for k in ("chi2", "p_value", *keys)]
        head += [figure_head(k) for k in ("reprojection_rms_px", "n_corners")] if meas else []
        rows, cls = [], []
        for p in pr["poses"]:
            r = [esc(p["pose_id"]), num(p.get("chi2"), ".3g"), num(p.get("p_value"), ".2g")]
            r += [num(p.get(k), ".4g") for k in keys]
            if meas:
                q = meas.get(p["pose_id"], {})
                r += [num(q.get("reprojection_rms_px"), ".3g"), esc(q.get("n_corners", ""))]
            rows.append(r)
            pv = p.get("p_value")
            cls.append("bad" if pv is not None and pv < 1e-3 else "warn" if pv is not None and pv < 1e-2 else "")
        out.append(f"<p class=\"muted\">{esc(pr.get('how', ''))}. p-value of each pose on its own (p &lt; 0.01 "
                   f"shaded, &lt; 0.001 red): of {len(rows)} poses about {len(rows) / 100:.2g} fall below 0.01 by "
                   "chance.</p>")
        out.append(table(head, rows[:shown], row_classes=cls[:shown]))
        if len(rows) > shown:
            out.append(f"<details><summary>the other {len(rows) - shown} poses</summary>"
                       + table(head, rows[shown:], row_classes=cls[shown:]) + "</details>")
    rej = [(str(r["pose_id"]), "measurement", r.get("reason", "")) for r in m.get("rejected") or []]
    rej += [(str(r["pose_id"]), "outlier (fit)", r.get("reason", "")) for r in report.get("outliers") or []]
    out.append(f"<h3>Rejected poses ({len(rej)})</h3>")
    out.append(table(["pose", "rejected by", "reason"], [[esc(a), esc(b), esc(c)] for a, b, c in rej], left=(0, 1, 2))
               if rej else "<p>none</p>")
    return "\n".join(out) + "</section>"


#: what each plot of report.json's ``files`` shows: (caption, what it adds when the run has a truth: simulation)
PLOT_CAPTIONS = {
    "residuals_plot": ("Residual norm per pose with the nominal and the identified parameters (log scale), and "
                       "their histograms; translation [mm] and rotation [deg] rows for pose residuals.", ""),
    "parameters_plot": ("Identified − nominal per parameter, one axis per unit (lengths in mm, angles in deg), ±2σ "
                        "error bars.", " The simulation's truth (red x) and the z-scores against it (grey band: ±2)."),
    "error_map_plot": ("Validation position error [mm] per pose, nominal and identified model, each panel with its "
                       "own colour scale.", " The error is against the simulation's truth."),
}


def has_truth(report: dict) -> bool:
    """Whether the run knows a truth (a simulation): a parameter row with a true value, or kind simulation."""
    return report.get("kind") == "simulation" or any(r.get("true") is not None for r in report.get("parameters") or [])


def plot_caption(key: str, report: dict) -> str:
    """The caption of a plot of report.json's ``files``: what it shows, and what it shows of the truth only when
    there is one (recorded data has none)."""
    text, truth = PLOT_CAPTIONS.get(key, ("", ""))
    return text + (truth if has_truth(report) else "")


def plots_section(report: dict, out_dir) -> str:
    files = report.get("files") or {}
    figs = []
    for key, name in files.items():
        if not key.endswith("_plot"):
            continue
        img = png_img(Path(out_dir) / name, name)
        if img:
            figs.append(f"<figure>{img}<figcaption>{esc(name)}: {esc(plot_caption(key, report))}</figcaption>"
                        "</figure>")
    return '<section id="plots"><h2>Plots</h2>' + ("\n".join(figs) or "<p>no plots in this run</p>") + "</section>"


def _overlay_id(o: dict, i: int) -> str:
    """The page anchor of the i-th overlay's full-size view (letters, digits, '-' only)."""
    return f"overlay-{i}-" + re.sub(r"[^A-Za-z0-9-]", "-", str(o["pose_id"]))


def overlays_section(overlays) -> str:
    from .overlay import LEGEND

    if overlays is None:
        return ""
    out = ['<section id="overlays"><h2>What the detector saw: the rejected and the worst poses</h2>',
           "<p class=\"muted\">" + esc("; ".join(LEGEND.values())) + ". Click an image (or its \"full size\" link) "
           "to open it at full size on this page.</p>"]
    if not overlays:
        out.append("<p>no rejected poses and no per-pose residuals to show</p>")
    figs, boxes = [], []
    for i, o in enumerate(overlays):
        d = o.get("drawn") or {}
        extra = (f"; {d['n_detected']} corners detected; crop x {d['crop'][0]}-{d['crop'][2]}, "
                 f"y {d['crop'][1]}-{d['crop'][3]} px" if d else "") + (
            f"; model reprojection vs detected: RMS {d['model_rms_px']:.3g} px, max {d['model_max_px']:.3g} px "
            f"(lines magnified x{d['vector_gain']:.3g})" if d.get("model_rms_px") is not None else "")
        cap = f"pose {o['pose_id']}, {o['role']}: {o['reason'] or 'no reason recorded'}{extra}"
        alt = f"overlay of pose {esc(o['pose_id'])}"
        img = (f'<img src="{data_uri(o["jpeg"], "image/jpeg")}" alt="{alt}">'
               if o.get("jpeg") else f"<p>(no image: {esc(o.get('note') or 'not available')})</p>")
        link = ""
        if o.get("jpeg") and o.get("full_jpeg"):
            fid, fd = _overlay_id(o, i), o.get("full_drawn") or {}
            size = f"{fd.get('width')} x {fd.get('height')} px" if fd else "full size"
            scale = (f", {fd['scale']:.3g} screen px per camera px" if fd.get("scale") else "")
            img = f'<a class="zoom" href="#{fid}" title="open at full size">{img}</a>'
            link = f' <a href="#{fid}">[full size: {esc(size)}]</a>'
            boxes.append(f'<div class="lightbox" id="{fid}"><a class="close" href="#overlays">close ✕</a>'
                         f"<p>{esc(cap)}; shown at full size, {esc(size)}{esc(scale)}</p>"
                         f'<img src="{data_uri(o["full_jpeg"], "image/jpeg")}" alt="{alt} at full size"></div>')
        figs.append(f"<figure>{img}<figcaption>{esc(cap)}{link}</figcaption></figure>")
    out.append('<div class="grid">' + "\n".join(figs) + "</div>")
    out += boxes
    return "\n".join(out) + "</section>"


def figures_table(columns, what: str = "figure") -> str:
    """<table> of figure dicts [(column name, {key: value})]: one row per key of the first dict (not n_poses),
    named by its label and display unit, its values converted to that unit (:func:`.text.figure_label`);
    ``what``: the head of the label column."""
    keys = [k for k in columns[0][1] if k != "n_poses"]
    rows = []
    for k in keys:
        label, unit, f = figure_label(k)
        rows.append([esc(label), esc(unit), *(num(d[k] * f if isinstance(d.get(k), (int, float)) else None, ".4g")
                                              for _, d in columns)])
    return table([what, "unit", *(name for name, _ in columns)], rows, left=(0, 1))


def holdout_html(h: dict | None) -> str:
    """The held-out k-fold validation (``experiment.holdout``): decision, before/after at the target (and the tool
    point), the RMS change's interval, the predicted accuracy; "" when there is none."""
    if not isinstance(h, dict) or not (h.get("overall") or {}).get("before"):
        return ""
    d = h.get("decision") or {}
    o, c = h["overall"], h.get("without_outliers")
    out = [f"<h3>Held-out accuracy ({esc(h.get('folds'))}-fold)</h3>",
           f"<p class=\"{'ok' if d.get('ok') else 'failed'}\">{'passed' if d.get('ok') else 'FAILED'}: "
           f"{esc(d.get('reason', ''))}</p>",
           f"<p>each pose predicted by the model identified on the other folds (errors of "
           f"{esc(h.get('residual_of', ''))}, measurement noise included); before = nominal model, after = "
           "calibrated; flagged outliers are in no training set:</p>"]
    cols = [(f"all {o.get('n_poses')} poses: {w}", o[w]) for w in ("before", "after")]
    if c:
        cols += [(f"without the {len(c.get('excluded') or [])} flagged outliers: {w}", c[w]) for w in ("before", "after")]
    t = h.get("tool")
    if t:
        cols += [(f"tool point {esc(h.get('tcp_m'))} m: {w}", t[w]) for w in ("before", "after")]
    out.append(figures_table(cols, "held-out error"))
    p = h.get("predicted")
    if p:
        rows = [[esc(f"std at the {what}"), "mm", num(p[what]["position_median_mm"], ".3g"),
                 num(p[what]["position_p95_mm"], ".3g")] for what in ("target", "tool") if what in p]
        out.append(f"<p>predicted from the parameter covariance over {esc(p.get('workspace'))}; held-out RMS predicted "
                   f"{num(p.get('heldout_position_rms_mm'), '.3g')} mm, observed / predicted "
                   f"{num(p.get('ratio_observed_to_predicted'), '.2f')}:</p>")
        out.append(table(["position", "unit", "median", "95 %"], rows, left=(0, 1)))
    return "\n".join(out)


def more_section(report: dict) -> str:
    out = ['<section id="more"><h2>Validation, camera and the rest</h2>']
    acc = report.get("accuracy")
    if acc:
        out.append(f"<p>validation on {acc['before'].get('n_poses')} poses never used in the fit"
                   + (" (against the simulation's truth)" if has_truth(report) else "") + ":</p>")
        out.append(figures_table([("before (nominal model)", acc["before"]), ("after (identified model)", acc["after"])],
                                 "validation error"))
    out.append(holdout_html(report.get("holdout")))
    files = report.get("files") or {}
    extra = [v for v in dict.fromkeys(files.values()) if v != HTML_NAME]
    if extra:  # optional: everything they show is on this page (the plots embedded, report.json's figures above)
        out.append('<p class="muted">optional downloads (the files written beside this page; the page itself needs '
                   "none of them): " + ", ".join(f'<a href="{esc(v)}" download>download {esc(v)}</a>' for v in extra)
                   + "</p>")
    out.append("<details><summary>summary.txt (everything in one screen of text)</summary><pre>"
               + esc(report.get("summary_text", "")) + "</pre></details>")
    return "\n".join(out) + "</section>"


def report_html(report: dict, out_dir, overlays=None, pictures: bool = True) -> str:
    """The page of one report.json dict; out_dir: the folder of its plot files; overlays: the list of
    :func:`.overlay.build_overlays` (None: no overlay section); pictures: False (``--no-plots``) leaves out the
    pictures drawn for the page (the accuracy map's slices; its table stays)."""
    title = f"vision_calib report: {STATE_WORDS.get(report['verdict'].get('status'), '?')} — {_what(report)}"
    body = [f"<h1>Calibration report</h1><p class=\"sub\">{esc(_what(report))}</p>",
            verdict_section(report), parameters_section(report), identifiability_section(report),
            adequacy_section(report), residuals_section(report), plots_section(report, out_dir),
            accuracy_map_section(report, picture=pictures), overlays_section(overlays), more_section(report)]
    return page(title, "\n".join(b for b in body if b))


def write_report_html(out_dir, report: dict, overlays=None, pictures: bool = True) -> Path:
    """Write ``out_dir/report.html`` (atomic) and return its path (pictures: :func:`report_html`)."""
    return write_text_atomic(Path(out_dir) / HTML_NAME, report_html(report, out_dir, overlays, pictures))
