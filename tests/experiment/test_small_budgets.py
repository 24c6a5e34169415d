"""No wrong robot at the budgets users run (issue 32): the H4 at 15 poses x 1 frame, where the rotation-axis test
can fail on the rotation noise of single frames, still gives a robot better than the nominal one with honest std;
a fit grossly inconsistent with its data (residuals far above the noise AND the two methods disagreeing) is never
written, whatever its held-out prediction of the measured poses says."""

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from vision_calib.experiment.simulate import run_simulation
from vision_calib.experiment.steps import UNEXPLAINED_CHI2_DOF, inconsistency_failure
from vision_calib.rig import load_scene

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_h4_fifteen_single_frame_poses_give_a_better_robot_with_honest_std():
    sc = load_scene(ROOT / "scenes" / "h4_vision.yaml")
    axis_failed = 0
    for seed in (1, 2, 3):
        rep = run_simulation(sc, seed=seed, n_poses=15, frames=1, workers=1, plots=False, reference=False)
        assert rep["verdict"]["status"] != "failed", rep["verdict"].get("message")
        b, a = rep["accuracy"]["before"], rep["accuracy"]["after"]
        assert a["position_rms_mm"] <= 0.5 * b["position_rms_mm"]
        ps = [p for p in rep["parameters"] if p["free"] and p["true"] is not None and p["std"]]
        z = np.array([(p["identified"] - p["true"]) / p["std"] for p in ps])
        assert np.max(np.abs(z)) <= 4
        prep = rep["prepared"]
        if not prep.get("axis_fixed", True):
            axis_failed += 1
            assert set(prep["identified"]) == {"B_T_C.tilt_x", "B_T_C.tilt_y", "M_T_E.tilt_x", "M_T_E.tilt_y"}
    # at least one of these seeds takes the failed-axis path (on the previous code: tilts frozen at nominal,
    # validation 1.38 -> 7.93 mm on seed 1)
    assert axis_failed >= 1


def _ident(chi2_dof, verdict):
    check = None if verdict is None else {"verdict": verdict, "methods": ["igm", "lse"], "chi2": 300.0, "dof": 19,
                                          "p_value": 1e-50, "max_abs_z": 2.8, "worst": "h4.L"}
    return SimpleNamespace(method_check=check, problem=SimpleNamespace(n_obs=15),
                           adequacy={"chi2_dof": chi2_dof, "expected_chi2_dof": (0.3, 2.2),
                                     "worst_poses": [{"label": "014"}, {"label": "003"}]},
                           prepared={"warning": "the measured rotations do not share one fixed rotation axis"})


def test_inconsistency_needs_both_a_misfit_and_a_method_disagreement():
    f = inconsistency_failure(_ident(193.0, "disagree"))
    assert f["kind"] == "model inconsistency" and f["message"].startswith("no calibrated model written")
    for part in ("chi2/dof 193", "h4.L", "more poses (15 used)", "frames", "014, 003", "fixed rotation axis"):
        assert part in f["message"]
    assert inconsistency_failure(_ident(193.0, "agree")) is None  # a misfit both methods agree on: a warning
    assert inconsistency_failure(_ident(193.0, None)) is None  # no second method
    assert inconsistency_failure(_ident(UNEXPLAINED_CHI2_DOF * 0.9, "disagree")) is None
    assert inconsistency_failure(_ident(float("nan"), "disagree")) is None
