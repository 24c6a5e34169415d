"""No wrong robot at the budgets users run (issue 32): the H4 at 15 poses x 1 frame, where the rotation-axis test
can fail on the rotation noise of single frames, still gives a robot better than the nominal one with honest std;
a fit grossly inconsistent with its data (residuals far above the noise AND the two methods disagreeing) is never
written, whatever its held-out prediction of the measured poses says."""

from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from vision_calib.experiment.simulate import run_simulation
from vision_calib.experiment.steps import inconsistency_failure
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


def _ident(chi2_dof, verdict, adequacy="too large"):
    check = None if verdict is None else {"verdict": verdict, "methods": ["igm", "lse"], "chi2": 300.0, "dof": 19,
                                          "p_value": 1e-50, "max_abs_z": 2.8, "worst": "h4.L"}
    return SimpleNamespace(method_check=check, problem=SimpleNamespace(n_obs=15),
                           adequacy={"chi2_dof": chi2_dof, "expected_chi2_dof": (0.3, 2.2), "verdict": adequacy,
                                     "worst_poses": [{"label": "014"}, {"label": "003"}]},
                           prepared={"warning": "the measured rotations do not share one fixed rotation axis"})


def test_inconsistency_needs_both_a_misfit_and_a_method_disagreement():
    f = inconsistency_failure(_ident(193.0, "disagree"))
    assert f["kind"] == "model inconsistency" and f["message"].startswith("no calibrated model written")
    for part in ("chi2/dof 193", "h4.L", "more poses (15 used)", "frames", "014, 003", "fixed rotation axis"):
        assert part in f["message"]
    assert inconsistency_failure(_ident(193.0, "agree")) is None  # a misfit both methods agree on: a warning
    assert inconsistency_failure(_ident(193.0, None)) is None  # no second method
    assert inconsistency_failure(_ident(1.5, "disagree", "consistent")) is None  # a disagreement alone: a warning
    assert inconsistency_failure(_ident(float("nan"), "disagree", "not available")) is None


def _holdout(after_mm, mounts_mm, mounts_change):
    from vision_calib.experiment.holdout import error_stats

    b, a, m = (error_stats(np.array([v]), np.array([v / 10])) for v in (10.0, after_mm, mounts_mm))
    return {"interval": {"level": 0.95, "position_rms_change_mm": [-9.0, -8.0]}, "overall": {"before": b, "after": a},
            "mounts_only": {"after": m, "position_rms_change_mm": list(mounts_change)}}


def test_the_calibrated_robot_must_beat_the_mounts_only_calibration_on_held_out_poses():
    from vision_calib.experiment.holdout import holdout_decision, with_holdout_warning

    ok = holdout_decision(_holdout(0.1, 0.8, (-0.8, -0.2)), [])
    assert ok["ok"] and "against the mounts-only calibration" in ok["reason"]
    worse = holdout_decision(_holdout(0.3, 0.2, (0.02, 0.17)), [])
    assert not worse["ok"] and "worse in position than the nominal robot with only its mounts" in worse["reason"]
    same = holdout_decision(_holdout(0.2, 0.2, (-0.05, 0.05)), [])  # no evidence either way: a warning
    assert same["ok"] and "not predict held-out poses significantly better than the nominal robot with only its " \
        "mounts" in same["warning"] and "more poses" in same["warning"]
    @dataclass(frozen=True)
    class _Result:  # the one field with_holdout_warning touches
        warnings: tuple

    res = _Result(("w0",))
    assert with_holdout_warning(res, {"decision": same}).warnings == ("w0", same["warning"])
    assert with_holdout_warning(res, {"decision": ok}) is res and with_holdout_warning(res, None) is res
    plain = _holdout(0.2, 0.2, (-0.05, 0.05))
    del plain["mounts_only"]  # no baseline (a base set of mounts only, or of robot parameters only)
    assert holdout_decision(plain, [])["ok"]


@pytest.mark.slow
def test_a_robot_the_model_cannot_represent_is_not_written_at_twelve_poses():
    """h4_unmodelled (a model-31 truth identified with model 12), 12 poses x 1 frame: on the previous decision
    seeds 1 and 2 wrote a robot worse than the nominal one (validation 0.80 -> 1.74 and 0.81 -> 1.34 mm) because
    the held-out check compared with the nominal model only; the mounts-only alternative refuses them."""
    sc = load_scene(ROOT / "scenes" / "h4_unmodelled.yaml")
    for seed in (1, 2):
        rep = run_simulation(sc, seed=seed, n_poses=12, frames=1, workers=1, plots=False, reference=False)
        reason = rep["holdout"]["decision"]["reason"]
        assert not rep["holdout"]["decision"]["ok"] and "only its mounts calibrated" in reason
        assert rep["verdict"]["status"] == "failed" and not rep["verdict"]["usable"]


def test_registered_validation_error_removes_a_rigid_frame_offset_only():
    """Evaluation.position_rms_registered_mm: a model whose positions are the truth's moved rigidly (another base
    frame) has a large raw error and none left after registration; a non-rigid error stays."""
    from vision_calib import frames as F
    from vision_calib.rig.base import Evaluation

    rng = np.random.default_rng(3)
    Q = rng.uniform(-0.1, 0.1, size=(30, 3))
    R, t = F.so3_exp(np.array([0.01, -0.02, 0.015])), np.array([0.002, -0.001, 0.003])
    err = np.zeros((30, 6))
    err[:, :3] = Q @ R.T + t - Q
    rigid = Evaluation(Q, err)
    assert rigid.to_dict()["position_rms_mm"] > 2.0 and rigid.position_rms_registered_mm < 1e-9
    bend = err.copy()
    bend[:, 2] += 1e-3 * (Q[:, 0] / 0.1) ** 2  # up to 1 mm of bending no rigid motion explains
    reg = Evaluation(Q, bend).position_rms_registered_mm
    assert 0.1 < reg < 1.0
    assert np.isnan(Evaluation(Q[:2], err[:2]).position_rms_registered_mm)
