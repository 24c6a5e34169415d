"""Are the reported std right on data the model does not share? Image-mode z-scores of the identified
parameters over several seeds (issue 8): z = (identified - true) / reported std, per free parameter.

    .venv/bin/python benchmarks/bench_zscores.py [--scene scenes/h4_vision.yaml] [--seeds 1 2 3 4 5]
                                                 [--poses N] [--frames F]

Prints per seed the chi2/dof, the variance factor, z RMS and max |z|, and over all seeds z RMS per
parameter and overall. Target: RMS z within 0.7-1.5 and no |z| > 4.
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import argparse

import numpy as np

from vision_calib.experiment.simulate import run_simulation


def zscores(scene: str, seeds, poses=None, frames=None, workers=2) -> dict:
    """{seed: (names, z (n,), chi2/dof, variance factor)} of image-mode runs of ``scene``."""
    out = {}
    for seed in seeds:
        rep = run_simulation(scene, seed=seed, n_poses=poses, frames=frames, workers=workers, plots=False)
        ps = [p for p in rep["parameters"] if p["free"] and p["true"] is not None and p["std"]]
        z = np.array([(p["identified"] - p["true"]) / p["std"] for p in ps])
        out[seed] = ([p["name"] for p in ps], z, rep["adequacy"]["chi2_dof"], rep["variance_factor"])
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="scenes/h4_vision.yaml")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    ap.add_argument("--poses", type=int, default=None)
    ap.add_argument("--frames", type=int, default=None)
    args = ap.parse_args(argv)
    res = zscores(args.scene, args.seeds, args.poses, args.frames)
    allz = []
    for seed, (names, z, c, f) in res.items():
        allz.append(z)
        print(f"seed {seed}: chi2/dof {c:.3g}, variance factor {f:.3g}, z RMS {np.sqrt(np.mean(z**2)):.2f}, "
              f"max |z| {np.max(np.abs(z)):.2f} ({names[int(np.argmax(np.abs(z)))]})")
    Z = np.array(allz)
    names = res[args.seeds[0]][0]
    per = np.sqrt(np.mean(Z**2, axis=0))
    print(f"over {len(args.seeds)} seeds: z RMS {np.sqrt(np.mean(Z**2)):.2f}, max |z| {np.max(np.abs(Z)):.2f}; "
          f"per-parameter z RMS from {per.min():.2f} ({names[int(np.argmin(per))]}) to {per.max():.2f} "
          f"({names[int(np.argmax(per))]})")


if __name__ == "__main__":
    main()
