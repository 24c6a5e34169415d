"""Power and false-alarm rate of the lack-of-fit tests (identify/lack_of_fit.py, issue 16 item 5).

    .venv/bin/python benchmarks/bench_lack_of_fit.py [--seeds 10] [--clean-seeds 100] [--amplitudes 0 0.005 ... 0.3]
                                                     [--image-seeds 0] [--image-amplitudes 0 0.005 0.01 0.02]
                                                     [--image-clean-seeds 0]

Synthetic mode (run_synthetic, the scene's pose noise): the RX-90 (scenes/rx90_eye_in_hand.yaml) with an
error the model lacks, A sin(2 q2 + phi) [deg] added to the TRUE joint 2 that moves the robot (the
reported joint stays the commanded one; phi uniform per seed), for each amplitude A over --seeds seeds.
Printed per A: how often the lack-of-fit test flags (any group, family-wise level 0.01) and names joint 2,
how often the global chi-square test says "too large", the max |z| of the parameters (identified - true) /
std (median and max over seeds), and the amplitude the test estimates (best harmonic order, median).
Then the false-alarm rate on clean synthetic runs of the RX-90, UR5e (scenes/ur5e_eye_in_hand.yaml) and H4
(scenes/h4_vision.yaml) over --clean-seeds seeds, and the KS test of the group p-values against uniform.
--image-seeds N: the same table in image mode (simulate: rendering, detection, PnP; N seeds per amplitude).
--image-clean-seeds N: false alarms of image-mode runs of the three scenes as shipped (the H4 scene's truth has
mount tilts and its chi-square already fails: not a clean case).
The "detectable A" columns: the amplitude the joint-2 group test flags with probability 0.8 at the best and
the worst phase, and the oracle's (a 1-dof test of the exactly known shape and phase at level 0.01, no
Bonferroni): no test on these residuals detects less.
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import argparse
import dataclasses
import time

import numpy as np

from vision_calib.experiment.steps import lack_of_fit_of, shared_truth
from vision_calib.experiment.synthetic import run_synthetic
from vision_calib.identify import model_adequacy
from vision_calib.rig import load_scene
from vision_calib.rig.serial import SerialSetup

RX90 = "scenes/rx90_eye_in_hand.yaml"
CLEAN = ("scenes/rx90_eye_in_hand.yaml", "scenes/ur5e_eye_in_hand.yaml", "scenes/h4_vision.yaml")


@dataclasses.dataclass(frozen=True)
class JointErrorTruth(SerialSetup):
    """The true arm: its joint ``joint`` (0-based) moves to q + amp_rad sin(order q + phase_rad) when
    commanded/reported at q (joints() stays the reported value): an error the identified model lacks."""

    joint: int = 1
    amp_rad: float = 0.0
    phase_rad: float = 0.0
    order: int = 2

    @classmethod
    def of(cls, setup: SerialSetup, **kw) -> "JointErrorTruth":
        return cls(**{f.name: getattr(setup, f.name) for f in dataclasses.fields(setup)}, **kw)

    def true_joints(self, poses) -> np.ndarray:
        q = np.array(poses, float)
        q[:, self.joint] += self.amp_rad * np.sin(self.order * q[:, self.joint] + self.phase_rad)
        return q

    def T_cam_target(self, poses, x):
        return super().T_cam_target(self.true_joints(poses), x)


def max_z(run) -> float:
    """max over the free parameters shared with the truth of |identified - true| / std."""
    res = run.result
    xt = shared_truth(run.setup, run.truth or run.scene.setup, run.x_true)
    ok = np.asarray(res.free, bool) & np.isfinite(xt) & np.isfinite(res.std)
    return float(np.max(np.abs(res.identified[ok] - xt[ok]) / res.std[ok]))


def detectable(lof) -> tuple[float, float, float]:
    """(best-phase, worst-phase detectable amplitude [deg] of A sin(2 q2 + phase) by the joint-2 group test,
    and the oracle's: a 1-dof test of the known shape at the plain level 0.01, best phase) of a lack_of_fit dict."""
    from vision_calib.identify.lack_of_fit import detectable_noncentrality

    g2 = next(g for g in lof["groups"] if g["name"] == "joint 2")
    best, worst = next(h for h in g2["harmonics"] if h["order"] == 2)["detectable_amplitude_deg"]
    lam = detectable_noncentrality(g2["dof"], lof["dof_residual"], lof["p_threshold"])
    lam1 = detectable_noncentrality(1, lof["dof_residual"], lof["level"])
    best, worst = (np.nan if v is None else v for v in (best, worst))  # None: the test sees nothing of that phase
    return best, worst, best * np.sqrt(lam1 / lam)


def one(scene, seed, amp_deg=0.0):
    """(lack-of-fit dict, adequacy verdict, max |z|) of one synthetic run."""
    truth = None
    if amp_deg:
        phase = np.random.default_rng([seed, 77]).uniform(0, 2 * np.pi)
        truth = JointErrorTruth.of(scene.setup, amp_rad=float(np.radians(amp_deg)), phase_rad=float(phase))
    run = run_synthetic(scene, seed=seed, truth=truth)
    lof = lack_of_fit_of(run.setup, run.measurements, run.problem, run.result)
    return lof, model_adequacy(run.result)["verdict"], max_z(run)


def power_table(amplitudes, seeds) -> None:
    scene = load_scene(RX90)
    print(f"RX-90 synthetic ({RX90}), error A sin(2 q2 + phi) on the true joint 2, {len(seeds)} seeds each")
    print(f"{'A deg':>7} {'flagged':>8} {'joint 2':>8} {'chi2 big':>8} {'max|z| med':>10} {'max|z| max':>10} "
          f"{'A est med (deg)':>15} {'A std med':>9} {'p med':>9}  detectable A (deg, median): best/worst phase, oracle")
    for a in amplitudes:
        flag = j2 = big = 0
        zs, amps, sds, ps, det = [], [], [], [], []
        for s in seeds:
            lof, adq, z = one(scene, s, a)
            flag += lof["significant"]
            g2 = next(g for g in lof["groups"] if g["name"] == "joint 2")
            j2 += g2["significant"]
            big += adq == "too large"
            zs.append(z)
            ps.append(g2["p_value"])
            best = next(h for h in g2["harmonics"] if h["order"] == 2)
            amps.append(best["amplitude_deg"])
            sds.append(best["amplitude_std_deg"])
            det.append(detectable(lof))
        n = len(seeds)
        d = np.nanmedian(np.array(det, float), axis=0)
        print(f"{a:7.3f} {flag:>4d}/{n:<3d} {j2:>4d}/{n:<3d} {big:>4d}/{n:<3d} {np.median(zs):10.2f} {np.max(zs):10.2f} "
              f"{np.median(amps):15.4f} {np.median(sds):9.4f} {np.median(ps):9.2g}  {d[0]:.4f}/{d[1]:.4f}, {d[2]:.4f}")


def false_alarms(scenes, seeds) -> None:
    from scipy.stats import kstest

    print(f"\nclean synthetic runs, {len(seeds)} seeds each: false alarms of the lack-of-fit test (level 0.01), "
          "KS test of the group p-values vs uniform")
    for path in scenes:
        scene = load_scene(path)
        t = time.perf_counter()
        flag, big, ps, names = 0, 0, [], []
        for s in seeds:
            lof, adq, _ = one(scene, s)
            flag += lof["significant"]
            big += adq == "too large"
            ps += [g["p_value"] for g in lof["groups"]]
            names += [g["name"] for g in lof["groups"] if g["significant"]]
        ps = np.array(ps, float)
        print(f"{path:32s} flagged {flag}/{len(seeds)}  (chi2 too large {big}/{len(seeds)})  group p < 0.05: "
              f"{np.mean(ps < 0.05):.3f} of {ps.size}  KS p {kstest(ps, 'uniform').pvalue:.2g}  "
              f"flagged terms {sorted(set(names)) or '-'}  ({time.perf_counter() - t:.0f} s)")


def image_runs(amplitudes, seeds) -> None:
    """Image-mode (simulate: rendering, detection, PnP) RX-90 with the joint-2 error: run_simulation takes its
    truth setup from ``steps.unmodelled_truth``, patched here to return the erring arm with the scene's x_true."""
    from unittest import mock

    import vision_calib.experiment.simulate as sim
    from vision_calib.experiment.steps import scene_truth

    base = load_scene(RX90)
    x_true = scene_truth(base)
    print(f"\nimage mode (simulate) RX-90, error A sin(2 q2 + phi) on the true joint 2, {len(seeds)} seeds each")
    print(f"{'A deg':>7} {'flagged':>8} {'joint 2':>8} {'verdict ok':>10} {'chi2 big':>8} {'max|z| med':>10} "
          f"{'max|z| max':>10} {'A est med (deg)':>15} {'A std med':>9} {'p med':>9}  detectable A (deg, median): "
          "best/worst phase, oracle")
    for a in amplitudes:
        flag = j2 = ok = big = 0
        zs, amps, sds, ps, other, det = [], [], [], [], [], []
        for s in seeds:
            phase = float(np.random.default_rng([s, 77]).uniform(0, 2 * np.pi))
            truth = JointErrorTruth.of(base.setup, amp_rad=float(np.radians(a)), phase_rad=phase) if a else None
            with mock.patch.object(sim, "unmodelled_truth", lambda scene: (truth, x_true if truth else None)):
                rep = sim.run_simulation(base, seed=s, plots=False, workers=2)
            lof = rep["lack_of_fit"]
            g2 = next(g for g in lof["groups"] if g["name"] == "joint 2")
            h2 = next(h for h in g2["harmonics"] if h["order"] == 2)
            flag += lof["significant"]
            j2 += g2["significant"]
            ok += rep["verdict"]["ok"]
            big += rep["adequacy"]["verdict"] == "too large"
            other += [g["name"] for g in lof["groups"] if g["significant"] and g["name"] != "joint 2"]
            zs.append(max(abs(p["identified"] - p["true"]) / p["std"] for p in rep["parameters"]
                          if p["free"] and p["true"] is not None and p["std"]))
            amps.append(h2["amplitude_deg"])
            sds.append(h2["amplitude_std_deg"])
            ps.append(g2["p_value"])
            det.append(detectable(lof))
        n = len(seeds)
        d = np.nanmedian(np.array(det, float), axis=0)
        print(f"{a:7.3f} {flag:>4d}/{n:<3d} {j2:>4d}/{n:<3d} {ok:>6d}/{n:<3d} {big:>4d}/{n:<3d} {np.median(zs):10.2f} "
              f"{np.max(zs):10.2f} {np.median(amps):15.4f} {np.median(sds):9.4f} {np.median(ps):9.2g}  "
              f"{d[0]:.4f}/{d[1]:.4f}, {d[2]:.4f}"
              + (f"  other terms flagged: {sorted(other)}" if other else ""))


def image_clean(scenes, seeds) -> None:
    """False alarms of the lack-of-fit test on image-mode (simulate) runs of the scenes as they are."""
    from vision_calib.experiment.simulate import run_simulation

    print(f"\nimage mode (simulate), the scenes as shipped, {len(seeds)} seeds each: lack-of-fit flags")
    for path in scenes:
        t = time.perf_counter()
        flag, big, terms = 0, 0, []
        for s in seeds:
            rep = run_simulation(path, seed=s, plots=False, workers=2)
            lof = rep["lack_of_fit"]
            flag += lof["significant"]
            big += rep["adequacy"]["verdict"] == "too large"
            terms += [g["name"] for g in lof["groups"] if g["significant"]] + (
                ["overall"] if (lof["overall"] or {}).get("significant") else [])
        print(f"{path:32s} flagged {flag}/{len(seeds)}  (chi2 too large {big}/{len(seeds)})  terms {sorted(terms) or '-'}"
              f"  ({time.perf_counter() - t:.0f} s)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--clean-seeds", type=int, default=100)
    ap.add_argument("--amplitudes", type=float, nargs="+", default=[0.0, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3])
    ap.add_argument("--image-seeds", type=int, default=0)
    ap.add_argument("--image-amplitudes", type=float, nargs="+", default=[0.0, 0.005, 0.01, 0.02])
    ap.add_argument("--image-clean-seeds", type=int, default=0, help="image-mode runs of the three scenes as shipped")
    a = ap.parse_args()
    if a.seeds:
        power_table(a.amplitudes, list(range(a.seeds)))
    if a.clean_seeds:
        false_alarms(CLEAN, list(range(a.clean_seeds)))
    if a.image_seeds:
        image_runs(a.image_amplitudes, list(range(a.image_seeds)))
    if a.image_clean_seeds:
        image_clean(CLEAN, list(range(a.image_clean_seeds)))


if __name__ == "__main__":
    main()
