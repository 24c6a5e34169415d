"""The plan's outputs (atomic writes, ``serialize``): ``poses.csv`` + ``recording.yaml`` + ``scene/`` + empty
``images/<pose_id>/`` folders (a recording to fill: ``io.recording.write_recording``), ``plan.json``, the 3-D picture
``plan_poses.png`` and ``report.html`` (one self-contained page: ``vision_calib.report.html``'s ``page``, ``table``,
``png_img``). Lengths shown in mm, angles in deg."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..report.accuracy_map_page import accuracy_map_section
from ..report.html import esc, num, page, png_img, table
from ..rig.base import ArmFrames
from ..serialize import write_bytes_atomic, write_json_atomic, write_text_atomic

PICTURE = "plan_poses.png"
ACCURACY_PICTURE = "plan_accuracy.png"
PLAN_JSON = "plan.json"
HTML = "report.html"
SIM_SCENE = "simulate_plan.yaml"


# ----------------------------------------------------------------------------------------------- 3-D picture
def _box_edges(T: np.ndarray, dims) -> list[np.ndarray]:
    """Edges [(2, 3)] of a box of edge lengths dims (3,) centred at T (4, 4)."""
    h = np.asarray(dims, float) / 2
    c = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
    p = (T[:3, :3] @ c.T).T + T[:3, 3]
    return [p[[i, j]] for i in range(8) for j in range(i + 1, 8) if np.sum(np.abs(c[i] - c[j]) > 1e-12) == 1]


def _circle(T: np.ndarray, r: float, z: float, k: int = 24) -> np.ndarray:
    a = np.linspace(0, 2 * np.pi, k)
    c = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(k, z)])
    return (T[:3, :3] @ c.T).T + T[:3, 3]


def _obstacle_lines(b, centre: np.ndarray, span: float) -> list[np.ndarray]:
    T = b.T_frame_body
    if b.plane:
        Tp = T.copy()
        Tp[:3, 3] = T[:3, 3] + T[:3, :3] @ np.array([0.0, 0.0, b.dims[2] / 2])  # the plane: the box's top face
        # a square of the plane around the poses
        off = Tp[:3, :3].T @ (centre - Tp[:3, 3])
        sq = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]], float) * span
        pts = np.column_stack([sq[:, 0] + off[0], sq[:, 1] + off[1], np.zeros(5)])
        return [(Tp[:3, :3] @ pts.T).T + Tp[:3, 3]]
    if b.shape == "box":
        return _box_edges(T, b.dims)
    if b.shape == "cylinder":
        r, h = b.dims
        lo, hi = _circle(T, r, -h / 2), _circle(T, r, h / 2)
        return [lo, hi] + [np.array([lo[i], hi[i]]) for i in range(0, len(lo), 6)]
    r = b.dims[0]
    return [_circle(T, r, 0.0), _circle(T @ np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1.0]]), r, 0.0)]


def draw_plan(path, scene, poses: np.ndarray, model) -> Path:
    """The planned poses in 3-D (robot base frame, mm): the arm's stick figure at each pose (arms), the end points
    (flange / nacelle) numbered in tour order and joined by the tour, the obstacles' edges (a plane as a square).
    Writes a PNG and returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    setup = scene.setup
    ends = setup.end_point(poses) * 1e3
    fig = plt.figure(figsize=(7.5, 6.5))
    ax = fig.add_subplot(projection="3d")
    cmap = plt.get_cmap("viridis")
    k = len(poses)
    cols = [cmap(i / max(k - 1, 1)) for i in range(k)]
    pts = [ends]
    if isinstance(setup, ArmFrames):
        F = setup.link_frames(poses) * np.array([1, 1, 1, 1e3])[None, None, None, :]  # translations in mm
        for i in range(k):
            o = F[i, :, :3, 3]
            ax.plot(o[:-1, 0], o[:-1, 1], o[:-1, 2], "-", color=cols[i], lw=0.8, alpha=0.6)
            ax.plot(o[-2:, 0], o[-2:, 1], o[-2:, 2], "-", color=cols[i], lw=1.6)
        pts.append(F[:, :, :3, 3].reshape(-1, 3))
    ax.plot(ends[:, 0], ends[:, 1], ends[:, 2], "--", color="0.3", lw=0.9)
    ax.scatter(ends[:, 0], ends[:, 1], ends[:, 2], c=cols, s=22, depthshade=False)
    for i, p in enumerate(ends):
        ax.text(p[0], p[1], p[2], f" {i:03d}", fontsize=6)
    lines = []
    if model is not None:
        for b in model.obstacles:
            if not b.plane:
                lines += [ln * 1e3 for ln in _obstacle_lines(b, None, 0.0)]
    allp = np.concatenate(pts + lines)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    mid, half = (lo + hi) / 2, float(np.max(hi - lo)) / 2 + 20
    if model is not None:
        for b in model.obstacles:
            if b.plane:  # a square of the plane, as large as the view
                lines += [ln * 1e3 for ln in _obstacle_lines(b, mid / 1e3, half / 1e3)]
    for ln in lines:
        ax.plot(ln[:, 0], ln[:, 1], ln[:, 2], "-", color="#b5523b", lw=0.8)
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    ax.set_title(f"{scene.name}: {k} poses in tour order (robot base frame)", fontsize=9)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return write_bytes_atomic(path, buf.getvalue())


# ----------------------------------------------------------------------------------------------- report.html
def _acc_table(pred: dict, given_label: str | None = None) -> str:
    rows, classes = [], []
    for r in pred["rows"]:
        for what, label in (("plan", "planned"), ("random", "random measurable")):
            f = r[what]
            rows.append([esc(r["count"]), esc(label), num(f["median_mm"], ".3g"), num(f["p95_mm"], ".3g"),
                         num(f["rms_median_mm"], ".3g"), esc(f"{f['draws']}" + (f" ({f['failed_draws']} failed)"
                                                                               if f["failed_draws"] else "")),
                         num(r["ratio_rms"], ".2f") if what == "plan" else ""])
            classes.append("" if what == "plan" else "warn")
    g = pred.get("given")
    if g:
        rows.insert(0, [esc(pred["counts"][0]), esc(given_label or "your list"), num(g["median_mm"], ".3g"),
                        num(g["p95_mm"], ".3g"), num(g["rms_median_mm"], ".3g"), esc(g["draws"]), ""])
        classes.insert(0, "")
    return table(["poses", "pose set", "median [mm]", "95 % [mm]", "RMS (median of draws) [mm]", "draws",
                  "RMS plan / random"], rows, left=(1,), row_classes=classes)


def _poses_table(res: dict) -> str:
    rows, classes = [], []
    problems = any(p.get("problem") for p in res["poses"])
    for p in res["poses"]:
        v = p["view"]
        j = [f"{a:.1f}" for a in p["joints_deg"]]
        h = (len(j) + 1) // 2
        rows.append([esc(p["id"]), esc(" ".join(j[:h])) + "<br>" + esc(" ".join(j[h:])),
                     num(None if p.get("clearance_m") is None else p["clearance_m"] * 1e3, ".1f", "-"),
                     "<br>".join(esc(c) for c in p.get("closest") or []) or "-",
                     num(None if v["distance_m"] is None else v["distance_m"] * 1e3, ".0f"),
                     num(v["incidence_deg"], ".1f"), num(v["square_px"], ".1f"), num(v["margin_px"], ".0f"),
                     num(p.get("leverage"), ".2f", "-")] + ([esc(p.get("problem", ""))] if problems else []))
        classes.append("bad" if p.get("problem") else "")
    return table(["pose", "joints [deg]", "clearance [mm]", "closest", "distance [mm]", "incidence [deg]",
                  "square [px]", "margin [px]", "leverage"] + (["problem"] if problems else []), rows,
                 left=(1, 3, 9), row_classes=classes)


def draw_accuracy(path, curve: dict) -> Path:
    """N -> predicted validation position RMS (median and 95th percentile, first order) of the planned and of random
    poses (``plan.json``'s ``accuracy_vs_count``), the target as a line; a PNG of ~600 px."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = curve["rows"]
    n = [r["count"] for r in rows]
    fig, ax = plt.subplots(figsize=(5.5, 3.0))
    for what, colour in (("plan", "#2b6cb0"), ("random", "#b5523b")):
        for q, style in (("median_mm", "-o"), ("p95_mm", "--")):
            ax.plot(n, [r[what][q] if r[what][q] is not None else np.nan for r in rows], style, color=colour, ms=3,
                    label=f"{what} {'median' if q == 'median_mm' else '95 %'}")
    if curve.get("target_mm"):
        ax.axhline(curve["target_mm"], color="#555", lw=0.8, ls=":", label="target")
    ax.set_xlabel("poses")
    ax.set_ylabel("validation position RMS [mm]")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return write_bytes_atomic(path, buf.getvalue())


def plan_html(res: dict, out_dir) -> str:
    """The page of a plan (or of a checked list): summary and warnings first, the predicted accuracy, the poses, the
    3-D picture, the tour, identifiability, screening, collision model, settings."""
    check = res["kind"] == "check"
    s, sc = res["settings"], res["scene"]
    title = f"vision_calib {'pose check' if check else 'pose plan'}: {sc['name']}"
    out = [f"<h1>{'Check of a pose list' if check else 'Pose plan'}</h1>",
           f"<p class=\"sub\">scene {esc(sc['name'])} · {esc(sc['robot_kind'])} · mount {esc(sc['mount'])} · "
           f"{esc(res['n_poses'])} poses · seed {esc(s['seed'])}</p>"]
    poses = res["poses"]
    clear = [p["clearance_m"] for p in poses if p.get("clearance_m") is not None]
    if check:
        v = res["verdict"]
        state = "ok" if v["ok"] else "failed"
        head = (f"{v['usable_poses']} of {v['n_poses']} poses usable; " + ("no move collides" if v["ok"] else
                                                                         "see the warnings"))
    else:
        state = "warning" if res["warnings"] else "ok"
        head = (f"{res['n_poses']} poses, tour {res['tour']['total_s']:.1f} s at "
                f"{s['max_joint_speed_deg_s']:.0f} deg/s" + (f"; smallest clearance {min(clear) * 1e3:.1f} mm "
                                                             f"(margin {s['clearance_m'] * 1e3:.0f} mm)" if clear else ""))
    items = [f"warning: {w}" for w in res["warnings"]] + [f"note: {n}" for n in res["notes"]]
    out.append(f'<section class="verdict {state}"><div class="state">{esc(head)}</div><ul class="w">'
               + ("".join(f"<li>{esc(t)}</li>" for t in items) or "<li>no warnings</li>") + "</ul></section>")
    pred = res.get("predicted_accuracy")
    out.append("<h2>Predicted accuracy</h2>")
    if pred:
        out.append(f"<p>identify-synthetic Monte Carlo under the image measurement ({esc(pred['noise']['model'])}; "
                   f"{pred['noise']['frames']} frames per pose; method {esc(pred['method'])}): position error of the "
                   "identified robot against the truth on "
                   f"{esc(pred['validation'])}, pooled over {pred['draws']} draws "
                   f"({esc(pred['seeds'])}). Random sets: new measurable collision-free poses each draw.</p>")
        out.append(_acc_table(pred, "your list (usable poses)" if check else None))
        out.append("<p class=\"muted\">simulate over exactly these poses (a scene with <code>poses: {kind: file, "
                   "path: poses.csv}</code>) reports the same figure as its validation position RMS, from images.</p>")
    else:
        out.append("<p>no prediction (too few usable poses)</p>")
    d = res.get("design")
    if d:
        eff = d["d_efficiency_vs_random"]
        effs = eff["median"] if isinstance(eff, dict) else eff
        out.append(f"<p>D criterion (log det of the information of the {d['n_base_parameters']} base parameters, "
                   f"scaled units) {d['logdet']:.4g}; D-efficiency against random sets of as many poses "
                   f"{effs:.3g} (median)" + (f"; against a D-optimal set {d['d_efficiency_vs_plan']:.3g}"
                                             if "d_efficiency_vs_plan" in d else "") + ".</p>")
    curve = res.get("accuracy_vs_count")
    if curve:
        out.append("<h3>How many poses</h3>")
        acc_pic = Path(out_dir) / ACCURACY_PICTURE
        if acc_pic.is_file():
            out.append(f"<figure>{png_img(acc_pic, 'predicted accuracy against the number of poses')}</figure>")
        out.append(table(["poses", "plan median [mm]", "plan 95 % [mm]", "random median [mm]", "random 95 % [mm]"],
                         [[esc(r["count"]), num(r["plan"]["median_mm"], ".3g"), num(r["plan"]["p95_mm"], ".3g"),
                           num(r["random"]["median_mm"], ".3g"), num(r["random"]["p95_mm"], ".3g")]
                          for r in curve["rows"]]))
        out.append(f"<p class=\"muted\">{esc(curve['of'])}" + (f"; target {curve['target_mm']:g} mm (95 %)"
                                                                 if curve.get("target_mm") else "") + ".</p>")
    out.append(accuracy_map_section(res))  # the accuracy map of the planned poses (report.accuracy_map_page)
    out.append("<h2>Poses</h2>")
    out.append("<p>in tour order; joints to command (nominal model); clearance: smallest distance of the robot's bodies "
               "to the obstacles and to its own non-adjacent links (FCL); view: camera to board centre, board normal "
               "to viewing ray, smallest projected square, board outline to image border; leverage: the pose's share "
               "of the information (the leverages of a design add up to the number of base parameters).</p>"
               if not check else "<p>in the list's order.</p>")
    out.append(_poses_table(res))
    pic = Path(out_dir) / PICTURE
    if pic.is_file():
        out.append(f"<figure>{png_img(pic, 'planned poses in 3-D')}<figcaption>the poses in the robot base frame "
                   "(mm), numbered in tour order; obstacles in red</figcaption></figure>")
    t = res["tour"]
    out.append("<h2>Tour</h2>")
    out.append(f"<p>{len(t['moves'])} moves, {t['total_s']:.1f} s (straight joint-space moves, every joint at most "
               f"{s['max_joint_speed_deg_s']:.0f} deg/s); "
               + ("moves checked for collisions every %.1f deg" % s["move_step_deg"] if t["moves_checked"]
                  else "moves not checked for collisions (no collision model)") + ".</p>")
    out.append(table(["from", "to", "time [s]", "largest joint change [deg]", "collides"],
                     [[esc(m["from"]), esc(m["to"]), num(m["time_s"], ".2f"), num(m["largest_joint_change_deg"], ".1f"),
                       esc("-" if m["collides"] is None else ("YES: " + m.get("why", "")) if m["collides"] else "no")]
                      for m in t["moves"]], left=(4,),
                     row_classes=["bad" if m.get("collides") else "" for m in t["moves"]]))
    ident = res.get("identifiability")
    if ident:
        out.append("<h2>Identifiability</h2>")
        out.append(f"<p>{ident['n_params']} base parameters, rank {ident['rank']} over these {ident['n_obs']} poses; "
                   f"condition number {ident['condition_number']:.4g}"
                   + (f" (of the {esc(ident['condition_number_of'])})" if ident.get("condition_number_of") else "")
                   + f"; not identifiable from these poses: {esc(', '.join(ident['non_identifiable']) or 'none')}; "
                   f"not identifiable from any pose of the region (fixed at nominal): "
                   f"{esc(', '.join(ident.get('not_in_base_set') or []) or 'none')}.</p>")
    sc_ = res["screening"]
    out.append("<h2>Candidates</h2>")
    by = ", ".join(f"{k} {v}" for k, v in (sc_.get("not_measurable_by_reason") or {}).items() if v)
    out.append(f"<p>{esc(s['candidate_source'])}: {sc_['candidates']} candidates, {sc_['unreachable']} unreachable, "
               f"{sc_['not_measurable']} with the target not measurable ({esc(by or 'none')}), "
               + (f"{sc_['colliding']} colliding, " if sc_.get("colliding") is not None else "")
               + f"{sc_['kept']} kept; screened in {sc_['seconds']:.2f} s ({sc_['rate_per_s'] or 0:.0f} per s, "
               f"{sc_['fcl_queries']} FCL distance queries).</p>")
    cm = res.get("collision_model")
    if cm:
        reduced = "; ".join(" / ".join(x["pair"]) + f" at {1e3 * x['allowed_m']:.1f} mm"
                            for x in cm.get("self_pairs_reduced", []))
        out.append(f"<p>collision model: {esc(cm['source'])}; bodies: "
                   f"{esc(', '.join(b['name'] for b in cm['bodies']))}; obstacles: "
                   f"{esc(', '.join(b['name'] + ' (' + b['shape'] + ')' for b in cm['obstacles']) or 'none')}; "
                   f"{len(cm['self_pairs_checked'])} link pairs checked, left out: "
                   f"{esc('; '.join(' / '.join(x['pair']) + ' (' + x['why'] + ')' for x in cm['self_pairs_left_out']) or 'none')}"
                   f"; checked at a reduced distance: {esc(reduced or 'none')}.</p>")
    out.append("<p>limits: clearance %.0f mm, camera to board %.0f-%.0f mm, incidence <= %.0f deg, board >= %.0f px "
               "inside the image, squares >= %.0f px.</p>" % (s["clearance_m"] * 1e3, s["distance_m"][0] * 1e3,
                                                            s["distance_m"][1] * 1e3, s["max_incidence_deg"],
                                                            s["margin_px"], s["min_square_px"]))
    files = res.get("files") or {}
    if files:
        out.append('<p class="muted">files: ' + ", ".join(esc(v) for v in files.values()) + "</p>")
    if not check:
        nf = (res.get("design") or {}).get("frames") or "the scene's"
        out.append("<h2>Next steps</h2><ol>"
                   "<li>drive the tour: the joint values of <code>poses.csv</code>, in its order (the robot's "
                   "current position to the first pose is not checked);</li>"
                   f"<li>at each pose record {esc(nf)} frames of the board into "
                   "<code>images/&lt;pose_id&gt;/</code> (the folders are there; <code>recording.yaml</code> "
                   "describes them);</li>"
                   f"<li>run <code>vision-calib process {esc(Path(out_dir).name)}</code> (in the folder above it): "
                   "measure, identify and validate.</li></ol>")
    return page(title, "\n".join(out))


def write_simulate_scene(out: Path, scene) -> Path:
    """``out/simulate_plan.yaml``: the scene copied by the recording (``out/scene/``) with its identification poses
    taken from the plan's ``poses.csv`` (``poses: {kind: file}``, angles in rad as recording.yaml says), so that
    ``simulate out/simulate_plan.yaml`` renders exactly the plan (its validation poses stay random)."""
    import yaml

    from ..config import load_yaml

    rec = load_yaml(out / "recording.yaml")
    copied = out / rec["scene"]
    doc = dict(load_yaml(copied))
    for key in ("robot", "target"):
        if doc.get(key):
            doc[key] = (Path(rec["scene"]).parent / doc[key]).as_posix()
    doc["name"] = f"{scene.name}_plan"
    # the region's keys stay (serial: center, spread): they still draw the random validation poses
    region = {k: v for k, v in (doc.get("poses") or {}).items() if k not in ("kind", "count", "configurations", "path",
                                                                             "units")}
    doc["poses"] = {"kind": "file", "path": "poses.csv", "units": {"angle": "rad"}, **region}
    head = (f"# scene {scene.name!r} with the identification poses of this plan (poses.csv): `vision-calib simulate "
            f"{SIM_SCENE} --out DIR` renders exactly the planned poses\n")
    return write_text_atomic(out / SIM_SCENE, head + yaml.safe_dump(doc, sort_keys=False))


def write_plan(out_dir, scene, res: dict, poses: np.ndarray, joints: np.ndarray, model, plots: bool = True,
               recording: bool = True) -> dict:
    """Write the plan's files into out_dir (module docstring; ``recording``: the recording skeleton and poses.csv,
    a plan; without: a checked list's plan.json and report.html only). Adds ``res["files"]``; returns it."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {}
    if recording:
        from ..io.recording import write_recording

        write_recording(out, scene, poses, joints, (res.get("design") or {}).get("frames") or scene.measurement.frames)
        for p in res["poses"]:
            (out / "images" / p["id"]).mkdir(parents=True, exist_ok=True)
        write_simulate_scene(out, scene)
        files.update({"poses": "poses.csv", "recording": "recording.yaml", "scene": "scene/", "images": "images/",
                      "simulate_scene": SIM_SCENE})
    if plots:
        draw_plan(out / PICTURE, scene, poses, model)
        files["picture"] = PICTURE
        if res.get("accuracy_vs_count"):
            draw_accuracy(out / ACCURACY_PICTURE, res["accuracy_vs_count"])
            files["accuracy_picture"] = ACCURACY_PICTURE
    files.update({"plan": PLAN_JSON, "report": HTML})
    res["files"] = files
    write_json_atomic(out / PLAN_JSON, res)
    write_text_atomic(out / HTML, plan_html(res, out))
    return files


__all__ = ["write_plan", "draw_plan", "draw_accuracy", "plan_html"]
