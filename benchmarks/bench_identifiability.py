"""Identifiability figures of the shipped setups (what the seeds report, recomputed by our analysis):

- RX-90 with base + flange-side transforms: rank with full-pose and position-only residuals;
- the thesis' chapter-3 setup (flange position only, parameters l5, a, theta, d): a6 not identifiable;
- H4 model 12 + external parameters (paper: 19 of 20) and model 31 + externals (paper: 36);
- H4 fidelity to the paper (vision_calib/docs/h4_fidelity.md): table 1 (geometric parameters, nacelle pose
  known, 100 random poses) and table 3 (variants A-H with the external parameters, 71 of the 81
  grid poses) beside the paper's figures, under three column scalings; the parameter directions
  that limit the conditioning; the effect of d and of l, and how they change with the nominal
  geometry and the workspace.

    .venv/bin/python benchmarks/bench_identifiability.py          # everything
    .venv/bin/python benchmarks/bench_identifiability.py h4       # the H4 fidelity figures only
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import numpy as np

from vision_calib.experiment.steps import analyze_setup, rngs
from vision_calib.experiment.synthetic import identifiability_json
from vision_calib.rig import SCENES_DIR, load_scene, scene_poses
from vision_calib.study import scene_with

import sys
from dataclasses import replace

H4_FILE = SCENES_DIR / "robots" / "h4.yaml"
PAPER_T1 = {"model 12": 257, "model 31 without d": 421, "model 31 with d": 1900}
PAPER_T3 = dict(zip("ABCDEFGH", (115, 160, 116, 161, 187, 192, 194, 220)))
from vision_calib.identify import analyze
from vision_calib.identify.serial_problem import serial_problem
from vision_calib.kinematics import h4_variants  # noqa: E402
from vision_calib.kinematics.h4 import random_workspace_poses
from vision_calib.kinematics.h4_io import load_h4_robot
from vision_calib.kinematics.serial_file import load_serial_robot


def _line(label, out):
    print(f"{label}: {out['n_params']} parameters, rank {out['rank']}, cond {out['condition_number']:.4g}; "
          f"not identifiable: {', '.join(out['non_identifiable']) or 'none'}")


def serial_figures():
    for res in ("pose", "position"):
        _line(f"RX-90 eye-in-hand, {res} residuals (all parameters)",
              identifiability_json(SCENES_DIR / "rx90_eye_in_hand.yaml", residual=res, all_params=True))
    arm = load_serial_robot(SCENES_DIR / "robots" / "thesis_arm.yaml")
    names = ["l5"] + [f"{p}{i}" for p in ("a", "theta", "d") for i in range(1, 7)]
    for label, q in (("50 random joint sets", np.random.default_rng(2).uniform(-np.pi, np.pi, (50, 6))),
                     ("the thesis' 7 configurations", arm.meta["configurations"]["six_plus_one"]["q"])):
        T = arm.forward(q)
        problem = serial_problem(arm, q, T, residual="position", sigma_t_m=1e-3)
        # the thesis' parameter list keeps d2 and d3 both (redundant): the analysis must find it
        rep = analyze(problem.with_params(problem.params.only_free(names)), selection="order")
        print(f"thesis arm, chapter 3, flange position, {label}: {rep.n_params} parameters, rank {rep.rank}; "
              f"not identifiable: {', '.join(rep.non_identifiable)}")
        for c in rep.couplings:
            print(f"    {c['parameter']} ~ " + (" ".join(f"{v:+.3g}*{k}" for k, v in c["combination_si"].items())
                                              or "(no effect on the measurements)"))


def h4_figures():
    scene = load_scene(SCENES_DIR / "h4_vision.yaml")
    _line("H4 model 12 + 8 external parameters", identifiability_json(scene, all_params=True))
    s31 = scene_with(scene, model="31")
    rp, _, _ = rngs(0)
    rep, _ = analyze_setup(s31.setup, scene_poses(s31, rp), all_params=True)
    print(f"H4 model 31 + 8 external parameters: {rep.n_params} parameters, rank {rep.rank}; not identifiable: "
          f"{', '.join(rep.non_identifiable)}")
    for c in rep.couplings:
        print(f"    {c['parameter']} ~ " + " ".join(f"{v:+.3g}*{k}" for k, v in c["combination_si"].items()))


# ----------------------------------------------------------------------------- H4 fidelity to the paper
def scaled(J, how, scale=None):
    """Columns of J scaled: "SI" (m, rad as they are), "unit" (unit norm), "1mm" (by scale: 1 mm, 1 mrad)."""
    if how == "unit":
        return J / np.linalg.norm(J, axis=0)
    return J * scale if how == "1mm" else J


def cond_and_weakest(J, names, how="unit", scale=None, k=5):
    """Condition number of the scaled J and the k largest components of its last right singular vector."""
    _, s, Vt = np.linalg.svd(scaled(J, how, scale), full_matrices=False)
    v = Vt[-1] / np.abs(Vt[-1]).max()
    top = np.argsort(-np.abs(v))[:k]
    return s[0] / s[-1], " ".join(f"{v[i]:+.2f}*{names[i]}" for i in top)


def table1_rows(r12, X):
    """(label, robot, names, J (4N, k)) of table 1: geometric parameters, X known in B."""
    r31 = h4_variants.to_model31(r12)
    rows = (("model 12", r12, list(r12.names[:12])),
            ("model 31 without d", r31, [n for n in r31.names[:31] if n != "h4.d"]),
            ("model 31 with d", r31, list(r31.names[:31])))
    return [(lab, r, nm, r.igm_jacobian_params(X)[..., r.params.indices(nm)].reshape(-1, len(nm))) for lab, r, nm in rows]


def variant_jacobian(r12, letter, X):
    """Stacked d q / d (free parameters) of a table-2 variant, external parameters included."""
    r = h4_variants.variant(r12, letter)
    nm = r.params.free_names
    J = r.igm_from_camera_jacobian(r.camera_measurement(X))[..., r.params.indices(nm)].reshape(-1, len(nm))
    return r, nm, J


def h4_table1(r12):
    X = random_workspace_poses(100, np.random.default_rng(1))
    print("H4 table 1 (geometric parameters, nacelle pose known in B, 100 random poses): cond(J), by column scaling")
    print(f"    {'':<20} {'SI':>7} {'unit':>7} {'1mm':>7}  paper   weakest direction (unit columns)")
    out = {}
    for lab, r, nm, J in table1_rows(r12, X):
        sc = r.params.scale[r.params.indices(nm)]
        c = {h: cond_and_weakest(J, nm, h, sc)[0] for h in ("SI", "unit", "1mm")}
        out[lab] = c
        print(f"    {lab:<20} {c['SI']:7.0f} {c['unit']:7.0f} {c['1mm']:7.0f}  {PAPER_T1[lab]:5d}   "
              f"{cond_and_weakest(J, nm)[1]}")
    w, wo = out["model 31 with d"]["unit"], out["model 31 without d"]["unit"]
    print(f"    adding d multiplies cond by {w / wo:.2f} (unit columns; paper 1900/421 = {1900 / 421:.2f})")


def h4_table3(r12, label="nominal", verbose=True):
    """Table 3 analogue: 71 of the 81 grid poses (fixed draw), externals included, unit columns."""
    X = r12.pose_grid()[np.sort(np.random.default_rng(0).choice(81, 71, replace=False))]
    c = {}
    for L in "ABCDEFGH":
        r, nm, J = variant_jacobian(r12, L, X)
        c[L], weak = cond_and_weakest(J, nm)
        if verbose:
            c_si = cond_and_weakest(J, nm, "SI")[0]
            print(f"    {L} ({len(nm)} free): cond {c[L]:6.0f} unit, {c_si:6.0f} SI; paper {PAPER_T3[L]:4d}; weakest {weak}")
    print(f"    {label:<28} " + " ".join(f"{L}:{c[L]:5.0f}" for L in c)
          + f"   B/A {c['B'] / c['A']:.2f} (paper 1.39), D/C {c['D'] / c['C']:.2f} (1.39), H/D {c['H'] / c['D']:.2f} (1.37)")
    return c


def h4_geometry_sensitivity(r12):
    """Does another nominal geometry or workspace reproduce the paper's effects? cond ratios for d
    (our d, and a d acting as a common y shift of the four attachment points) and table 3."""
    X = random_workspace_poses(100, np.random.default_rng(1))
    print("H4 effect of d in table 1 (unit columns), by nominal geometry:")
    cases = (("nominal (DESIGN.md §4)", {}, {}), ("forearm l = 0.6 m", {"h4.l": 0.6}, {}), ("arm L = 0.4 m", {"h4.L": 0.4}, {}),
             ("motor radius R = 0.1 m", {"h4.R": 0.10}, {}), ("rod h = 0.05 m", {"h4.h": 0.05}, {}))
    for lab, kw, _ in cases:
        r = r12.with_values(r12.params.vector(kw)) if kw else r12
        rows = table1_rows(r, X)
        wo, w = (np.linalg.cond(scaled(J, "unit")) for _, _, _, J in rows[1:])
        r31 = rows[1][1]
        Jy = np.column_stack([rows[1][3], r31.igm_jacobian_pose(X)[..., 1].reshape(-1)])  # d as a common y shift
        print(f"    {lab:<24} model 31 without d {wo:6.0f}; with our d x{w / wo:.2f}; with a common-y-shift d "
              f"x{np.linalg.cond(scaled(Jy, 'unit')) / wo:.2f}   (paper x{1900 / 421:.2f})")
    print("H4 table 3 (unit columns) by nominal geometry and workspace (71 of the 81 grid poses):")
    big = dict(size=2.0 * r12.size, center=r12.center + np.array([0.0, 0.0, -0.05]))
    for lab, kw, ws in cases[1:4] + (("workspace 400x400x300 mm", {}, big),):
        r = replace(r12.with_values(r12.params.vector(kw)) if kw else r12, **ws)
        h4_table3(r, lab, verbose=False)


def h4_fidelity():
    r12 = load_h4_robot(H4_FILE)
    h4_table1(r12)
    print("H4 table 3 (variants A-H with the external parameters, 71 of the 81 grid poses):")
    h4_table3(r12, "nominal (DESIGN.md §4)")
    h4_geometry_sensitivity(r12)


if __name__ == "__main__":
    if sys.argv[1:] != ["h4"]:
        serial_figures()
        h4_figures()
    h4_fidelity()
