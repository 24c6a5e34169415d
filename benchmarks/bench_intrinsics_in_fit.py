"""Intrinsics calibrated from the recording, their uncertainty in the fit: per seed, ref (true intrinsics)
and out (intrinsics calibrated from the recording) runs of the RX-90 eye-in-hand scene; prints adequacy chi2/dof + verdict, rejected poses, and z = (identified - true)/std of the
free parameters vs the simulation truth (sim/report.json); ~1 min per seed.

    PYOPENGL_PLATFORM=egl EGL_PLATFORM=surfaceless PYTHONPATH=. python benchmarks/bench_intrinsics_in_fit.py 3 4 5 6 7 8
"""
import sys, shutil, yaml, json, numpy as np, tempfile
from pathlib import Path
from vision_calib.experiment.simulate import run_simulation
from vision_calib.experiment.process import process_folder


def zs(rep, truth):
    z = []
    for p in rep["parameters"]:
        t = truth.get(p["name"])
        if p["free"] and t is not None and p["std"]:
            z.append((p["identified"] - t) / p["std"])
    return np.array(z)


def line(tag, seed, rep, truth):
    a = rep.get("adequacy") or {}
    z = zs(rep, truth)
    print(f"seed {seed} {tag}: chi2/dof {a.get('chi2_dof'):.3f} band {np.round(a.get('expected_chi2_dof'), 3).tolist()} "
          f"{a.get('verdict')} status {rep['verdict']['status']} rejected {len(rep.get('outliers', []))} prop {(rep['intrinsics'].get('propagated') or {}).get('n_directions')} | z: n {z.size} rms {np.sqrt(np.mean(z**2)):.2f} "
          f"max|z| {np.max(np.abs(z)):.2f}", flush=True)
    return z


if __name__ == "__main__":
    allz = {"ref": [], "out": []}
    for seed in [int(s) for s in sys.argv[1:]]:
        d = Path(tempfile.mkdtemp())
        run_simulation("scenes/rx90_eye_in_hand.yaml", out_dir=d / "sim", seed=seed, n_poses=24, frames=1,
                       export_recording=d / "rec", workers=2, plots=False)
        sim = json.loads((d / "sim" / "report.json").read_text())
        truth = {p["name"]: p["true"] for p in sim["parameters"]}
        ref = process_folder(d / "rec", d / "ref", plots=False)
        shutil.copytree(d / "rec", d / "rec2")
        doc = yaml.safe_load((d / "rec2" / "recording.yaml").read_text()); doc["camera"] = {"width": 1024}
        (d / "rec2" / "recording.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
        out = process_folder(d / "rec2", d / "out", plots=False)
        allz["ref"].append(line("ref", seed, ref, truth))
        allz["out"].append(line("out", seed, out, truth))
        shutil.rmtree(d, ignore_errors=True)
    for k, v in allz.items():
        z = np.concatenate(v)
        print(f"ALL {k}: n {z.size} RMS z {np.sqrt(np.mean(z**2)):.2f} max|z| {np.max(np.abs(z)):.2f}")
