"""H4 identification methods through the measured-data step (experiment.steps.identify_measurements) and the
report: igm minimises the joint residuals (the paper's method), lse the forward model's pose residuals, ekf
the joint residuals by EKF; each is named for what ran, and igm / lse run the other one on the same kept
poses as a check (report ``method_check`` block and summary line)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from vision_calib.errors import ConfigError
from vision_calib.experiment.steps import identify_measurements, scene_truth
from vision_calib.report.build import build_report
from vision_calib.rig import load_scene

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "h4_vision.yaml"


@pytest.fixture(scope="module")
def data():
    sc = load_scene(SCENE)
    sc = replace(sc, truth=replace(sc.truth, unmodelled={}))  # the truth the model shares
    setup = sc.setup
    x_true = scene_truth(sc)
    meas = setup.synthetic_measurements(setup.pose_grid("grid81"), x_true, np.random.default_rng(3),
                                        sigma_t_m=5e-5, sigma_r_rad=np.radians(0.01))
    out = {}
    for method in ("igm", "lse", "ekf"):
        ident = identify_measurements(setup, meas, method, setup.residual_for(method, sc.identification.residual))
        out[method] = ident, build_report("simulation", source={"scene": {"name": sc.name, "path": str(SCENE),
                                                                          "robot_kind": "h4"}},
                                          settings={"poses": 81, "method": method}, result=ident.result,
                                          identified=ident)
    return out, dict(zip(setup.params.names, x_true))


@pytest.mark.parametrize("method,kind,other", [("igm", "joint", "lse"), ("lse", "pose", "igm"), ("ekf", "joint", None)])
def test_method_that_ran_is_named_and_checked(data, method, kind, other):
    out, x_true = data
    ident, report = out[method]
    assert ident.result.method == report["identification"]["method"] == method
    assert ident.problem.residual_kind == report["identification"]["residual_kind"] == kind
    assert f"identification ({method})" in report["summary_text"]
    if other is None:
        assert ident.method_check is None and "method_check" not in report
        return
    check = report["method_check"]
    assert check["methods"] == [method, other] and check["residual_kinds"][0] == kind
    assert check["n_poses"] == ident.problem.n_obs == 81
    assert check["verdict"] == "agree" and check["p_value"] > check["level"]
    assert f"method check ({method} vs {other} on the same 81 poses): agree" in report["summary_text"]
    # the truth within the reported std (the model is right; the truth has no mount tilts: 0 for the prepared
    # setup's tilt parameters)
    fi = ident.result.free
    true = np.array([x_true.get(n, 0.0) for n in ident.result.names])
    z = (ident.result.identified - true)[fi] / ident.result.std[fi]
    assert np.abs(z).max() < 4.5


def test_igm_and_lse_are_different_estimators_that_agree(data):
    """Not the same code: the estimates differ, by less than the check's std of the difference allows (5 std)."""
    out, _ = data
    a, b = out["igm"][0], out["lse"][0]
    assert not np.array_equal(a.result.identified, b.result.identified)
    d = (a.result.identified - b.result.identified)[a.result.free]
    assert np.abs(d).max() > 0
    # each check's second fit (started from the first's solution) lands on the other run's estimate: the
    # difference igm - lse reported by both, with the sign of its method order, to 1e-3 of its std
    for ident, sign in ((a, 1.0), (b, -1.0)):
        rows = ident.method_check["parameters"]
        dd, sd = np.array([p["difference"] for p in rows]), np.array([p["std"] for p in rows])
        assert np.all(np.abs(dd - sign * d) < 1e-3 * sd)
        assert np.all(np.abs(d) < 5 * sd)


def test_scene_residual_contradicting_the_method_is_refused(tmp_path):
    root = SCENE.parents[1]
    text = SCENE.read_text().replace("robot: robots/", f"robot: {root}/scenes/robots/").replace(
        "target: ../targets/", f"target: {root}/targets/")
    assert "  method: igm\n  residual: joint\n" in text
    p = tmp_path / "s.yaml"
    p.write_text(text.replace("  method: igm\n  residual: joint\n", "  method: lse\n  residual: joint\n"))
    with pytest.raises(ConfigError, match="identification.residual.*'lse' minimises 'pose'"):
        load_scene(p)
    p.write_text(text.replace("  method: igm\n  residual: joint\n", "  method: lse\n"))
    assert load_scene(p).identification.residual == "pose"
