"""camera.yaml's uncertainty (io/camera_file.py load_camera_uncertainty; issue 32 item 8): the std and covariance
calibrate-camera writes are read back exactly; a file without std gives none; a malformed std or covariance is a
ConfigError naming the file and key."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from vision_calib.errors import ConfigError
from vision_calib.io.camera_file import load_camera_uncertainty
from vision_calib.measure.intrinsics import PARAM_NAMES

CAM = {"format": "vision_calib.camera/1", "width": 640, "height": 480, "fx": 600.0, "fy": 601.0, "cx": 320.0,
       "cy": 240.0, "dist": [0.1, -0.2, 0.0, 0.0, 0.05]}
STD = [0.8, 0.7, 0.5, 0.6, 0.01, 0.03, 1e-4, 1e-4, 0.02]


def _cov():
    rng = np.random.default_rng(0)
    corr = np.corrcoef(rng.normal(size=(9, 40)))
    return corr * np.outer(STD, STD)


def _write(tmp_path, **extra):
    p = tmp_path / "camera.yaml"
    p.write_text(yaml.safe_dump({**CAM, **extra}))
    return p


def _std_block():
    return {"fx": STD[0], "fy": STD[1], "cx": STD[2], "cy": STD[3], "dist": STD[4:]}


def test_std_and_covariance_read_back(tmp_path):
    C = _cov()
    p = _write(tmp_path, std=_std_block(), covariance={"names": list(PARAM_NAMES), "matrix": C.tolist()})
    std, cov = load_camera_uncertainty(p)
    assert [std[k] for k in PARAM_NAMES] == STD and np.array_equal(cov, C)
    assert load_camera_uncertainty(_write(tmp_path, std=_std_block())) == (dict(zip(PARAM_NAMES, STD)), None)
    assert load_camera_uncertainty(_write(tmp_path)) == (None, None)


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["std"].update(fx=-1.0), r"camera.yaml: std: expected finite numbers >= 0"),
    (lambda d: d["std"].update(dist=[0.1, 0.2]), r"camera.yaml: std.dist: expected 5 numbers"),
    (lambda d: d["covariance"].update(matrix=[[1.0] * 8] * 9), r"covariance.matrix: expected a finite 9 x 9 matrix"),
    (lambda d: d["covariance"]["matrix"][0].__setitem__(1, 5.0), r"covariance.matrix: not symmetric"),
    (lambda d: d["covariance"].update(names=list(reversed(PARAM_NAMES))), r"covariance.names: expected"),
    (lambda d: d["std"].update(fx=2.0), r"covariance.matrix: its diagonal is not the square of std"),
])
def test_malformed_uncertainty_is_named(tmp_path, edit, message):
    doc = {**CAM, "std": _std_block(), "covariance": {"names": list(PARAM_NAMES), "matrix": _cov().tolist()}}
    edit(doc)
    p = tmp_path / "camera.yaml"
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=message):
        load_camera_uncertainty(p)
