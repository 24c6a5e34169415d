"""Scale of images-mode studies on this machine (issue 18): printed, not asserted.

1. cost: per-run cost of a demo-size images run (H4 default scene, the 81-pose grid x 10 frames, plus its 50
   validation poses x 10 frames for V1/V2) as a study run (``study.run_cell``: the chain in this thread, built
   once) against the same poses x frames through ``simulate`` (``run_simulation``) on a started 1-worker
   ``ImagePool``: as shipped (with its 5-draw synthetic reference) and without the reference (the study run's
   work). Wall and CPU seconds per run (CPU = this process + the pool worker's chain CPU), same seeds.
2. scale: ``vision-calib study`` of R demo-size runs in a new interpreter (what a user runs) at ``--workers 1``,
   ``--workers 2``, and on a ``distributed.LocalCluster`` of 2 worker processes x 1 thread (the client in a new
   interpreter too): runs/hour over the whole command (start included) and steady (from the runs' file times,
   after each worker's first run), the 1 -> 2 worker speed-up, the projected hours of a 10,000-run study; the CPU
   seconds per run of the command and every process it waited for (workers included), and the cores it kept
   busy (CPU / wall): on a loaded machine the second worker gets less than a core.
3. memory: one spawned worker runs M small images runs (20 poses x 1 frame, 10 validation poses; seeds and noise
   vary) through ``run_cell``; its RSS after runs 1, 10, 50, 100, 150, M (flat = nothing accumulates per run).

Each scale configuration is measured ``--repeat`` times. Wall times and rates depend on the machine's load: the
load average (/proc/loadavg) is printed beside them; CPU seconds are robust to it.

    .venv/bin/python benchmarks/bench_study_scale.py [--reps 10] [--repeat 2] [--memory-runs 200]
                                                     [--parts cost,scale,memory]
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "h4_vision.yaml"
STAGES = ("render_cpu", "effects_cpu", "write_cpu", "measure_cpu")


def load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def write_spec(folder: Path, name: str, reps: int, scene=SCENE, settings=None, sweep=None) -> Path:
    p = folder / f"{name}.yaml"
    p.write_text(yaml.safe_dump({"name": name, "scene": str(scene), "mode": "images", "repetitions": reps,
                                 "seed": 0, "settings": settings or {}, "sweep": sweep or {}}, sort_keys=False))
    return p


# ----------------------------------------------------------------------------- 1. per-run cost
def cost(tmp: Path, runs: int) -> None:
    from vision_calib import study as S
    from vision_calib.experiment.image_chain import ImagePool
    from vision_calib.experiment.simulate import image_chain_of, run_simulation
    from vision_calib.rig import load_scene

    spec = S.load_study(write_spec(tmp, "cost", runs))
    seeds = [S.run_seed(spec.seed, r) for r in range(runs)]
    scene = load_scene(SCENE)
    out = {}
    with ImagePool(image_chain_of(scene), workers=1) as pool:
        run_simulation(scene, seed=12345, pool=pool)  # started and warm (worker imports, renderer, detectors)
        for label, ref in (("simulate, started pool, as shipped (+ synthetic reference)", True),
                           ("simulate, started pool, no reference (the study run's work)", False)):
            wall, cpu = [], []
            for s in seeds:
                t, c = time.perf_counter(), time.process_time()
                rep = run_simulation(scene, seed=s, pool=pool, reference=ref)
                wall.append(time.perf_counter() - t)
                cpu.append(time.process_time() - c + sum(rep["timings_s"].get(k, 0.0) for k in STAGES))
            out[label] = (wall, cpu)
    S.run_cell(spec, {}, runs + 7)  # this thread's chain built and warm, as in a worker after its first run
    wall, cpu = [], []
    for r in range(runs):
        t, c = time.perf_counter(), time.process_time()
        S.run_cell(spec, {}, r)
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    out["study run (run_cell, chain in this thread)"] = (wall, cpu)
    print(f"1. per-run cost, demo-size images run (81 poses x 10 frames + 50 validation poses x 10), {runs} runs "
          f"each, same seeds; load average {load()}")
    for label, (w, c) in out.items():
        print(f"   {label:62s} wall {np.mean(w):6.2f} s  CPU {np.mean(c):6.2f} s per run")
    sw, sc = out["study run (run_cell, chain in this thread)"]
    for label, (w, c) in list(out.items())[:2]:
        print(f"   study run / {label.split(', ', 2)[2]:45s}: CPU x{np.mean(sc) / np.mean(c):.3f}, "
              f"wall x{np.mean(sw) / np.mean(w):.3f}")


# ----------------------------------------------------------------------------- 2. throughput
_DASK = r"""
import json, sys, time
from distributed import Client, LocalCluster
from vision_calib.study import run_study
if __name__ == "__main__":
    t0 = time.time()
    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        res = run_study(sys.argv[1], sys.argv[2], scheduler=client, plots=False)
    print(json.dumps({"t0": t0, "n_computed": res["n_computed"]}))
"""


def _env():
    return {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
            "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


def _one_study(spec: Path, out: Path, how: str) -> dict:
    """Run the study in a new interpreter: wall of the command, and the run files' completion times."""
    if how == "dask":
        cmd = [sys.executable, "-c", _DASK, str(spec), str(out)]
    else:
        cmd = [sys.executable, "-m", "vision_calib.cli", "study", str(spec), "--out", str(out), "--workers", how,
               "--no-plots", "--json"]
    import resource

    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.time()
    p = subprocess.run(cmd, cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=3600)
    wall = time.time() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)  # the command and every process it waited for
    if p.returncode != 0:
        raise RuntimeError(f"{how}: exit {p.returncode}\n{p.stderr[-3000:]}")
    done = sorted(f.stat().st_mtime for f in (out / "runs").glob("*.json"))
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return {"wall": wall, "t0": t0, "done": done, "cpu": cpu}


def scale(tmp: Path, reps: int, repeat: int) -> None:
    spec = write_spec(tmp, "scale", reps)
    rows = []
    for k in range(repeat):
        for how, w in (("1", 1), ("2", 2), ("dask", 2)):
            la = load()
            r = _one_study(spec, tmp / f"scale_{how}_{k}", how)
            n = len(r["done"])
            steady = (n - w) / (r["done"][-1] - r["done"][w - 1]) * 3600 if n > w else float("nan")
            rows.append((how, k, n, r["wall"], n / r["wall"] * 3600, steady, la, r["cpu"]))
    print(f"2. throughput, {reps} demo-size images runs per study (one cell), a new interpreter per study; "
          f"steady = after each worker's first run")
    names = {"1": "--workers 1", "2": "--workers 2", "dask": "LocalCluster 2 proc x 1 thr"}
    for how, k, n, wall, rate, steady, la, cpu in rows:
        print(f"   {names[how]:28s} try {k + 1}: {n} runs in {wall:6.1f} s = {rate:6.0f} runs/h "
              f"(steady {steady:6.0f} runs/h); CPU {cpu / n:5.2f} s per run, start included, {cpu / wall:4.2f} cores "
              f"busy; load average before {la}")
    best = {how: max(r[5] for r in rows if r[0] == how) for how in names}
    whole = {how: max(r[4] for r in rows if r[0] == how) for how in names}
    print(f"   1 -> 2 local workers speed-up (best try each): steady x{best['2'] / best['1']:.2f}, "
          f"whole command x{whole['2'] / whole['1']:.2f}; Dask 2 workers vs local 1: x{best['dask'] / best['1']:.2f}")
    for how in ("2", "dask"):
        print(f"   projected wall time of a 10,000-run demo-size images study, {names[how]}: "
              f"{10000 / best[how]:.1f} h (steady rate, best try)")


# ----------------------------------------------------------------------------- 3. memory
def _rss_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _memory_worker(spec_path: str, n: int) -> list:
    from vision_calib.experiment.image_chain import study_worker_settings
    from vision_calib import study as S

    study_worker_settings()  # as a study worker runs
    spec = S.load_study(spec_path)
    cells = S.study_cells(spec)
    marks = {1, 10, 50, 100, 150, n}
    out = []
    t = time.perf_counter()
    for k in range(n):
        S.run_cell(spec, cells[k % len(cells)], k // len(cells))
        if k + 1 in marks:
            out.append((k + 1, _rss_mib(), time.perf_counter() - t))
    return out


def memory(tmp: Path, n: int) -> None:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    doc = yaml.safe_load(SCENE.read_text())
    doc["robot"] = str(SCENE.parent / doc["robot"])
    doc["target"] = str((SCENE.parent / doc["target"]).resolve())
    doc["validation"] = {"kind": "random", "count": 10}
    scene = tmp / "h4_small_validation.yaml"
    scene.write_text(yaml.safe_dump(doc, sort_keys=False))
    spec = write_spec(tmp, "memory", n, scene=scene, settings={"n_poses": 20, "frames": 1},
                      sweep={"noise_grey": [1.0, 8.0]})
    with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as ex:
        marks = ex.submit(_memory_worker, str(spec), n).result()
    print(f"3. memory of one study worker over {n} images runs (20 poses x 1 frame + 10 validation poses, noise "
          f"1 / 8 alternating, a new seed every 2 runs); load average {load()}")
    for k, rss, t in marks:
        print(f"   after run {k:4d}: RSS {rss:7.1f} MiB  ({t:6.1f} s)")
    print(f"   growth from run 10 to run {n}: {marks[-1][1] - marks[1][1]:+.1f} MiB")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=10, help="demo-size runs per throughput study")
    ap.add_argument("--repeat", type=int, default=2, help="tries of each throughput configuration")
    ap.add_argument("--cost-runs", type=int, default=3)
    ap.add_argument("--memory-runs", type=int, default=200)
    ap.add_argument("--parts", default="cost,scale,memory")
    a = ap.parse_args()
    parts = a.parts.split(",")
    print(f"{os.cpu_count()} CPUs; load average at start {load()}")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        if "cost" in parts:
            cost(tmp, a.cost_runs)
        if "scale" in parts:
            scale(tmp, a.reps, a.repeat)
        if "memory" in parts:
            memory(tmp, a.memory_runs)
    print(f"load average at end {load()}")


if __name__ == "__main__":
    main()
