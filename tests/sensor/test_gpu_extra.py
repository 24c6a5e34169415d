"""torch and kornia are the optional extra [gpu]: the default path (CLI, simulate with the OpenCV sensor path,
identification) runs with them unimportable, and the torch/kornia sensor path says which extra to install.

Each test runs a fresh interpreter whose ``sitecustomize`` makes the blocked modules unimportable, as if not
installed, in it and in every process it starts (image workers, fork server). (``sys.modules[name] = None`` would
not do: scipy's array-API helpers look torch up in sys.modules and fail on None.)"""

import json
from pathlib import Path

import pytest
from blocked_imports import run_blocked

ROOT = Path(__file__).resolve().parents[2]


def test_default_path_runs_without_torch_and_the_device_path_names_the_extra(tmp_path):
    p = run_blocked(tmp_path, f"""
        import json, sys
        import numpy as np
        try:
            import torch
            sys.exit("torch is importable: the block did not work")
        except ImportError:
            pass
        from vision_calib.cli import main
        from vision_calib.camera import CameraIntrinsics
        from vision_calib.errors import MissingExtraError
        from vision_calib.sensor import SensorEffects, apply_effects
        code = main(["identify-synthetic", {str(ROOT / "scenes" / "rx90_eye_in_hand.yaml")!r}, "--poses", "20",
                     "--json"])
        intr = CameraIntrinsics(64, 48, 60.0, 60.0, 31.5, 23.5, (0, 0, 0, 0, 0))
        cpu = apply_effects(np.full((48, 64), 100.0), SensorEffects(), 2, 0, intr)  # default: OpenCV
        errors = []
        for call in (lambda: apply_effects(np.full((48, 64), 100.0), SensorEffects(), 1, 0, intr, device="cpu"),
                     lambda: __import__("vision_calib.sensor", fromlist=["x"]).deterministic_image):
            try:
                call()
                errors.append(None)
            except MissingExtraError as exc:
                errors.append([str(exc), exc.exit_code, isinstance(exc, ImportError)])
        print(json.dumps({{"code": code, "cpu_shape": list(cpu.shape), "errors": errors,
                          "loaded": [m for m in ("torch", "kornia") if m in sys.modules]}}))
        """)
    assert p.returncode == 0, p.stderr[-3000:]
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert out["code"] == 0 and out["cpu_shape"] == [2, 48, 64] and out["loaded"] == []
    for err in out["errors"]:
        assert err is not None, "the torch path ran without torch"
        msg, exit_code, is_import_error = err
        assert "pip install 'vision_calib[gpu]'" in msg and "torch" in msg
        assert exit_code == 2 and is_import_error


def test_kornia_missing_alone_names_the_extra(tmp_path):
    pytest.importorskip("torch", reason="the torch/kornia sensor path is the optional extra [gpu]")
    p = run_blocked(tmp_path, """
        import numpy as np, torch
        from vision_calib.camera import CameraIntrinsics
        from vision_calib.errors import MissingExtraError
        from vision_calib.sensor import SensorEffects, deterministic_image
        intr = CameraIntrinsics(64, 48, 60.0, 60.0, 31.5, 23.5, (0, 0, 0, 0, 0))
        try:
            deterministic_image(torch.full((48, 64), 100.0), SensorEffects(blur_sigma_px=1.0), intr)
        except MissingExtraError as exc:
            print(exc)
        """, blocked=("kornia",))
    assert p.returncode == 0, p.stderr[-3000:]
    assert "kornia" in p.stdout and "pip install 'vision_calib[gpu]'" in p.stdout


@pytest.mark.slow
def test_simulate_renders_and_identifies_without_torch(tmp_path):
    """Rendering, the OpenCV sensor path in image workers, measurement and identification: no torch anywhere."""
    p = run_blocked(tmp_path, f"""
        import sys
        from vision_calib.cli import main
        sys.exit(main(["simulate", {str(ROOT / "scenes" / "rx90_eye_in_hand.yaml")!r}, "--poses", "8", "--frames",
                       "1", "--workers", "2", "--no-plots", "--out", "sim"]))
        """)
    assert p.returncode == 0, p.stderr[-3000:]
    report = json.loads((tmp_path / "sim" / "report.json").read_text())
    assert report["measurements"]["n_valid"] == 8 and report["identification"]["converged"]
