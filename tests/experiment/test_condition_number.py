"""The condition number means one thing wherever it is printed: `simulate` and `process` of the same poses print the
same figure with what it is computed on (the Jacobian of the identifiable parameters at the nominal model over the
measured poses, whitened by their measured covariances, columns scaled by 1 mm / 1 mrad). The `identifiability`
command's planning figure of the same poses differs only by the weighting (no noise model), and says so."""

import json
import re

import numpy as np
import pytest

from vision_calib.cli import main
from vision_calib.experiment.steps import analyze_setup
from vision_calib.identify import analyze
from vision_calib.rig import SCENES_DIR, Measurements, load_scene

RX90 = SCENES_DIR / "rx90_eye_in_hand.yaml"
COND = re.compile(r"condition number (\S+) \(of the (.*)\)$", re.M)


def _cond_line(text: str):
    found = COND.findall(text)
    assert len(found) == 1, text
    return float(found[0][0]), found[0][1]


@pytest.mark.slow
def test_simulate_and_process_print_the_same_condition_number(tmp_path, capsys):
    assert main(["simulate", str(RX90), "--poses", "12", "--frames", "1", "--seed", "0", "--workers", "1",
                 "--no-plots", "--out", str(tmp_path / "sim"), "--export-recording", str(tmp_path / "rec")]) == 0
    sim_cond, sim_of = _cond_line(capsys.readouterr().out)
    assert main(["process", str(tmp_path / "rec"), "--no-plots", "--out", str(tmp_path / "proc")]) == 0
    proc_cond, proc_of = _cond_line(capsys.readouterr().out)
    assert f"{sim_cond:.3g}" == f"{proc_cond:.3g}" and sim_of == proc_of
    reports = [json.loads((tmp_path / d / "report.json").read_text())["identifiability"] for d in ("sim", "proc")]
    assert reports[0]["condition_number"] == pytest.approx(reports[1]["condition_number"], rel=1e-6)
    assert reports[0]["condition_number_of"] == reports[1]["condition_number_of"] == proc_of
    idf = reports[1]
    n_base = idf["n_params"] - len(idf["non_identifiable"])
    assert f"{n_base} identifiable parameters" in proc_of and "12 poses" in proc_of
    assert "covariances" in proc_of and "1 mm per length, 1 mrad per angle" in proc_of
    assert f"{proc_cond:.3g}" == f"{idf['condition_number']:.3g}"

    # the planning analysis of the same joints (`identifiability` command) weighs 1 mm like 1 mrad: another
    # figure, labelled so; the measured poses re-weighted that way give it back, so the weighting is the difference
    scene = load_scene(RX90)
    poses = np.loadtxt(tmp_path / "rec" / "poses.csv", delimiter=",", skiprows=1)[:, 1:]
    plan, _ = analyze_setup(scene.setup, poses, "pose")
    assert "unweighted" in plan.condition_of and "covariances" not in plan.condition_of
    assert plan.condition_number < proc_cond / 3  # measured image noise is anisotropic (depth, tilts)
    m = json.loads((tmp_path / "proc" / "measurements.json").read_text())
    kept = [p for p in m["poses"] if p["valid"]]
    assert len(kept) == len(poses)
    T = np.array([p["T_cam_target"] for p in kept])
    cov = np.array([p["cov"] for p in kept])
    measured = Measurements(poses, poses, T, cov, tuple(p["pose_id"] for p in kept))
    rep = analyze(scene.setup.problem(measured, "pose"), selection="order")
    assert rep.condition_number == pytest.approx(proc_cond, rel=2e-3)  # printed to 3 digits
    exact = scene.setup.synthetic_measurements(poses, scene.setup.params.nominal, np.random.default_rng(0))
    unweighted = Measurements(poses, poses, T, exact.cov, measured.labels)  # the planning analysis' covariances
    rep_u = analyze(scene.setup.problem(unweighted, "pose"), selection="order")
    assert rep_u.condition_number == pytest.approx(plan.condition_number, rel=1e-3)

