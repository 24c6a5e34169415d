"""Bad user input gives one line and exit 2, never a traceback; the calibrated model round-trips."""

import subprocess
import sys

import numpy as np
import pytest

from vision_calib.rig import SCENES_DIR, load_scene
from vision_calib.study import scene_with
from vision_calib.io.model_export import load_calibrated_model, write_calibrated_model


@pytest.mark.parametrize("args,needle", [
    (["identifiability", "scenes/h4_vision.yaml", "--poses", "-3"], "--poses"),
    (["identify-synthetic", "scenes/h4_vision.yaml", "--seed", "-1"], "--seed"),
    (["identify-synthetic", "scenes/rx90_eye_in_hand.yaml", "--sigma-mm", "-0.1"], "--sigma-mm"),
    (["identify-synthetic", "scenes/rx90_eye_in_hand.yaml", "--method", "igm"], "igm"),
    (["identifiability", "scenes/h4_vision.yaml", "--poses", "200"], "the grid has 81"),
])
def test_bad_arguments(args, needle):
    r = subprocess.run([sys.executable, "-m", "vision_calib.cli", *args], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    last = r.stderr.strip().splitlines()[-1]  # argparse prints its usage lines first
    assert last.startswith("vision-calib") and needle in last


@pytest.mark.parametrize("bad,needle", [
    ("measurement:\n  sigma_mm: -0.1\n", "measurement.sigma_mm"),
    ("truth: {seed: -11}\n", "truth.seed"),
    ("truth: {deviations: {h4.L: abc}}\n", "truth.deviations.h4.L"),
    ("poses: {kind: grid81, count: 2.5}\n", "poses.count"),
    ("key: [unclosed\n", "invalid YAML"),
])
def test_bad_scene_values(tmp_path, bad, needle):
    text = (SCENES_DIR / "h4_vision.yaml").read_text()
    text = text.replace("robot: robots/h4.yaml", f"robot: {SCENES_DIR / 'robots/h4.yaml'}")
    text = text.replace("target: ../targets/charuco_h4.yaml", f"target: {SCENES_DIR.parent / 'targets/charuco_h4.yaml'}")
    # a repeated top-level key replaces the scene's own section (PyYAML keeps the last one)
    p = tmp_path / "s.yaml"
    p.write_text(text + "\n" + bad)
    r = subprocess.run([sys.executable, "-m", "vision_calib.cli", "identify-synthetic", str(p)], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert needle in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("variant", ["D", "E", "H"])
def test_calibrated_h4_model_round_trips_for_every_model_form(tmp_path, variant):
    scene = scene_with(load_scene(SCENES_DIR / "h4_vision.yaml"), variant=variant)
    setup = scene.setup
    x = setup.params.nominal + 1e-3 * np.random.default_rng(0).normal(size=len(setup.params)) * setup.params.free
    write_calibrated_model(tmp_path / "m.yaml", setup, x)
    robot = load_calibrated_model(tmp_path / "m.yaml")
    X = setup.robot.pose_grid()[::10]
    np.testing.assert_allclose(robot.igm(X), setup.robot.igm(X, x), atol=1e-12)


def test_calibrated_serial_model_round_trips(tmp_path):
    setup = load_scene(SCENES_DIR / "rx90_eye_in_hand.yaml").setup
    x = setup.params.nominal + 1e-3 * np.random.default_rng(1).normal(size=len(setup.params))
    write_calibrated_model(tmp_path / "m.yaml", setup, x)
    chain = load_calibrated_model(tmp_path / "m.yaml")
    q = np.radians([[0, 35, 95, 0, 50, 0], [10, 30, 100, 20, 40, -30]])
    np.testing.assert_allclose(chain.forward(q), setup.chain.forward(q, x), atol=1e-12)
