"""The accuracy map on a page: report.html's "Accuracy map" section (``simulate``, ``process``, ``plan``) and the page
of ``vision-calib compare`` (report.html beside compare.json), drawn from the JSON blocks alone
(``experiment.accuracy_map``, ``experiment.compare``).

The picture: three slices of the tool positions through the calibration poses' centre (x-y seen from above, x-z and
y-z from the side), each cell coloured by its value (r95, or the normalised difference), the calibration poses' tool
positions as dots (all, projected; coloured by their own value where they have one) and the box they span dashed; positions outside the
convex hull of the calibration poses (extrapolated) carry a small white dot. Matplotlib (Agg), PNG inlined as a data
URI: the page needs no file beside it.
"""

from __future__ import annotations

import base64
import html
import io
import math

import numpy as np

#: the section's heading (tests look for it)
HEADING = "Accuracy map"
_VIEWS = ((0, 1, "x", "y"), (0, 2, "x", "z"), (1, 2, "y", "z"))


def _esc(x) -> str:
    return html.escape("" if x is None else str(x))


def _num(v, fmt: str = ".3g") -> str:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return format(v, fmt)


def _png(fig) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _spacing(v: np.ndarray) -> float:
    """The typical spacing of coordinates v (N,): the median gap between their distinct values (1 when one value)."""
    u = np.unique(np.round(v, 6))
    return float(np.median(np.diff(u))) if len(u) > 1 else 1.0


def map_picture(xyz_m, values, extrapolated, cal_xyz_m, label: str, title: str = "", cal_values=None) -> str:
    """Data URI of the three-view picture (module docstring) of points xyz_m (M, 3) [m] with ``values`` (M,) (colour,
    named by ``label``), extrapolated (M,) bool, the calibration tool positions cal_xyz_m (K, 3) [m] (cal_values (K,):
    their own values, as the dots' colours; default black); positions in mm on the axes, each point a cell of the
    grid spacing."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import Normalize

    P = np.asarray(xyz_m, float).reshape(-1, 3) * 1e3
    v = np.asarray(values, float)
    ext = np.asarray(extrapolated, bool)
    K = np.asarray(cal_xyz_m, float).reshape(-1, 3) * 1e3
    ok = np.isfinite(v)
    cv = None if cal_values is None else np.asarray(cal_values, float)
    vmax = float(np.nanmax(np.concatenate([v[ok], [] if cv is None else cv[np.isfinite(cv)]]), initial=0.0))
    norm = Normalize(vmin=0.0, vmax=vmax if vmax > 0 else 1.0)
    cmap = plt.get_cmap("viridis")
    fig, axs = plt.subplots(1, 3, figsize=(13.5, 4.6))
    fig.subplots_adjust(left=0.05, right=0.9, bottom=0.12, top=0.86, wspace=0.3)
    centre = K.mean(axis=0) if len(K) else P.mean(axis=0)
    for ax, (a, b, na, nb) in zip(axs, _VIEWS):
        wa, wb = _spacing(P[:, a]), _spacing(P[:, b])
        o = 3 - a - b  # the axis across the slice: the layer of points nearest the calibration poses' centre
        layers = np.unique(np.round(P[:, o], 6))
        at = layers[np.argmin(np.abs(layers - centre[o]))] if len(layers) else 0.0
        sel = np.abs(P[:, o] - at) <= 0.5 * _spacing(P[:, o]) if len(layers) > 1 else np.ones(len(P), bool)
        order = np.flatnonzero(sel)[np.argsort(np.where(ok, v, -np.inf)[sel])]  # the largest last: on top
        c = P[order][:, [a, b]]
        boxes = np.stack([c + [-wa / 2, -wb / 2], c + [wa / 2, -wb / 2], c + [wa / 2, wb / 2], c + [-wa / 2, wb / 2]],
                         axis=1)
        ax.add_collection(PolyCollection(boxes, facecolors=cmap(norm(np.where(ok, v, 0.0)[order])),
                                         edgecolors="none"))
        e = order[ext[order]]
        ax.scatter(P[e, a], P[e, b], s=3, c="white", marker="o", linewidths=0)
        lo = np.minimum(P[:, [a, b]].min(axis=0) - [wa, wb], K[:, [a, b]].min(axis=0) if len(K) else np.inf)
        hi = np.maximum(P[:, [a, b]].max(axis=0) + [wa, wb], K[:, [a, b]].max(axis=0) if len(K) else -np.inf)
        if len(K):
            ax.scatter(K[:, a], K[:, b], s=18, c="black" if cv is None else cmap(norm(cv)), edgecolors="black",
                       linewidths=0.8, marker="o", label="calibration poses")
            kl, kh = K[:, [a, b]].min(axis=0), K[:, [a, b]].max(axis=0)
            ax.plot([kl[0], kh[0], kh[0], kl[0], kl[0]], [kl[1], kl[1], kh[1], kh[1], kl[1]], "k--", lw=0.8)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_xlabel(f"{na} [mm]")
        ax.set_ylabel(f"{nb} [mm]")
        ax.set_aspect("equal", adjustable="box")
        ax.set_title(f"{na}-{nb} at {'xyz'[o]} = {at:.0f} mm", fontsize=10)
    cax = fig.add_axes([0.92, 0.15, 0.015, 0.68])
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax).set_label(label)
    if title:
        fig.suptitle(title, fontsize=11)
    if len(K):
        axs[0].legend(loc="lower left", fontsize=8, framealpha=0.8)
    return _png(fig)


class _NoPicture(Exception):
    """The map's picture left out on purpose (``--no-plots``)."""


def _stats_cell(s, fmt=".3g") -> str:
    return "none" if not s else f"{_num(s['median'], fmt)} / {_num(s['p95'], fmt)} / {_num(s['max'], fmt)}"


def accuracy_map_section(report: dict, picture: bool = True) -> str:
    """report.html's section of report.json's ``accuracy_map`` block ('' without one); picture False (``--no-plots``):
    the table without the slices (drawing them is most of the section's time)."""
    m = report.get("accuracy_map")
    if not isinstance(m, dict) or not m.get("points"):
        return ""
    pts = [p for p in m["points"] if not p.get("calibration")]
    cal = [p for p in m["points"] if p.get("calibration")]
    xyz = [p["xyz_m"] for p in pts]
    ext = [bool(p.get("extrapolated")) for p in pts]
    out = [f'<section id="accuracy-map"><h2>{HEADING}</h2>',
           f"<p>The predicted tool-point accuracy over the workspace: the radius holding 95 % of the tool position "
           f"error (r95) at {m['n_points']} tool positions around the calibration poses ({m['n_extrapolated']} of them "
           f"outside the calibration poses' convex hull: extrapolated), tool point {_esc(m.get('tcp_m'))} m in the "
           "flange frame, relative to the base frame registered on the calibration poses.</p>"]
    try:
        if not picture:
            raise _NoPicture("not drawn with --no-plots")
        uri = map_picture(xyz, [p["r95_mm"] for p in pts], ext, [p["xyz_m"] for p in cal], "r95 position [mm]",
                          cal_values=[p["r95_mm"] for p in cal])
        out.append(f'<figure><img src="{uri}" alt="accuracy map"><figcaption>r95 of the tool position [mm] on three '
                   "slices through the calibration poses' centre; circles: the calibration poses (all, projected; "
                   "coloured by their own r95; dashed: their box); white dots: extrapolated positions (outside the "
                   "calibration poses' convex hull); blank cells: positions the model does not reach with the "
                   "orientation of the nearest calibration pose.</figcaption></figure>")
    except Exception as exc:  # a picture that cannot be drawn must never cost the page
        out.append(f"<p class=\"muted\">(picture {_esc(exc)})</p>" if isinstance(exc, _NoPicture)
                   else f"<p class=\"muted\">(picture not drawn: {_esc(exc)})</p>")
    rows = []
    for where in ("inside", "extrapolated"):  # inside: the calibration poses and the grid within their hull
        rows.append(f"<tr><td class=\"l\">{where}</td><td>{_stats_cell(m['r95_mm'].get(where))}</td>"
                    f"<td>{_stats_cell(m['r95_deg'].get(where), '.2g')}</td></tr>")
    out.append("<table><thead><tr><th class=\"l\">tool positions</th><th>r95 position [mm] median / 95 % / max</th>"
               "<th>r95 rotation [deg] median / 95 % / max</th></tr></thead><tbody>" + "".join(rows) + "</tbody></table>")
    cov = m.get("coverage")
    if cov:
        out.append(f"<p>Against the simulation's truth: the true tool position error is within r95 at "
                   f"{_num(100 * cov['position']['all'], '.0f')} % of the positions (rotation "
                   f"{_num(100 * cov['rotation']['all'], '.0f')} %); mean squared normalised error "
                   f"{_num(cov.get('mean_z2_over_3'), '.2f')} (1 when the predicted covariance describes it).</p>")
    if m.get("not_covered"):
        out.append("<p>Assumed at their nominal values (no pose identifies them; the tool pose carries their "
                   "deviation): " + ", ".join(f"{_esc(c['parameter'])} (in {_esc(', '.join(c['carried_by']))})"
                                              for c in m["not_covered"]) + ".</p>")
    out.append(f"<p class=\"muted\">{_esc(m.get('how'))}. {_esc((m.get('grid') or {}).get('how'))}.</p>")
    return "\n".join(out) + "</section>"


def compare_body(out: dict) -> str:
    """The body of the page of ``vision-calib compare`` (compare.json's content; ``report.html.page`` makes it a
    page)."""
    dec, p, m = out["decision"], out["parameters"], out["map"]
    state = "ok" if dec["consistent"] else "failed"
    body = ["<h1>Comparison of two calibrations</h1>",
            f"<p class=\"sub\">A {_esc(out['a'])}<br>B {_esc(out['b'])}</p>",
            f"<div class=\"verdict {state}\"><div class=\"state\">{'CONSISTENT' if dec['consistent'] else 'DIFFER'}"
            f"</div><div>{_esc(dec['why'])}</div>"
            + (f"<div>moved: {_esc(', '.join(dec['moved']))}</div>" if dec.get("moved") else "") + "</div>"]
    rows = []
    for r in sorted(p["compared"], key=lambda r: -abs(r["shift_z"]) if math.isfinite(r["shift_z"]) else 0.0):
        ang = r.get("kind") == "angle"
        f, u = (math.degrees(1.0), "deg") if ang else (1e3, "mm")
        rows.append("<tr" + (' class="bad"' if r["moved"] else "") + f"><td class=\"l\">{_esc(r['name'])}</td>"
                    f"<td>{_num(r['a'] * f, '.6g')}</td><td>{_num(r['b'] * f, '.6g')}</td>"
                    f"<td>{_num(r['difference'] * f, '+.4g')} {u}</td><td>{_num(r['std_a'] * f, '.2g')}</td>"
                    f"<td>{_num(r['std_b'] * f, '.2g')}</td><td>{_num(r['z'], '+.2f')}</td>"
                    f"<td>{_num(r['shift_z'], '+.2f')}</td><td>{_num(r['p_bonferroni'], '.3g')}</td>"
                    + (f"<td class=\"l\">{_num(r['moved_by'] * f, '+.4g')} &plusmn; {_num(r['moved_by_std'] * f, '.2g')} "
                       f"{u}" + (f" (or {_esc(', '.join(r['or']))})" if r.get("or") else "") + "</td>"
                       if r["moved"] else "<td></td>") + "</tr>")
    body.append(f"<h2>Parameters (chi-square {_num(p['chi2'], '.4g')} on {p['dof']}, p = {_num(p['chi2_p'])})</h2>"
                "<table><thead><tr><th class=\"l\">parameter</th><th>A</th><th>B</th><th>B - A</th><th>std A</th>"
                "<th>std B</th><th>z</th><th>shift z</th><th>p (Bonferroni)</th><th>moved by</th></tr></thead><tbody>"
                + "".join(rows) + "</tbody></table>")
    if p["not_compared"]:
        body.append("<p>Not compared: " + "; ".join(f"{_esc(r['name'])}: {_esc(r['why'])}" for r in p["not_compared"])
                    + ".</p>")
    body.append(f"<p class=\"muted\">{_esc(p['how'])}.</p>")
    body.append(f"<h2>{HEADING}: normalised difference of the tool poses</h2>")
    pts = [q for q in m["points"] if not q.get("calibration") and q.get("from") == "A"]  # one grid: A's
    cal = [q for q in m["points"] if q.get("calibration")]
    try:
        uri = map_picture([q["xyz_m"] for q in pts], [q["normalised"] for q in pts],
                          [q["extrapolated"] for q in pts], [q["xyz_m"] for q in cal],
                          "normalised difference (position)", cal_values=[q["normalised"] for q in cal])
        body.append(f'<figure><img src="{uri}" alt="normalised difference map"><figcaption>normalised tool position '
                    "difference B - A (above 2.8: beyond the 95 % radius of the combined uncertainty) on three slices of "
                    "A's map grid through the calibration poses' centre; circles: the calibration poses of both runs (coloured by "
                    "their own value).</figcaption></figure>")
    except Exception as exc:  # a picture that cannot be drawn must never cost the page
        body.append(f"<p class=\"muted\">(picture not drawn: {_esc(exc)})</p>")
    body.append(f"<p>{m['n_points']} joint sets: largest difference {_num(m['max_difference_mm'])} mm; normalised "
                f"difference beyond its 95 % value at {_num(100 * m['share_beyond_95'], '.0f')} % of them.</p>"
                f"<p class=\"muted\">{_esc(m['how'])}.</p>")
    body.append("<details><summary>summary</summary><pre>" + _esc(out.get("summary_text", "")) + "</pre></details>")
    return "\n".join(body)


__all__ = ["HEADING", "accuracy_map_section", "compare_body", "map_picture"]
