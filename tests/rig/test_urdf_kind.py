"""The URDF robot kind end to end: simulate images of the shipped UR5e scene, export the recording,
process it back; the calibrated robot is written as URDF too and loads back."""

import json

import numpy as np
import pytest

from vision_calib.experiment.process import process_folder
from vision_calib.experiment.simulate import run_simulation
from vision_calib.io.model_export import load_calibrated_model
from vision_calib.kinematics.urdf import load_urdf_robot
from vision_calib.rig import SCENES_DIR, load_scene

pytestmark = pytest.mark.slow
SCENE = SCENES_DIR / "ur5e_eye_in_hand.yaml"


def test_ur5e_scene_is_a_urdf_kind_with_30_base_parameters():
    from vision_calib.experiment.synthetic import identifiability_json

    sc = load_scene(SCENE)
    assert sc.kind == "urdf" and sc.setup.chain.n_joints == 6
    out = identifiability_json(SCENE)
    assert out["n_params"] == 54 and out["rank"] == 30


def test_ur5e_simulate_export_process(tmp_path):
    rep = run_simulation(SCENE, out_dir=tmp_path / "sim", seed=2, n_poses=16, frames=2,
                         export_recording=tmp_path / "rec", workers=2)
    assert rep["verdict"]["converged"] and rep["measurements"]["n_valid"] == 16
    b, a = rep["accuracy"]["before"], rep["accuracy"]["after"]
    assert a["position_rms_mm"] < 0.3 * b["position_rms_mm"]
    files = json.loads((tmp_path / "sim" / "report.json").read_text())["files"]
    assert files["urdf"] == "calibrated_model.urdf"
    # the calibrated URDF (joint origins changed only) + the identified mounts = the calibrated chain
    calibrated = load_calibrated_model(tmp_path / "sim" / "calibrated_model.yaml")
    urdf = load_urdf_robot(tmp_path / "sim" / "calibrated_model.urdf", "base_link", "tool0",
                           *calibrated.mount_names, *calibrated.nominal_transforms())
    q = load_scene(SCENE).setup.sample_poses(np.random.default_rng(0), 5, check_view=False)
    np.testing.assert_allclose(urdf.forward(q), calibrated.forward(q), atol=1e-9)
    out = process_folder(tmp_path / "rec", tmp_path / "proc")
    sim = {p["name"]: p["identified"] for p in rep["parameters"]}
    for p in out["parameters"]:
        assert abs(p["identified"] - sim[p["name"]]) <= 1e-9 * max(1.0, abs(sim[p["name"]])), p["name"]
