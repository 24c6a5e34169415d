"""A new robot kind is a one-place change: a 2-link planar arm defined outside the package (the plugin example's
module, no package module edited), registered through ``rig.register``, runs ``identify-synthetic`` end to end
from a scene file, recovers its true parameters within the predicted std, and round-trips its calibrated-model file."""

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from vision_calib.cli import main
from vision_calib.io.model_export import load_calibrated_model, write_calibrated_model
from vision_calib.rig import Setup, load_scene, register, unregister

# the toy robot of the plugin example (tests/plugins/vc_toy_plugin), here registered by hand under its own kind name
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "plugins" / "vc_toy_plugin"))
from vc_toy_plugin.robot import NAMES, Planar2Setup as PluginPlanar2  # noqa: E402


@dataclass(frozen=True)
class Planar2Setup(PluginPlanar2):
    kind: ClassVar[str] = "planar2"


@pytest.fixture
def toy_scene(tmp_path):
    register(Planar2Setup)
    (tmp_path / "arm.yaml").write_text("kind: planar2\nL1: 0.4\nL2: 0.3\n")
    (tmp_path / "scene.yaml").write_text(
        "name: toy\nrobot: arm.yaml\nmount: fixed\n"
        "truth: {seed: 3, sigma_length_mm: 2.0, sigma_angle_deg: 0.3}\n"
        "poses: {kind: random, count: 40}\nvalidation: {kind: random, count: 20}\n"
        "measurement: {sigma_mm: 0.05, sigma_deg: 0.01}\n")
    yield tmp_path / "scene.yaml"
    unregister("planar2")


def test_toy_kind_runs_identify_synthetic_end_to_end(toy_scene, capsys):
    assert load_scene(toy_scene).kind == "planar2"
    assert main(["identify-synthetic", str(toy_scene), "--json", "--seed", "5"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["converged"] and out["residual"] == "position" and out["method"] == "lse"
    z = [(p["identified"] - p["true"]) / p["std"] for p in out["parameters"] if p["free"]]
    assert len(z) == 7 and np.max(np.abs(z)) < 4, z
    moved = [abs(p["true"] - p["nominal"]) for p in out["parameters"]]
    assert max(moved) > 10 * max(p["std"] for p in out["parameters"])  # the truth is not the nominal
    a, b = out["accuracy"]["after"], out["accuracy"]["before"]
    assert a["position_rms_mm"] < 0.2 * b["position_rms_mm"]


def test_toy_kind_analytic_jacobian_and_model_file(toy_scene, tmp_path):
    setup = load_scene(toy_scene).setup
    rng = np.random.default_rng(0)
    q = setup.sample_poses(rng, 6)
    x = setup.params.nominal + rng.normal(size=7) * 1e-2
    meas = setup.synthetic_measurements(q, x, rng, 1e-4, 1e-4)
    prob = setup.problem(meas)
    J = prob.jacobian(x)
    eps = 1e-7
    fd = np.stack([(prob.residual(x + eps * e) - prob.residual(x - eps * e)) / (2 * eps) for e in np.eye(7)], -1)
    np.testing.assert_allclose(J, fd, atol=1e-7)
    write_calibrated_model(tmp_path / "m.yaml", setup, x)
    robot = load_calibrated_model(tmp_path / "m.yaml")
    np.testing.assert_allclose(robot.T_cam_tip(q, robot.params.nominal), setup.robot.T_cam_tip(q, x), atol=1e-12)


def test_unknown_robot_kind_is_named(tmp_path):
    (tmp_path / "arm.yaml").write_text("kind: delta3\n")
    (tmp_path / "s.yaml").write_text("robot: arm.yaml\nmount: fixed\n")
    from vision_calib.errors import ConfigError

    with pytest.raises(ConfigError, match="no robot kind reads this file"):
        load_scene(tmp_path / "s.yaml")


def test_register_names_what_a_robot_kind_lacks():
    """register takes a Setup subclass of the rig.registry.RobotKind interface; TypeError naming the rest."""

    class NotASetup:
        kind, mounts = "x", ("fixed",)

    with pytest.raises(TypeError, match="must be a Setup subclass"):
        register(NotASetup)
    with pytest.raises(TypeError, match=r"robot kind Planar2Setup lacks 'mounts'"):
        register(type("Planar2Setup", (Setup,), {"claims": Planar2Setup.claims, "from_scene": Planar2Setup.from_scene,
                                                 "load_model": Planar2Setup.load_model}))
    assert register(Planar2Setup) is Planar2Setup
    unregister("planar2")
