"""Has the robot changed? Two calibration results of the same robot compared against their combined predicted
uncertainty (``vision-calib compare A B --out DIR``: compare.json and report.html).

Inputs: two result folders of ``simulate`` / ``process`` (calibrated_model.yaml with its covariance, report.json
with its ``accuracy_map``), of the same robot model (kind, parameter names, the robot file's nominal geometry):
another day, another camera, after a collision. The two fits are independent: the covariance of a difference is
the sum of the two covariances.

Parameters: the robot's own parameters (not the camera / target mounts, which may differ between the two: another
camera, the target moved) identified in both, except those that carry a mount parameter no pose identifies (the
model file's ``folded`` entries: e.g. d6 carries the camera's offset along the flange axis, theta6 its rotation
about it; a new camera moves them without the robot changing). On those L parameters, the difference
d = x_B - x_A (L,) and S = C_A + C_B (L, L):

- chi-square test: d^T S^+ d against chi2 with rank(S) degrees of freedom (p-value ``chi2_p``);
- each parameter's z = d_i / sqrt(S_ii) (its own difference in combined std) and its ``shift_z`` = (S^+ d)_i /
  sqrt((S^+)_ii), the z of the hypothesis that it alone moved (the best test of one parameter that moved: the
  others' correlated differences are accounted for), with its Bonferroni p over the L parameters (two-sided);
- the parameters that *moved*: selected forward (:func:`moved_stepwise`), the most significant shift first, then
  the next given it, while the Bonferroni p stays below :data:`LEVEL`: one moved joint offset is named alone, not
  with every parameter correlated with it; each with its estimated shift and std.

Decision: the results differ (exit 3) when the chi-square p-value or the smallest Bonferroni p-value is below
:data:`LEVEL` (a family-wise false alarm of at most 2 LEVEL when the covariances are right); consistent (exit 0)
otherwise.

Map: the difference of the tool poses over the joint sets of both results' accuracy maps, to first order through the
compared parameters, with both base frames registered on the calibration poses of both runs as the accuracy map is
(``experiment.accuracy_map``): the difference [mm, deg], the 95 % radius of its predicted distribution and the
normalised difference sqrt(e^T C^-1 e) of the position (a chi with 3 degrees of freedom when nothing changed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import DataError
from ..serialize import write_json_atomic
from .accuracy_map import base_motion_lever, norm_quantile

FORMAT = "vision_calib.compare/1"
#: level of each of the two tests (chi-square; the smallest Bonferroni p of the shift z)
LEVEL = 0.01
#: z^2 difference below which another parameter's shift explains the difference as well (chi2 with 1 dof, 95 %)
INDISTINGUISHABLE = 3.841
#: eigenvalues of S below this share of the largest are not counted in the chi-square (rank)
RANK_TOL = 1e-10


def _load(path, which: str):
    """(CalibratedRobot, report.json dict, result folder) of a result folder (or its calibrated_model.yaml); DataError
    naming it when a file is missing or unreadable, or its covariance is absent or not finite."""
    from ..deploy import CalibratedRobot, model_path
    from ..deploy.export import read_report_json

    p = Path(path)
    if not p.exists():
        raise DataError(f"{which} {p}: no such result folder")
    mp = model_path(p)
    folder = mp.parent
    rp = folder / "report.json"
    try:
        report = read_report_json(rp)
    except DataError as exc:
        raise DataError(f"{which} {exc}") from None
    amap = report.get("accuracy_map")
    if not isinstance(amap, dict) or not amap.get("points"):
        raise DataError(f"{which} {rp}: no accuracy_map (a result written before the accuracy map, or whose map "
                        "could not be computed): run the calibration again with this version")
    tcp = amap.get("tcp_m") or [0.0, 0.0, 0.0]
    robot = CalibratedRobot.load(mp, tcp=tcp)
    C = np.asarray(robot.covariance, float)
    if not np.all(np.isfinite(C)):
        raise DataError(f"{which} {mp}: the parameter covariance is not finite")
    if robot.model.covariance_source.startswith("diagonal") or not np.any(C):
        raise DataError(f"{which} {mp}: no parameter covariance in the model file (written before format 2, or by a "
                        "fit that gave none): the results cannot be compared against their uncertainty")
    return robot, report, folder


def check_same_robot(ra, rb, a, b) -> None:
    """DataError naming both results and the first difference when A and B are not the same robot model."""
    ma, mb = ra.model, rb.model
    if ma.kind != mb.kind:
        raise DataError(f"A {a} and B {b} are not the same robot model: kinds {ma.kind!r} and {mb.kind!r}")
    if tuple(ma.names) != tuple(mb.names):
        only = sorted(set(ma.names) ^ set(mb.names))
        raise DataError(f"A {a} and B {b} are not the same robot model: their parameters differ"
                        + (f" ({', '.join(only[:6])} in only one)" if only else " (order)"))
    na, nb = ma.nominal_robot, mb.nominal_robot
    an, bn = getattr(na, "name", None), getattr(nb, "name", None)
    if an != bn:
        raise DataError(f"A {a} and B {b} are not the same robot: robot files name {an!r} and {bn!r}")
    va, vb = np.asarray(na.params.nominal, float), np.asarray(nb.params.nominal, float)
    for nm, x, y in zip(na.params.names, va, vb):
        if nm in ra.kin.arm_names and not np.isclose(x, y, rtol=0, atol=1e-12):
            raise DataError(f"A {a} and B {b} are not the same robot model: nominal {nm} = {x:.9g} and {y:.9g} "
                            "in their robot files")
    if ra.n_joints != rb.n_joints:
        raise DataError(f"A {a} and B {b} are not the same robot: {ra.n_joints} and {rb.n_joints} joints")


def compared_parameters(ra, rb) -> tuple[list[str], list[dict]]:
    """(names compared, [{name, why}] of the robot parameters left out): the robot's own parameters identified in
    both, except those that carry a mount parameter (module docstring)."""
    arm = set(ra.kin.arm_names)
    carried = {}
    for m in (ra.model, rb.model):
        for f in m.folded:
            if f["parameter"] not in arm:  # a mount parameter folded into ...
                for into in f.get("into", {}):
                    if into in arm:
                        carried.setdefault(into, set()).add(f["parameter"])
    names, left = [], []
    fa, fb = dict(zip(ra.names, ra.model.free)), dict(zip(rb.names, rb.model.free))
    for nm in ra.names:
        if nm not in arm:
            continue
        if not (fa[nm] and fb[nm]):
            if fa[nm] or fb[nm]:
                left.append({"name": nm, "why": f"identified in {'A' if fa[nm] else 'B'} only"})
            continue
        if nm in carried:
            left.append({"name": nm, "why": "carries " + ", ".join(sorted(carried[nm])) + " (a mount parameter no pose "
                                             "identifies: a new camera or target mount moves it too)"})
            continue
        names.append(nm)
    return names, left


def moved_stepwise(d: np.ndarray, W: np.ndarray, level: float = LEVEL) -> list[dict]:
    """The parameters that moved, by forward selection: the parameter whose shift best explains the difference
    d (L,) not yet explained (score z of its shift given the shifts already selected, weight W = S^+) is selected
    while its Bonferroni p (over the parameters left) is below ``level``; the selected shifts are estimated together
    (generalised least squares). Returns [{index, z (score z when selected), p_bonferroni, alternatives (indices of
    the parameters whose shift would explain it about as well: z^2 within INDISTINGUISHABLE), shift, shift_std}] in
    the order selected: the smallest set of single-parameter moves that explains the difference (a parameter that only
    correlates with a moved one is not in it)."""
    from scipy.stats import norm

    L = len(d)
    active: list[int] = []
    steps = []
    Wd = W @ d
    for _ in range(L):
        if active:
            WAA = W[np.ix_(active, active)]
            shift = np.linalg.solve(WAA, Wd[active])
            r = d.copy()
            r[active] -= shift
            WiA = W[:, active]
            var = np.diag(W) - np.einsum("ia,ab,ib->i", WiA, np.linalg.inv(WAA), WiA)
        else:
            r, var = d, np.diag(W).copy()
        u = W @ r
        cand = [i for i in range(L) if i not in active and var[i] > 0]
        if not cand:
            break
        z = {i: u[i] / np.sqrt(var[i]) for i in cand}
        best = max(cand, key=lambda i: abs(z[i]))
        p = float(min(1.0, len(cand) * 2 * norm.sf(abs(z[best]))))
        if not p < level:
            break
        active.append(best)
        # the others whose single shift explains the difference about as well (likelihood ratio below chi2_1(95 %))
        alt = [i for i in cand if i != best and z[best] ** 2 - z[i] ** 2 < INDISTINGUISHABLE]
        steps.append({"index": best, "z": float(z[best]), "p_bonferroni": p, "alternatives": alt})
    if active:
        WAA = W[np.ix_(active, active)]
        shift, cov = np.linalg.solve(WAA, Wd[active]), np.linalg.inv(WAA)
        for k, st in enumerate(steps):
            st["shift"], st["shift_std"] = float(shift[k]), float(np.sqrt(max(cov[k, k], 0.0)))
    return steps


def parameter_test(names, d: np.ndarray, S: np.ndarray, level: float = LEVEL) -> dict:
    """The chi-square and per-parameter tests of a difference d (L,) with covariance S (L, L) (module docstring);
    ``moved``: :func:`moved_stepwise`."""
    from scipy.stats import chi2, norm

    S = 0.5 * (S + S.T)
    lam, V = np.linalg.eigh(S)
    keep = lam > RANK_TOL * max(float(lam.max()), np.finfo(float).tiny)
    W = (V[:, keep] / lam[keep]) @ V[:, keep].T
    stat = float(d @ W @ d)
    dof = int(keep.sum())
    p = float(chi2.sf(stat, dof)) if dof else float("nan")
    sd = np.sqrt(np.clip(np.diag(S), 0, None))
    wd = W @ d
    wdiag = np.diag(W)
    rows = []
    L = len(names)
    steps = moved_stepwise(d, W, level)
    chosen = {st["index"]: st for st in steps}
    for i, nm in enumerate(names):
        z = float(d[i] / sd[i]) if sd[i] > 0 else float("nan")
        sz = float(wd[i] / np.sqrt(wdiag[i])) if wdiag[i] > 0 else float("nan")
        pb = float(min(1.0, L * 2 * norm.sf(abs(sz)))) if np.isfinite(sz) else float("nan")
        row = {"name": nm, "z": z, "shift_z": sz, "p_bonferroni": pb, "moved": i in chosen}
        if i in chosen:
            row |= {"moved_by": chosen[i]["shift"], "moved_by_std": chosen[i]["shift_std"],
                    "or": [names[k] for k in chosen[i]["alternatives"]]}
        rows.append(row)
    pmin = min((r["p_bonferroni"] for r in rows if np.isfinite(r["p_bonferroni"])), default=float("nan"))
    return {"chi2": stat, "dof": dof, "chi2_p": p, "min_p_bonferroni": pmin, "rows": rows,
            "moved": [names[st["index"]] for st in steps],
            "differ": bool((np.isfinite(p) and p < level) or (np.isfinite(pmin) and pmin < level))}


def _map_points(ra, rb, rep_a, rep_b, names, d, S) -> dict:
    """The normalised map (module docstring) over both results' map joint sets."""
    pts_q, src, flags = [], [], []
    for tag, rep in (("A", rep_a), ("B", rep_b)):
        for p in rep["accuracy_map"]["points"]:
            pts_q.append(p["q_rad"])
            src.append(tag)
            flags.append((bool(p.get("extrapolated")), bool(p.get("calibration"))))
    q = np.asarray(pts_q, float)
    qreg = np.concatenate([np.asarray(r["accuracy_map"].get("calibration_q_rad") or [], float).reshape(-1, ra.n_joints)
                           for r in (rep_a, rep_b)])
    if q.ndim != 2 or q.shape[1] != ra.n_joints or not np.all(np.isfinite(q)):
        raise DataError("accuracy_map points: joint sets q_rad of the wrong width or not finite")
    cols = [ra.names.index(n) for n in names]
    x = ra.x

    def jac(qq):
        return ra.kin.tool_jacobian(qq, x)[:, :, cols]

    J = jac(q)
    T = ra.kin.tool(q, x)
    if len(qreg):
        Tr = ra.kin.tool(qreg, x)
        c, H = Tr[:, :3, 3].mean(axis=0), -jac(qreg).mean(axis=0)
        J = J + base_motion_lever(T[:, :3, 3], c) @ H
    e = J @ d  # (M, 6): B - A at each joint set, first order, registered
    C = np.einsum("kil,lm,kjm->kij", J, S, J)
    r_mm = norm_quantile(C[:, :3, :3]) * 1e3
    r_deg = np.degrees(norm_quantile(C[:, 3:, 3:]))
    Cp = C[:, :3, :3]
    z = np.sqrt(np.einsum("ki,ki->k", e[:, :3], np.einsum("kij,kj->ki", np.linalg.pinv(Cp, hermitian=True), e[:, :3])))
    from scipy.stats import chi2

    beyond = z**2 > chi2.ppf(0.95, 3)
    points = [{"xyz_m": [float(v) for v in T[k, :3, 3]], "q_rad": [float(v) for v in q[k]], "from": src[k],
               "difference_mm": float(np.linalg.norm(e[k, :3]) * 1e3),
               "difference_deg": float(np.degrees(np.linalg.norm(e[k, 3:]))),
               "r95_mm": float(r_mm[k]), "r95_deg": float(r_deg[k]), "normalised": float(z[k]),
               "extrapolated": flags[k][0], "calibration": flags[k][1]}
              for k in range(len(q))]
    return {"points": points, "n_points": len(points), "share_beyond_95": float(np.mean(beyond)),
            "max_normalised": float(z.max()), "max_difference_mm": float(np.max(np.linalg.norm(e[:, :3], axis=1)) * 1e3),
            "how": "tool pose of B minus A at each joint set (first order through the compared parameters; both base "
                   "frames registered on the calibration poses of both runs), its predicted 95 % radius from C_A + C_B, "
                   "normalised: sqrt(e^T C^-1 e) of the position (about 1.6 on average, above 2.8 at 5 % of the points "
                   "when nothing changed)"}


def compare_results(a, b, out_dir=None, level: float = LEVEL) -> dict:
    """Compare result folders a and b (module docstring); writes DIR/compare.json and DIR/report.html (atomic) when
    out_dir is given; returns compare.json's content (``decision.consistent``: False when they differ)."""
    ra, rep_a, fa = _load(a, "A")
    rb, rep_b, fb = _load(b, "B")
    check_same_robot(ra, rb, fa, fb)
    names, left = compared_parameters(ra, rb)
    if not names:
        raise DataError(f"A {fa} and B {fb}: no robot parameter is identified in both (nothing to compare)")
    ia = [ra.names.index(n) for n in names]
    ib = [rb.names.index(n) for n in names]
    d = rb.x[ib] - ra.x[ia]
    S = ra.covariance[np.ix_(ia, ia)] + rb.covariance[np.ix_(ib, ib)]
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(S))):
        raise DataError(f"A {fa} and B {fb}: parameter values or covariances not finite")
    test = parameter_test(names, d, S, level)
    for r, i, j in zip(test["rows"], ia, ib):
        r |= {"a": float(ra.x[i]), "b": float(rb.x[j]), "difference": float(rb.x[j] - ra.x[i]),
              "std_a": float(np.sqrt(ra.covariance[i, i])), "std_b": float(np.sqrt(rb.covariance[j, j])),
              "kind": "angle" if _is_angle(ra, r["name"]) else "length"}
    amap = _map_points(ra, rb, rep_a, rep_b, names, d, S)
    differ = test["differ"]
    why = (f"chi-square {test['chi2']:.4g} on {test['dof']} parameters, p = {test['chi2_p']:.3g}; smallest Bonferroni "
           f"p of one parameter moved {test['min_p_bonferroni']:.3g} (level {level:g} each)")
    out = {
        "format": FORMAT, "kind": "compare",
        "a": str(fa), "b": str(fb),
        "robot": {"kind": ra.model.kind, "name": getattr(ra.model.nominal_robot, "name", None)},
        "level": level,
        "decision": {"consistent": not differ, "why": why,
                     "moved": test["moved"]},
        "parameters": {"compared": test["rows"], "not_compared": left, "chi2": test["chi2"], "dof": test["dof"],
                       "chi2_p": test["chi2_p"], "min_p_bonferroni": test["min_p_bonferroni"],
                       "how": "d = x_B - x_A on the robot parameters identified in both (mounts and the parameters "
                              "carrying a mount parameter left out), S = C_A + C_B; chi2 = d^T S^+ d on rank(S) "
                              "degrees of freedom; z = d_i / sqrt(S_ii); shift_z: the z of parameter i alone moved, "
                              "(S^+ d)_i / sqrt((S^+)_ii), p Bonferroni-corrected over the parameters; moved: "
                              "forward selection of single-parameter shifts (each given those before it) while "
                              "significant, moved_by: their joint estimate"},
        "map": amap,
        "tcp_m": list(rep_a["accuracy_map"].get("tcp_m") or [0.0, 0.0, 0.0]),
        "notes": _notes(rep_a, rep_b),
    }
    out["summary_text"] = summary_text(out)
    if out_dir is not None:
        write_compare(out_dir, out)
    return out


def _is_angle(robot, name) -> bool:
    kinds = dict(zip(robot.model.nominal_robot.params.names, robot.model.nominal_robot.params.kinds))
    return kinds.get(name) == "angle"


def _notes(rep_a, rep_b) -> list[str]:
    notes = []
    ta, tb = rep_a["accuracy_map"].get("tcp_m"), rep_b["accuracy_map"].get("tcp_m")
    if ta != tb:
        notes.append(f"the maps' tool points differ (A {ta}, B {tb}): A's is used for both")
    return notes


def _value(r: dict, key: str) -> str:
    v = r[key]
    return f"{np.degrees(v):+.5f} deg" if r.get("kind") == "angle" else f"{v * 1e3:+.4f} mm"


def summary_text(out: dict) -> str:
    p, m, dec = out["parameters"], out["map"], out["decision"]
    lines = [f"compare: {'CONSISTENT' if dec['consistent'] else 'DIFFER'} ({dec['why']})",
             f"A {out['a']}", f"B {out['b']}",
             f"parameters compared: {len(p['compared'])}; left out: {len(p['not_compared'])}"
             + (" (" + "; ".join(f"{r['name']}: {r['why']}" for r in p["not_compared"][:4]) + ")"
                if p["not_compared"] else "")]
    moved = [r for nm in dec["moved"] for r in p["compared"] if r["name"] == nm]
    if moved:
        lines.append("moved (selected forward, each given those before): " + ", ".join(
            f"{r['name']} {_value(r, 'moved_by')} +- {_value(r, 'moved_by_std').lstrip('+')}"
            + (f" (or, as well explained here: {', '.join(r['or'])})" if r.get("or") else "") for r in moved))
    rows = sorted(p["compared"], key=lambda r: -abs(r["shift_z"]) if np.isfinite(r["shift_z"]) else 0)[:5]
    lines.append("largest shift z: " + ", ".join(f"{r['name']} {_value(r, 'difference')} (z {r['z']:+.2f}, shift z "
                                                 f"{r['shift_z']:+.2f})" for r in rows))
    lines.append(f"tool map: {m['n_points']} joint sets, largest difference {m['max_difference_mm']:.3g} mm, "
                 f"normalised difference above its 95 % value at {100 * m['share_beyond_95']:.0f} % of them "
                 f"(max {m['max_normalised']:.2f})")
    lines += [f"note: {n}" for n in out.get("notes", [])]
    return "\n".join(lines)


def write_compare(out_dir, out: dict) -> Path:
    """DIR/compare.json and DIR/report.html (each written atomically)."""
    from ..report.accuracy_map_page import compare_body
    from ..report.html import page
    from ..serialize import write_text_atomic

    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    title = "vision_calib compare: " + ("consistent" if out["decision"]["consistent"] else "differ")
    write_text_atomic(d / "report.html", page(title, compare_body(out)))
    return write_json_atomic(d / "compare.json", out)


__all__ = ["FORMAT", "LEVEL", "compare_results", "compared_parameters", "parameter_test", "summary_text",
           "moved_stepwise", "write_compare"]
