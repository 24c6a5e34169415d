"""Robot and target kinds from outside the package: a toy plugin package (``tests/plugins/vc_toy_plugin``:
entry points ``vision_calib.robots`` and ``vision_calib.targets``) is pip-installed (into a temporary folder put
on the path, so the shared virtualenv is left as it is) and the CLI runs on its kinds in a fresh process."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
PLUGIN = Path(__file__).with_name("vc_toy_plugin")


@pytest.fixture(scope="module")
def plugin_path(tmp_path_factory):
    """PYTHONPATH with the worktree first and the installed plugin after it."""
    tmp = tmp_path_factory.mktemp("plugin")
    shutil.copytree(PLUGIN, tmp / "src")
    site = tmp / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                    "--no-index", "--target", str(site), str(tmp / "src")], check=True, capture_output=True)
    assert list(site.glob("vc_toy_plugin-*.dist-info/entry_points.txt")), "pip wrote no entry points"
    yield os.pathsep.join([str(ROOT), str(site)])
    shutil.rmtree(tmp, ignore_errors=True)


def _run(args, pythonpath, cwd):
    env = {**os.environ, "PYTHONPATH": pythonpath}
    return subprocess.run([sys.executable, "-m", "vision_calib.cli", *args], capture_output=True, text=True,
                          env=env, cwd=cwd)


def test_identify_synthetic_runs_on_a_plugin_robot_kind(plugin_path, tmp_path):
    (tmp_path / "arm.yaml").write_text("kind: plugin_planar2\nL1: 0.4\nL2: 0.3\n")
    (tmp_path / "scene.yaml").write_text(
        "name: toy\nrobot: arm.yaml\nmount: fixed\n"
        "truth: {seed: 3, sigma_length_mm: 2.0, sigma_angle_deg: 0.3}\n"
        "poses: {kind: random, count: 40}\nvalidation: {kind: random, count: 20}\n"
        "measurement: {sigma_mm: 0.05, sigma_deg: 0.01}\n")
    r = _run(["identify-synthetic", str(tmp_path / "scene.yaml"), "--json", "--seed", "5"], plugin_path, tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["converged"] and out["residual"] == "position"
    z = [(p["identified"] - p["true"]) / p["std"] for p in out["parameters"] if p["free"]]
    assert len(z) == 7 and np.max(np.abs(z)) < 4, z  # the plugin's model recovers its truth within the std
    # without the plugin on the path the kind is unknown, and the error says so
    bare = _run(["identify-synthetic", str(tmp_path / "scene.yaml"), "--json"], str(ROOT), tmp_path)
    assert bare.returncode != 0 and "no robot kind reads this file" in bare.stderr


def test_target_command_draws_a_plugin_target_kind(plugin_path, tmp_path):
    (tmp_path / "board.yaml").write_text("kind: plugin_squares\nrows: 2\ncols: 3\nside_m: 0.0254\nmargin_m: 0\n")
    r = _run(["target", str(tmp_path / "board.yaml"), "--out", str(tmp_path / "b.png"), "--dpi", "100"],
             plugin_path, tmp_path)
    assert r.returncode == 0, r.stderr
    import cv2

    img = cv2.imread(str(tmp_path / "b.png"), cv2.IMREAD_GRAYSCALE)
    assert img.shape == (300, 500)  # 3 x 5 squares of 1 inch at 100 dpi
    assert abs((img < 128).mean() - 6 / 15) < 1e-3  # 6 black squares


def test_a_broken_plugin_is_named_and_the_rest_still_works(tmp_path):
    """An entry point that fails to import: a warning naming it, the shipped kinds still load."""
    dist = tmp_path / "vc_broken-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: vc-broken\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[vision_calib.robots]\nbroken = vc_missing_module:Nope\n")
    code = ("import warnings\nwarnings.simplefilter('always')\n"
            "from vision_calib.rig import KINDS\nprint(sorted(KINDS))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)])})
    assert r.returncode == 0, r.stderr
    assert "plugin 'broken'" in r.stderr and "ModuleNotFoundError" in r.stderr
    assert "serial" in r.stdout and "h4" in r.stdout
