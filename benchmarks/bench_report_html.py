"""What report.html adds to a run: the demo (scenes/h4_vision.yaml, seed 0) run once with its plots, then, on its
report, the overlays (the worst poses rendered again from their seeds, detected, drawn; report/overlay.py) and the page
(report/html.py) timed (CPU and wall, best of --repeats), beside the run's own total as the baseline; sizes of
report.html and its overlay JPEGs.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python benchmarks/bench_report_html.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    from vision_calib.experiment.image_chain import overlay_frames
    from vision_calib.experiment.simulate import DEFAULT_SCENE, image_chain_of, run_simulation
    from vision_calib.experiment.steps import rngs, scene_truth
    from vision_calib.report.overlay import OverlaySource, build_overlays
    from vision_calib.report.html import report_html
    from vision_calib.rig import load_scene, scene_poses
    from vision_calib.targets import load_target

    out = Path(tempfile.mkdtemp(prefix="bench_report_html_"))
    t = time.perf_counter()
    rep = run_simulation(DEFAULT_SCENE, out, seed=0)
    print(f"demo run (report.html included): wall {time.perf_counter() - t:.2f} s; its timings_s.total "
          f"{rep['timings_s']['total']:.2f} s (before the report files)")
    scene = load_scene(DEFAULT_SCENE)
    chain = image_chain_of(scene)
    rp, _, _ = rngs(0)
    T = scene.setup.T_cam_target(scene_poses(scene, rp, rep["settings"]["poses"]), scene_truth(scene))
    labels = [f"{i:03d}" for i in range(len(T))]
    src = OverlaySource(lambda ids: overlay_frames(chain, T, labels, 0, rep["settings"]["frames"], ids),
                        load_target(scene.target_path), chain.camera, None)
    best = {"overlays": (1e9, 1e9), "page": (1e9, 1e9)}
    for _ in range(args.repeats):
        c, w = time.process_time(), time.perf_counter()
        ov = build_overlays(rep, src)
        c1, w1 = time.process_time(), time.perf_counter()
        page = report_html(rep, out, ov)
        c2, w2 = time.process_time(), time.perf_counter()
        best = {"overlays": min(best["overlays"], (c1 - c, w1 - w)), "page": min(best["page"], (c2 - c1, w2 - w1))}
    for k, (c, w) in best.items():
        print(f"{k}: CPU {c:.3f} s, wall {w:.3f} s (best of {args.repeats})")
    print(f"overlays: {len(ov)} poses ({', '.join(o['role'] for o in ov)}), JPEG kB "
          + ", ".join(f"{len(o['jpeg']) / 1e3:.1f}" for o in ov if o["jpeg"]))
    print(f"report.html: {len(page.encode()) / 1e3:.0f} kB (written: {(out / 'report.html').stat().st_size / 1e3:.0f} "
          f"kB), plots: " + ", ".join(f"{p.name} {p.stat().st_size / 1e3:.0f} kB" for p in sorted(out.glob('*.png'))))


if __name__ == "__main__":
    main()
