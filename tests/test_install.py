"""The package installs like a library (issue 25): its shipped data is package data, and the commands a new user
runs work from any folder after a plain (non-editable) install of the built wheel.

The wheel is built from this checkout and installed WITHOUT dependencies into a fresh virtual environment whose
dependencies come from the test's own environment (a ``.pth`` line naming its site-packages: a plain path entry,
so the checkout's editable finder there is not activated); the commands run from a temporary folder, and the
test checks that the package they import is the installed wheel, not this checkout."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest
import yaml
from blocked_imports import run_blocked
from readme_block import check_python_block_output, readme_python_block, tree_digest

from vision_calib.shipped import MARKER, data_dir, examples_dir, scenes_dir, shipped_path, targets_dir

ROOT = Path(__file__).resolve().parents[1]


def test_shipped_data_is_package_data():
    """The data folder is inside the imported package, with its marker, the scenes, targets and example."""
    import vision_calib

    pkg = Path(vision_calib.__file__).resolve().parent
    assert data_dir().resolve() == (pkg / "data").resolve()
    assert (data_dir() / MARKER).is_file()
    assert {"h4_vision", "rx90_eye_in_hand", "ur5e_eye_in_hand"} <= {p.stem for p in scenes_dir().glob("*.yaml")}
    assert (targets_dir() / "charuco_a5.yaml").is_file()
    assert (examples_dir() / "rx90_eye_in_hand" / "recording.yaml").is_file()
    # every file a shipped scene names resolves inside the data folder
    for scene in scenes_dir().glob("*.yaml"):
        doc = yaml.safe_load(scene.read_text())
        for key in ("robot", "target"):
            if doc.get(key):
                p = (scene.parent / doc[key]).resolve()
                assert p.is_file() and data_dir().resolve() in p.parents, (scene.name, key)


def test_shipped_path_falls_back_to_package_data(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert shipped_path("scenes/h4_vision.yaml") == data_dir() / "scenes/h4_vision.yaml"
    assert shipped_path("h4_vision.yaml") == scenes_dir() / "h4_vision.yaml"
    assert shipped_path("examples/rx90_eye_in_hand").is_dir()
    assert shipped_path("nothing/here.yaml") == Path("nothing/here.yaml")  # a missing path stays the user's
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "h4_vision.yaml").write_text("mine")
    assert shipped_path("scenes/h4_vision.yaml") == Path("scenes/h4_vision.yaml")  # the user's own file wins


def _wheel_venv(tmp: Path) -> Path:
    """A fresh venv with this checkout's wheel installed (no deps; deps from this environment); its bin/."""
    wheel_dir = tmp / "wheel"
    build = [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(wheel_dir), str(ROOT)]
    try:
        import setuptools  # noqa: F401

        build.insert(5, "--no-build-isolation")  # offline-friendly: the build backend is already here
    except ImportError:
        pass
    subprocess.run(build, check=True, capture_output=True, text=True, timeout=300)
    (wheel,) = wheel_dir.glob("vision_calib-*.whl")
    env_dir = tmp / "venv"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    py = env_dir / "bin" / "python"
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    Path(site, "test_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    # without PYTHONPATH: a checkout on it, with the egg-info the build leaves there, reads as "already installed"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", str(wheel)],
                   check=True, capture_output=True, text=True, timeout=300, env=env)
    return env_dir / "bin"


@pytest.mark.slow
def test_wheel_commands_from_any_folder(tmp_path):
    """The Done-when of issue 25 on the built wheel: init + process of the example, the demo, init of a cell from
    the UR5e then identifiability and simulate on it, target of a shipped board; of issue 36: a documentation page
    (``docs validate``) and the README's Python block: all from a temporary folder."""
    bindir = _wheel_venv(tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VISION_CALIB_ALLOW_PATHS")}

    def vc(*args, ok=(0,)):
        p = subprocess.run([str(bindir / "vision-calib"), *args], cwd=work, env=env, capture_output=True, text=True,
                           timeout=600)
        assert p.returncode in ok, (args, p.returncode, p.stdout[-2000:], p.stderr[-2000:])
        return p

    where = subprocess.run([str(bindir / "python"), "-c", "import vision_calib; print(vision_calib.__file__)"],
                           cwd=work, env=env, capture_output=True, text=True, check=True).stdout.strip()
    assert str(tmp_path / "venv") in where and str(ROOT) not in where, where
    vc("init", "ex", "--from", "example")
    vc("process", "ex", "--out", "r", "--no-plots")
    rep = yaml.safe_load((work / "r" / "report.json").read_text())
    assert rep["verdict"]["status"] == "ok", rep["verdict"]
    vc("process", "examples/rx90_eye_in_hand", "--out", "r2", "--no-plots")  # the README's path, from anywhere
    vc("demo", "--out", "d", "--no-plots")
    assert (work / "d" / "report.json").is_file()
    vc("init", "cell", "--from", "ur5e")
    assert "robot/ur5e.urdf" in (work / "cell" / "scene.yaml").read_text()
    vc("identifiability", "cell/scene.yaml", "--poses", "30")
    vc("simulate", "cell/scene.yaml", "--poses", "12", "--out", "s", "--no-plots", "--frames", "2")
    assert (work / "s" / "calibrated_model.yaml").is_file()
    vc("target", "targets/charuco_a5.yaml", "--paper", "A4", "--out", "b.pdf")
    pdf = (work / "b.pdf").read_bytes()
    assert b"DICT_5X5_100" in pdf and b"/Image" not in pdf
    assert vc("docs", "validate").stdout == (ROOT / "vision_calib" / "docs" / "validate.md").read_text()
    assert "validate" in vc("docs").stdout and "no page 'nope'" in vc("docs", "nope", ok=(2,)).stderr
    api = tmp_path / "api"
    api.mkdir()
    example = Path(where).parent / "data" / "examples" / "rx90_eye_in_hand"
    before = tree_digest(example)
    p = subprocess.run([str(bindir / "python"), "-c", readme_python_block()], cwd=api, env=env, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    check_python_block_output(p.stdout, api / "out")
    assert tree_digest(example) == before


#: the modules of the extras [sim], [cluster], [gpu], [ros], of [test]'s URDF reader, and FCL (a core dependency
#: since `plan` is in the core, imported only by plan's collision checks): none is needed by these core commands
EXTRA_MODULES = ("pyrender", "OpenGL", "trimesh", "dask", "distributed", "pyarrow", "torch", "kornia", "yourdfpy",
                 "lxml", "fcl", "rosbags")


def test_core_commands_run_without_the_extras_and_the_others_name_theirs(tmp_path):
    """A core install: processing the example, identifiability, identify-synthetic, init and the demo (CPU polygon
    renderer) run with every extra unimportable; rendering with occluders (pyrender) and a Dask study say which
    extra to install and the pip command, exit 2."""
    p = run_blocked(tmp_path, """
        import json, sys
        from vision_calib.cli import main
        from vision_calib.errors import MissingExtraError
        codes = {
            "process": main(["process", "examples/rx90_eye_in_hand", "--out", "r", "--no-plots", "--json"]),
            "identifiability": main(["identifiability", "scenes/ur5e_eye_in_hand.yaml", "--poses", "30", "--json"]),
            "identify-synthetic": main(["identify-synthetic", "rx90_eye_in_hand.yaml", "--poses", "20", "--json"]),
            "init": main(["init", "cell", "--from", "ur5e"]),
        }
        import numpy as np
        from vision_calib.camera import CameraIntrinsics
        from vision_calib.render import TargetRenderer
        from vision_calib.shipped import targets_dir
        from vision_calib.targets import load_target
        intr = CameraIntrinsics(64, 48, 60.0, 60.0, 31.5, 23.5, (0, 0, 0, 0, 0))
        msgs = {}
        try:
            TargetRenderer(load_target(targets_dir() / "charuco_a5.yaml"), intr, backend="pyrender").render(np.eye(4))
        except MissingExtraError as exc:
            msgs["sim"] = [str(exc), exc.exit_code]
        codes["study --scheduler"] = main(["study", "scenes/studies/rx90_lse_vs_ekf.yaml", "--out", "st",
                                           "--scheduler", "tcp://127.0.0.1:1"])
        print(json.dumps({"codes": codes, "msgs": msgs,
                          "loaded": sorted({m.split(".")[0] for m in sys.modules} & set(%r))}))
        """ % (EXTRA_MODULES,), blocked=EXTRA_MODULES, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    out = __import__("json").loads(p.stdout.strip().splitlines()[-1])
    assert out["codes"] == {"process": 0, "identifiability": 0, "identify-synthetic": 0, "init": 0,
                            "study --scheduler": 2}, out
    assert out["loaded"] == []
    msg, code = out["msgs"]["sim"]
    assert "pip install 'vision_calib[sim]'" in msg and "pyrender" in msg and code == 2, msg
    assert "a study on a Dask cluster (--scheduler) needs distributed" in p.stderr
    assert "pip install 'vision_calib[cluster]'" in p.stderr
