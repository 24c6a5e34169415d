"""An output that cannot be written is an error naming it, never a warning hidden in report.json (issue 28, the
"disk full" cases): a monkeypatched writer refuses one file with ENOSPC; the command exits 2 naming that file, and
leaves no calibrated model without its report."""

from __future__ import annotations

import errno
import json
import os

import numpy as np
import pytest

from vision_calib import frames as F
from vision_calib.cli import main
from vision_calib.experiment.steps import rngs, scene_truth
from vision_calib.io.measured_poses_writer import write_measured_poses
from vision_calib.rig import SCENES_DIR, load_scene, scene_poses
from vision_calib.serialize import write_text_atomic

ST, SR = 1e-4, float(np.radians(0.02))


def _full_for(monkeypatch, name):
    """os.replace (the last step of every atomic write) fails with ENOSPC, no file named, for files called name."""
    real = os.replace

    def replace(src, dst, *a, **k):
        if os.path.basename(str(dst)) == name:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(src, dst, *a, **k)
    monkeypatch.setattr(os, "replace", replace)


def test_atomic_writer_names_the_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    _full_for(monkeypatch, "a.txt")
    with pytest.raises(OSError) as exc:
        write_text_atomic(tmp_path / "a.txt", "x")
    assert exc.value.errno == errno.ENOSPC and exc.value.filename == str(tmp_path / "a.txt")
    assert list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    d = tmp_path_factory.mktemp("mp")
    path = SCENES_DIR / "rx90_eye_in_hand.yaml"
    scene = load_scene(path)
    rp, rn, _ = rngs(2)
    q = scene_poses(scene, rp, 30)
    dd = np.concatenate([rn.normal(scale=ST, size=(30, 3)), rn.normal(scale=SR, size=(30, 3))], axis=1)
    T = F.perturb_pose(scene.setup.T_cam_target(q, scene_truth(scene)), dd)
    return write_measured_poses(d / "m.yaml", path, [f"p{i:02d}" for i in range(30)], q, T, "T_cam_target",
                                units={"length": "mm", "angle": "deg"}, default_sigma=(ST, SR))


@pytest.mark.parametrize("name,plots", [("report.html", False), ("report.json", False), ("summary.txt", False),
                                        ("residuals.png", True), ("calibrated_model.yaml", False)])
def test_an_output_that_cannot_be_written_is_an_error(measured, tmp_path, monkeypatch, capsys, name, plots):
    out = tmp_path / "out"
    (out).mkdir()
    (out / "report.html").write_text("an earlier run's page")
    _full_for(monkeypatch, name)
    code = main(["process-poses", str(measured), "--out", str(out), *([] if plots else ["--no-plots"])])
    err = capsys.readouterr().err
    assert code == 2, err
    assert f"vision-calib: error: {out / name}: No space left on device (the outputs in {out} are incomplete: no " \
           "calibrated model kept" in err
    assert not list(out.glob("calibrated_model.*"))  # no model without its report
    assert not (out / "report.html").exists()  # nor an earlier run's page beside this run's report
    if name != "report.json":
        rep = json.loads((out / "report.json").read_text())
        assert any(w.startswith(f"{out / name}: could not be written (No space left on device)") for w in rep["warnings"])
        assert "model" not in rep["files"] and "html" not in rep["files"]
    else:
        assert not (out / "report.json").exists()


def test_a_plot_that_cannot_be_drawn_is_a_printed_warning(measured, tmp_path, monkeypatch, capsys):
    """Not a write error (a drawing bug): the run keeps its report and model; the warning is printed too."""
    from vision_calib.report import plots

    monkeypatch.setattr(plots, "plot_residuals", lambda *a: (_ for _ in ()).throw(ValueError("cannot draw")))
    assert main(["process-poses", str(measured), "--out", str(tmp_path / "out")]) == 0
    assert "warning: plotting failed: cannot draw" in capsys.readouterr().out
    assert (tmp_path / "out" / "calibrated_model.yaml").is_file()
