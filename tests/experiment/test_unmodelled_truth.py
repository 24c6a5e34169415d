"""Truths the identified model does not share (scene ``truth`` keys ``model`` / ``tilt_deg`` of an H4
scene, rig.h4.H4Setup.truth_model): the chi-square adequacy test flags a model-31 truth identified
with model 12 at the scene's deviations, and does not flag the clean case."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from vision_calib.errors import ConfigError
from vision_calib.experiment.steps import unmodelled_truth
from vision_calib.experiment.synthetic import run_synthetic
from vision_calib.identify import model_adequacy
from vision_calib.kinematics.h4 import TILT_NAMES
from vision_calib.rig import load_scene

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "h4_vision.yaml"


def scene(unmodelled, **truth):
    sc = load_scene(SCENE)
    # paper-level deviations: 1 mm and 0.2 deg per parameter
    truth = {"sigma_length_m": 1e-3, "sigma_angle_rad": np.radians(0.2), **truth}
    return replace(sc, truth=replace(sc.truth, unmodelled=unmodelled, **truth))


def verdict(sc, seed):
    out = run_synthetic(sc, seed=seed, prepare=True)
    return model_adequacy(out.result), out


@pytest.mark.parametrize("seed", [0, 1])
def test_adequacy_flags_model31_truth_under_model12_and_not_the_clean_case(seed):
    clean, _ = verdict(scene({}), seed)
    assert clean["verdict"] == "consistent", clean["chi2_dof"]
    # per-chain geometry (model 31) drawn with the scene's 1 mm / 0.2 deg, identified with model 12
    bad, out = verdict(scene({"model": "31"}), seed)
    assert out.truth.model == "31" and out.setup.model == "12"
    assert bad["verdict"] == "too large" and bad["chi2_dof"] > 1.5 * clean["chi2_dof"]
    # the misfit matters: calibration does not reach the clean case's accuracy
    assert out.after["position_rms_mm"] > 2 * run_synthetic(scene({}), seed=seed).after["position_rms_mm"]


def test_truth_tilts_are_drawn_and_carried_by_the_tilt_parameters():
    sc = scene({"tilt_deg": 0.5})
    truth, x = unmodelled_truth(sc)
    tv = truth.params.values(x)
    t = np.degrees([tv[n] for n in TILT_NAMES])
    assert truth.robot.tilt_params and 0.05 < np.abs(t).max() < 2.5
    assert truth.params.n_free == sc.setup.params.n_free  # the tilts are not drawn again as deviations
    # the scene's own deviations: as without tilts (same random stream), the tilts aside
    t0, x0 = unmodelled_truth(scene({"tilt_deg": 1e-9}))
    np.testing.assert_allclose(x[:-4], x0[:-4])
    with pytest.raises(ConfigError, match="tilt_deg"):
        sc.setup.truth_model({"tilt_deg": "big"}, np.random.default_rng(0))
