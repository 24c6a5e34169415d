"""Validation position error of the H4 demo scene with an unmodelled camera/target tilt in the truth.

Per seed: RMS validation position error [mm] after calibration for
  no-tilt   : truth without tilt (tilt mode "identify", which then measures ~0)
  no-axis   : truth tilts drawn (std --tilt-deg), nominal tilts kept (tilt_mode "off")
  axis      : tilts measured from the rotation axis, then fixed (paper §4.1, tilt_mode "axis")
  identified: axis values as initial values, camera tilts identified (tilt_mode "identify", the default)
plus the error of the estimated camera tilt vs the truth [deg] (axis-only and identified).
Image mode (render + detect + PnP; --poses / --frames subsets to save time) and synthetic mode
(pose noise from the scene). Ratios are to the no-tilt case of the same seed and mode.

    PYTHONPATH=. python benchmarks/bench_tilt.py [--seeds 0 1 2] [--poses 81] [--frames 10] [--no-image]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vision_calib.experiment.synthetic import run_synthetic  # noqa: E402
from vision_calib.kinematics.h4 import TILT_NAMES  # noqa: E402
from vision_calib.rig import load_scene  # noqa: E402

import vision_calib.experiment.simulate as _sim  # noqa: E402

_render = _sim._render_and_measure
_CACHE: dict = {}


def _cached_render(scene, chain, T_true, q_true, poses, seed, frames, *rest):
    """The tilt modes only change the identification: render and measure each truth once."""
    key = (T_true.tobytes(), seed, frames)
    if key not in _CACHE:
        _CACHE[key] = _render(scene, chain, T_true, q_true, poses, seed, frames, *rest)
    return _CACHE[key]


_sim._render_and_measure = _cached_render

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "h4_vision.yaml"
MODES = ("off", "axis", "identify")
#: "no tilt": tilts drawn at ~1e-11 rad, so that the truth's other deviations (drawn from the same random
#: stream as with tilts) are those of the tilted runs: the comparison is then tilt vs no tilt only
NO_TILT = 1e-9


def scene_with(tilt_deg: float, mode: str):
    sc = load_scene(SCENE)
    unm = {k: v for k, v in sc.truth.unmodelled.items() if k != "tilt_deg"}
    unm.pop("model", None)  # only the tilt is studied here: the truth model is the identified one
    if tilt_deg > 0:
        unm["tilt_deg"] = tilt_deg
    # the deviations of the scene before its demo truth got per-chain errors (1 mm, 0.2 deg per parameter)
    sc = replace(sc, truth=replace(sc.truth, unmodelled=unm, sigma_length_m=1e-3, sigma_angle_rad=np.radians(0.2)))
    return sc.with_setup(replace(sc.setup, tilt_mode=mode))


def cam_tilt_err(out) -> float:
    """Max |model value - true| [deg] of the camera tilts after identification (NaN if absent); out: an
    image report (dict) or a SyntheticRun."""
    if not isinstance(out, dict):
        ps, tv = out.setup.params, out.truth.params.values(out.x_true)
        e = [abs(out.result.identified[ps.index(n)] - tv[n]) for n in TILT_NAMES[:2] if n in ps.names]
        return float(np.degrees(max(e))) if e else float("nan")
    rows = {r["name"]: r for r in out["parameters"]}
    e = [abs(rows[n]["identified"] - rows[n]["true"]) for n in TILT_NAMES[:2] if n in rows and rows[n].get("true")
         is not None]
    return float(np.degrees(max(e))) if e else float("nan")


def image_run(tilt, mode, seed, poses, frames):
    rep = _sim.run_simulation(scene_with(tilt, mode), seed=seed, n_poses=poses, frames=frames, plots=False)
    acc = rep["accuracy"]["after"]
    return acc["position_rms_mm"], rep


def synthetic_run(tilt, mode, seed, poses):
    sc = scene_with(tilt, mode)
    out = run_synthetic(sc, seed=seed, n_poses=poses, prepare=True)
    return out.after.to_dict()["position_rms_mm"], out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--poses", type=int, default=None, help="random subset of the 81-pose grid")
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--tilt-deg", type=float, default=0.5)
    ap.add_argument("--no-image", action="store_true")
    a = ap.parse_args(argv)
    runs = [("synthetic", synthetic_run)] + ([] if a.no_image else [("image", image_run)])
    for name, fn in runs:
        print(f"{name} mode: validation position RMS [mm] (ratio to no-tilt/identify), tilt std {a.tilt_deg} deg")
        print(f"{'seed':>4} {'no-tilt/off':>11} {'no-tilt/identify':>16} {'tilt/no-axis':>15} {'tilt/axis':>15} "
              f"{'tilt/identified':>15}  cam-tilt err axis / identified [deg]")
        for s in a.seeds:
            args = (s, a.poses) if name == "synthetic" else (s, a.poses, a.frames)
            e00 = fn(NO_TILT, "off", *args)[0]
            e0 = fn(NO_TILT, "identify", *args)[0]
            res = [fn(a.tilt_deg, m, *args) for m in MODES]
            errs = [cam_tilt_err(r[1]) for r in res[1:]]
            print(f"{s:>4} {e00:11.3f} {e0:16.3f} " + " ".join(f"{r[0]:8.3f} ({r[0] / e0:4.1f})" for r in res)
                  + f"  {errs[0]:.4f} / {errs[1]:.4f}", flush=True)


if __name__ == "__main__":
    main()
