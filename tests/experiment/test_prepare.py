"""The preparation step (experiment.prepare) runs from a setup's capability (rig.base.TiltsFromAxis), not from its
kind: a serial setup is returned as is, any object with the capability gets the rotation-axis step."""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from vision_calib.errors import ConfigError
from vision_calib.experiment.prepare import prepare_setup
from vision_calib.experiment.steps import identify_measurements, prepare_measured
from vision_calib.experiment.synthetic import run_synthetic
from vision_calib.identify.camera_axis import estimate_camera_axis
from vision_calib.rig import load_scene
from vision_calib.rig.base import TiltsFromAxis

ROOT = Path(__file__).resolve().parents[2]


def test_a_setup_without_the_capability_is_returned_as_is():
    sc = load_scene(ROOT / "scenes" / "rx90_eye_in_hand.yaml")
    assert not isinstance(sc.setup, TiltsFromAxis)
    meas = run_synthetic(sc, seed=0, n_poses=12, prepare=False).measurements
    setup, info = prepare_setup(sc.setup, meas)
    assert setup is sc.setup and info == {}
    assert prepare_measured(sc.setup, meas, "pose") == (sc.setup, {}, None)  # nothing freed: no new analysis


@dataclass(frozen=True)
class _Toy:
    """Not an H4Setup: only the capability's four members; with_tilts records its arguments."""

    tilt_mode: str
    R_BC0: np.ndarray
    R_ME0: np.ndarray
    tilt_names: tuple = ("cam.x", "cam.y", "tgt.x", "tgt.y")

    def tilt_reference(self):
        return self.R_BC0, self.R_ME0

    def with_tilts(self, tilts_rad, prior_std_rad=None):
        return ("tilted", np.asarray(tilts_rad, float), None if prior_std_rad is None else np.asarray(prior_std_rad))


@pytest.fixture(scope="module")
def h4_run():
    sc = load_scene(ROOT / "scenes" / "h4_vision.yaml")
    return sc, run_synthetic(sc, seed=1, n_poses=30, prepare=False)


def test_the_step_goes_through_the_capability_only(h4_run):
    sc, out = h4_run
    assert isinstance(sc.setup, TiltsFromAxis)
    R_BC0, R_ME0 = sc.setup.tilt_reference()
    est = estimate_camera_axis(out.measurements.T_cam_target, R_BC0=R_BC0, R_ME0=R_ME0)
    vals = np.concatenate([est.tilt_cam_rad, est.tilt_target_rad])
    std = np.concatenate([est.tilt_cam_std_rad, est.tilt_target_std_rad])
    toy = _Toy("identify", R_BC0, R_ME0)
    assert isinstance(toy, TiltsFromAxis)
    (tag, v, s), info = prepare_setup(toy, out.measurements)
    assert tag == "tilted" and info["applied"] and info["identified"] == list(toy.tilt_names)
    np.testing.assert_allclose(v, vals, atol=0)
    np.testing.assert_allclose(s, std, atol=0)
    assert set(info["prior"]) == set(toy.tilt_names)
    (_, v, s), info = prepare_setup(_Toy("axis", R_BC0, R_ME0), out.measurements)
    assert s is None and info["identified"] == [] and "not carried" in info["note"]
    np.testing.assert_allclose(v, vals, atol=0)
    off = _Toy("off", R_BC0, R_ME0)
    assert prepare_setup(off, out.measurements) == (off, {"applied": False, "reason": "tilt_mode off"})
    with pytest.raises(ConfigError, match="_Toy.tilt_mode"):
        prepare_setup(_Toy("sometimes", R_BC0, R_ME0), out.measurements)


def test_measured_and_synthetic_paths_analyse_the_prepared_setup_alike(h4_run):
    """The H4 preparation frees the 4 tilt parameters: prepare_measured analyses the prepared setup again, and
    both the measured-data identification and run_synthetic identify that analysis' base set."""
    sc, out = h4_run
    residual = sc.identification.residual
    setup, info, rep = prepare_measured(sc.setup, out.measurements, residual)
    assert info["applied"] and rep is not None and set(setup.tilt_names) <= set(setup.params.free_names)
    assert set(setup.tilt_names) <= set(rep.base_parameters)
    ident = identify_measurements(sc.setup, out.measurements, sc.identification.method, residual, robust=False,
                                  cross_check=False)
    assert ident.analysis.base_parameters == rep.base_parameters
    assert ident.setup.params.free_names == setup.params.free_names
    syn = run_synthetic(sc, seed=1, n_poses=30, prepare=True)
    np.testing.assert_array_equal(syn.base, setup.params.mask(rep.base_parameters))
