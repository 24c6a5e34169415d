"""Issue 32 item 3: honesty audit at the budgets users run, not the scenes' own settings.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_reduced_budget.py [--scenes h4,rx90,...] [--poses 12 15 20 30]
        [--frames 1 3] [--seeds 1 2 3 4 5 6] [--truth scene,new] [--workers 2]

Every cell (scene x poses x frames x truth) runs ``simulate`` in image mode (render + measure + identify, no
synthetic reference) once per seed, with the scene's own truth ("scene") and with a new true robot per seed
("new": the truth's seed set to the run's seed). Per cell it prints:

- ``written``: runs whose model would be written by ``process`` (the verdict is not failed, or failed only by the
  simulation's own check against the truth, which ``process`` cannot make);
- ``WORSE``: of those, the runs whose validation position or rotation RMS against the truth is worse after
  calibration than with the nominal model (the goal is 0: no exit-0 run writes a robot worse than nominal);
- ``WORSE registered``: the same with the validation positions compared after the best rigid transform of the
  model's positions onto the true ones (``Evaluation.position_rms_registered_mm``): a model that places its base
  frame elsewhere than the truth's convention (h4_unmodelled: model 12 on a model-31 robot, whose base frame is
  fixed by its first motor) is WORSE but not WORSE registered;
- ``val`` the median ratio validation position RMS after / before over the written runs;
- ``z RMS`` and ``max|z|``: z = (identified - true) / reported std over the free parameters with a true value, all
  runs of the cell pooled (written or not: a refused run's std are still printed);
- ``alarms``: runs whose verdict is a warning or a refusal other than the truth check (false alarms where the
  model holds; on h4_unmodelled they are expected);
- ``errors``: runs that stopped with an error (exit 2: e.g. too few poses to identify), named below the table.

A scene whose identification poses are a fixed configuration set (the thesis scenes: 10 joint sets) is run at
these budgets with poses drawn by its random sampler (around ``poses.center`` within ``poses.spread``, the target
in view), marked "(random)".
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import argparse
import dataclasses
import time

import numpy as np

from vision_calib.errors import VisionCalibError
from vision_calib.experiment.simulate import run_simulation
from vision_calib.rig import load_scene

SCENES = {"h4": "scenes/h4_vision.yaml", "h4_unmodelled": "scenes/h4_unmodelled.yaml",
          "rx90": "scenes/rx90_eye_in_hand.yaml", "ur5e": "scenes/ur5e_eye_in_hand.yaml",
          "ur5e_cell": "scenes/ur5e_cell.yaml", "thesis_eih": "scenes/thesis_arm_eye_in_hand.yaml",
          "thesis_tripod": "scenes/thesis_arm_tripod_probe.yaml"}
TRUTH_KIND = "validation against the truth"


def one_run(scene, seed: int, poses: int, frames: int, workers: int) -> dict:
    """One simulate run summarised: written (by process' rules), worse than nominal, z, verdict."""
    rep = run_simulation(scene, seed=seed, n_poses=poses, frames=frames, workers=workers, plots=False,
                         reference=False)
    v = rep["verdict"]
    failure = rep.get("failure") or {}
    written = v["status"] != "failed" or failure.get("kind") == TRUTH_KIND
    b, a = rep["accuracy"]["before"], rep["accuracy"]["after"]
    worse = any(k in a and k in b and np.isfinite(a[k]) and a[k] > b[k]
                for k in ("position_rms_mm", "rotation_rms_deg"))
    ps = [p for p in rep["parameters"] if p["free"] and p["true"] is not None and p["std"]]
    z = np.array([(p["identified"] - p["true"]) / p["std"] for p in ps], float)
    alarm = v["status"] == "warning" or (v["status"] == "failed" and failure.get("kind") != TRUTH_KIND)
    k = "position_rms_registered_mm"
    worse_reg = bool(k in a and k in b and np.isfinite(a[k]) and a[k] > b[k])
    return {"written": written, "worse": bool(written and worse), "worse_reg": bool(written and worse_reg),
            "z": z, "alarm": alarm,
            "ratio": a["position_rms_mm"] / b["position_rms_mm"] if b.get("position_rms_mm") else np.nan,
            "failure": failure.get("kind")}


def cell(path: str, poses: int, frames: int, truth: str, seeds, workers: int) -> dict:
    base = load_scene(path)
    sampled = base.poses.kind == "configurations"
    if sampled:  # the thesis scenes' fixed 10-configuration sets: the budget drawn by the scene's random sampler
        base = dataclasses.replace(base, poses=dataclasses.replace(base.poses, kind="random", configurations=None))
    rows, errors = [], []
    for s in seeds:
        sc = base if truth == "scene" else dataclasses.replace(base, truth=dataclasses.replace(base.truth, seed=int(s)))
        try:
            rows.append(one_run(sc, int(s), poses, frames, workers))
        except VisionCalibError as exc:  # exit 2 / 3 of the CLI: named, no model
            errors.append(f"seed {s}: {type(exc).__name__}: {str(exc)[:160]}")
    z = np.concatenate([r["z"] for r in rows]) if rows else np.zeros(0)
    written = [r for r in rows if r["written"]]
    return {"n": len(rows) + len(errors), "written": len(written), "worse": sum(r["worse"] for r in rows),
            "worse_reg": sum(r["worse_reg"] for r in rows),
            "val": float(np.nanmedian([r["ratio"] for r in written])) if written else np.nan,
            "z_rms": float(np.sqrt(np.mean(z ** 2))) if z.size else np.nan,
            "max_z": float(np.max(np.abs(z))) if z.size else np.nan,
            "alarms": sum(r["alarm"] for r in rows), "errors": errors,
            "failures": sorted({r["failure"] for r in rows if r["failure"]}), "sampled": sampled}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(SCENES), help="comma-separated keys of " + ", ".join(SCENES))
    ap.add_argument("--poses", type=int, nargs="+", default=[12, 15, 20, 30])
    ap.add_argument("--frames", type=int, nargs="+", default=[1, 3])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6])
    ap.add_argument("--truth", default="scene,new", help="scene, new or both (comma-separated)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    print("| scene | poses | frames | truth | runs | written | WORSE | WORSE registered | val after/before (median) "
          "| z RMS | max abs z | alarms | errors | refusals |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    notes, t0 = [], time.perf_counter()
    for key in args.scenes.split(","):
        for n in args.poses:
            for f in args.frames:
                for truth in args.truth.split(","):
                    c = cell(SCENES[key], n, f, truth, args.seeds, args.workers)
                    print(f"| {key} | {n}{' (random)' if c['sampled'] else ''} | {f} | {truth} | {c['n']} | {c['written']} | {c['worse']} | {c['worse_reg']} | {c['val']:.3g} | "
                          f"{c['z_rms']:.3g} | {c['max_z']:.3g} | {c['alarms']} | {len(c['errors'])} | "
                          f"{', '.join(c['failures']) or '-'} |", flush=True)
                    notes += [f"{key} {n}x{f} {truth}: {e}" for e in c["errors"]]
    for line in notes:
        print("error:", line)
    print(f"seeds {args.seeds}; {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
