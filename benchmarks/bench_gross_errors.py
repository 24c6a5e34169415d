"""Figures behind experiment/gross.py's GROSS_CHI2_DOF = 1e3: chi2/dof of process-poses on clean RX-90 files, on
the same files with gross input errors (issue 21 cases 1 and 5), and on UR5e data with unmodelled periodic joint
transmission errors (model errors calibration is for). Prints one line per case: chi2/dof, verdict, failure kind.

    PYTHONPATH=. python benchmarks/bench_gross_errors.py [OUT_DIR]
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

from vision_calib import frames as F
from vision_calib.experiment.poses import process_poses
from vision_calib.experiment.steps import rngs, scene_truth
from vision_calib.io.measured_poses_writer import write_measured_poses
from vision_calib.rig import SCENES_DIR, load_scene, scene_poses

ST, SR = 1e-4, float(np.radians(0.02))


def files(out: Path) -> dict:
    rx = SCENES_DIR / "rx90_eye_in_hand.yaml"
    scene = load_scene(rx)
    x = scene_truth(scene)

    def data(n, seed):
        rp, rn, _ = rngs(seed)
        q = scene_poses(scene, rp, n)
        d = np.concatenate([rn.normal(scale=ST, size=(n, 3)), rn.normal(scale=SR, size=(n, 3))], axis=1)
        return q, F.perturb_pose(scene.setup.T_cam_target(q, x), d)

    def w(name, q, T, scene_path=rx):
        return write_measured_poses(out / name, scene_path, [f"p{i:03d}" for i in range(len(q))], q, T, "T_cam_target",
                                    sigmas=np.tile([ST] * 3 + [SR] * 3, (len(q), 1)), units={"length": "mm", "angle": "deg"})

    q, T = data(205, 1)
    cases = {"rx90 205 poses clean": w("clean.yaml", q, T), "rx90 205 direction reversed": w("rev.yaml", q, F.inv_T(T))}
    p = w("swap.yaml", q, T)
    c = p.with_suffix(".csv")
    lines = c.read_text().splitlines()
    lines[0] = lines[0].replace(",x,y,", ",y,x,")
    c.write_text("\n".join(lines) + "\n")
    cases["rx90 205 x/y columns swapped"] = p
    q, T = data(40, 2)
    cases["rx90 40 clean"] = w("clean40.yaml", q, T)
    cases["rx90 40 joint 1 negated"] = w("flip.yaml", q * [-1, 1, 1, 1, 1, 1], T)
    ur = SCENES_DIR / "ur5e_eye_in_hand.yaml"
    su = load_scene(ur)
    xu = scene_truth(su)
    for amp in (2e-3, 1e-2):
        rng = np.random.default_rng(3)
        qu = scene_poses(su, rng, 40)
        Tu = su.setup.T_cam_target(qu + amp * np.sin(2 * qu), xu)
        Tu = F.perturb_pose(Tu, rng.normal(size=(40, 6)) * np.array([ST] * 3 + [SR] * 3))
        cases[f"ur5e 40 transmission error {amp * 1e3:g} mrad x sin 2q"] = w(f"ur{amp}.yaml", qu, Tu, ur)
    return cases


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp())
    out.mkdir(parents=True, exist_ok=True)
    for what, path in files(out).items():
        rep = process_poses(path, out / f"out_{path.stem}", plots=False)
        v = rep["verdict"]
        print(f"{what:45s} chi2/dof {rep['adequacy']['chi2_dof']:10.4g}  verdict {v['status']:8s} "
              f"{v.get('failure', '')}")


if __name__ == "__main__":
    main()
