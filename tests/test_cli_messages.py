"""Messages of the last resort (issue 32 item 8): an out-of-memory error names what was being built (the innermost
frame of the package: module, function, line) and what to reduce, not always "reduce the image size, dpi, poses
or workers"; the verdict line never calls the model consistent and says it misses something in one breath: the
overall test's verdict, then the poses that do not fit (the pose-tail note)."""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from vision_calib.cli import main
from vision_calib.cli.exits import memory_message
from vision_calib.identify.adequacy import pose_tail
from vision_calib.report.summary import verdict_line
from vision_calib.shipped import data_dir


def _boom(*a, **k):
    raise MemoryError


def test_out_of_memory_names_what_was_built(monkeypatch, capsys):
    """A MemoryError while the scene's YAML is composed, then while an image header is read: each message names
    the package function it came through and its own advice."""
    import vision_calib.config as config

    monkeypatch.setattr(config, "safe_load", _boom)
    assert main(["identifiability", str(data_dir() / "scenes" / "rx90_eye_in_hand.yaml")]) == 2
    err = capsys.readouterr().err
    assert "out of memory in vision_calib.config.load_yaml (line " in err and "while building a YAML file's values " \
           "for `identifiability`" in err, err
    assert "reduce the image size, dpi" not in err

    import vision_calib.io.images as images

    monkeypatch.setattr(images, "header_size", _boom)
    try:
        images.check_pixels("x.png")
    except MemoryError as exc:
        msg = memory_message(exc, "process")
    assert msg.startswith("out of memory in vision_calib.io.images.check_pixels (line ") and "process" in msg
    try:  # no frame of the package: the generic advice
        _boom()
    except MemoryError as exc:
        assert memory_message(exc) == "out of memory (reduce the image size, dpi, poses or workers)"


def test_consistent_verdict_with_a_pose_tail_says_which_holds():
    """40 poses, 6 of them far in the chi-square tail: the pose-tail test is significant while the overall
    adequacy is "consistent"; the line says consistent over all poses, then but ... those poses fit worse."""
    rng = np.random.default_rng(0)
    pc = chi2.rvs(6, size=40, random_state=rng)
    pc[10:16] = 60.0
    tail = pose_tail(pc, 6, [f"p{i:02d}" for i in range(40)])
    assert tail["significant"]
    v = {"ok": True, "status": "ok", "n_rejected_poses": 0, "n_outliers": 0, "adequacy": "consistent",
         "note": tail["message"], "warnings": 0}
    line = verdict_line(v)
    assert "misses something" not in line
    assert "model adequacy: consistent over all poses (chi2/dof in its band); but 6 of 40 poses have a residual" in line
    assert "clustered in p10-p15 (6 poses): those poses fit worse than their noise allows" in line
