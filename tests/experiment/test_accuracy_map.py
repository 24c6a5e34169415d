"""The accuracy map (experiment.accuracy_map): the 95 % radius of a 3-D Gaussian against closed forms and Monte
Carlo, the registered tool Jacobian against finite differences, the map's r95 covering 95 % of the tool errors of
parameter errors drawn from the covariance; the map in report.json / report.html of process-poses; and
`vision-calib compare` exit codes (0 same robot, 3 another robot, 2 bad input) on process-poses results."""

import json
import shutil

import numpy as np
import pytest
import yaml
from scipy.stats import chi2

from vision_calib import frames as F
from vision_calib.cli import main
from vision_calib.experiment import accuracy_map as M
from vision_calib.experiment.compare import parameter_test
from vision_calib.experiment.steps import rngs, scene_truth
from vision_calib.experiment.synthetic import run_synthetic
from vision_calib.io.measured_poses_writer import write_measured_poses
from vision_calib.rig import SCENES_DIR, load_scene, scene_poses

RX90 = SCENES_DIR / "rx90_eye_in_hand.yaml"


# ------------------------------------------------------------------------------------------------ the radius
def test_norm_quantile_closed_forms():
    s = 0.3
    assert M.norm_quantile(s**2 * np.eye(3)) == pytest.approx(s * np.sqrt(chi2.ppf(0.95, 3)), rel=1e-6)
    assert M.norm_quantile(np.diag([s**2, 0, 0])) == pytest.approx(s * 1.959964, rel=1e-5)
    assert M.norm_quantile(np.diag([0, s**2, s**2])) == pytest.approx(s * np.sqrt(chi2.ppf(0.95, 2)), rel=1e-6)
    assert M.norm_quantile(np.zeros((3, 3))) == 0.0
    assert np.isnan(M.norm_quantile(np.full((3, 3), np.nan)))
    # a rotated covariance has the same radius; a batch keeps its shape
    R = F.T_from_xyz_rotvec(np.r_[0, 0, 0, 0.3, -0.5, 1.1])[:3, :3]
    C = np.diag([4.0, 1.0, 0.01])
    r = M.norm_quantile(np.stack([C, R @ C @ R.T]).reshape(1, 2, 3, 3))
    assert r.shape == (1, 2) and r[0, 0] == pytest.approx(r[0, 1], rel=1e-9)


def test_norm_quantile_matches_monte_carlo():
    rng = np.random.default_rng(7)
    n = 400_000
    for k in range(4):
        A = rng.normal(size=(3, 3)) * np.array([1.0, 0.3, 0.03])[:, None] ** k
        C = A @ A.T
        r = np.linalg.norm(rng.multivariate_normal(np.zeros(3), C, size=n), axis=1)
        share = np.mean(r <= M.norm_quantile(C))
        assert abs(share - 0.95) < 4 * np.sqrt(0.95 * 0.05 / n), (k, share)


# ------------------------------------------------------------------------------------------------ the map
@pytest.fixture(scope="module")
def fitted():
    """A synthetic RX-90 identification (12 poses): (kin, names, x, cov (n, n), q_cal)."""
    run = run_synthetic(RX90, seed=1, n_poses=12)
    kin, names = M.model_kinematics(run.setup)
    free = [n for n, f in zip(run.result.names, run.result.free) if f]
    cov = M.embed_covariance(names, free, run.result.covariance)
    return kin, names, M.robot_x(run.setup, names, run.result.identified), cov, run.measurements.joints


def test_registered_jacobian_matches_finite_differences(fitted):
    """The map's first-order registered tool error J_reg dx equals the registered error of the model moved by dx."""
    kin, names, x, cov, q_cal = fitted
    rng = np.random.default_rng(3)
    q = q_cal + rng.normal(scale=0.3, size=q_cal.shape)
    reg = M.registration(kin, x, q_cal)
    J = M.registered_jacobian(kin, x, q, reg)
    dx = rng.multivariate_normal(np.zeros(len(x)), cov) * 1e-2  # small: the second order negligible
    T0c, T1c = kin.tool(q_cal, x), kin.tool(q_cal, x + dx)
    T0, T1 = kin.tool(q, x), kin.tool(q, x + dx)
    e = M.registered_error(F.pose_error(T0c, T1c), T1c[:, :3, 3], F.pose_error(T0, T1), T1[:, :3, 3])
    lin = J @ dx
    assert np.max(np.abs(e - lin)) < 1e-3 * np.max(np.abs(lin))
    # registered on the calibration poses: their mean error is gone
    assert np.abs(M.registered_jacobian(kin, x, q_cal, reg).mean(axis=0)).max() < 1e-12


def test_map_r95_covers_95_percent_of_drawn_errors(fitted):
    """True robots drawn from the covariance around the fit: the true (registered, non-linear) tool errors at the
    map's joint sets fall within r95 at 95 % of the points, pooled over the draws."""
    kin, names, x, cov, q_cal = fitted
    block = M.build_map(kin, names, x, cov, q_cal)
    q = np.array([p["q_rad"] for p in block["points"]])
    r = np.array([p["r95_mm"] for p in block["points"]]) * 1e-3
    assert block["n_points"] > len(q_cal) and block["n_extrapolated"] > 0
    assert sum(p["calibration"] for p in block["points"]) == len(q_cal)
    rng = np.random.default_rng(11)
    L = np.linalg.cholesky(cov + 1e-30 * np.eye(len(x)))
    T, Tc = kin.tool(q, x), kin.tool(q_cal, x)
    hits = []
    for _ in range(300):
        xt = x - L @ rng.normal(size=len(x))
        Ttc, Tt = kin.tool(q_cal, xt), kin.tool(q, xt)
        e = M.registered_error(F.pose_error(Ttc, Tc), Tc[:, :3, 3], F.pose_error(Tt, T), T[:, :3, 3])
        hits.append(np.mean(np.linalg.norm(e[:, :3], axis=1) <= r))
    assert np.mean(hits) == pytest.approx(0.95, abs=0.02)
    # the same through build_map's own truth path (one draw): the block reports it per point
    xt = x - L @ rng.normal(size=len(x))
    b2 = M.build_map(kin, names, x, cov, q_cal, truth=(kin, xt))
    assert all("true_error_mm" in p and "true_error_z" in p for p in b2["points"])
    assert 0.0 <= b2["coverage"]["position"]["all"] <= 1.0


def test_coverage_law_of_a_correct_map(fitted):
    """The coverage a correct map gives (coverage_law): its mean is the level; one draw per run moves the whole map,
    so a pooled coverage of 8 runs spreads far wider than a band around 95 %; and truths drawn from the map's own
    covariance give p_at_least_observed values that are uniform (a correct map is neither flagged nor flattered)."""
    kin, names, x, cov, q_cal = fitted
    block = M.build_map(kin, names, x, cov, q_cal)
    q = np.array([p["q_rad"] for p in block["points"]])
    r = np.array([p["r95_mm"] for p in block["points"]]) * 1e-3
    J = M.registered_jacobian(kin, x, q, M.registration(kin, x, q_cal))[:, :3, :]
    law = M.coverage_law(J, cov, r, np.random.default_rng(5))
    assert law.mean() == pytest.approx(0.95, abs=0.01)
    pooled = M.pooled_coverage_law([law] * 8, np.random.default_rng(6))
    assert pooled.mean() == pytest.approx(0.95, abs=0.01) and np.percentile(pooled, 5) < 0.9
    # point-independent errors alone (an extra term, e.g. the joints' repeatability): each draw averages M
    # independent points, the law narrows around the level
    extra = np.einsum("k,ij->kij", r**2, np.eye(3))
    ind = M.coverage_law(J, 0.0 * cov, M.norm_quantile(extra), np.random.default_rng(7), draws=400, extra=extra)
    assert ind.mean() == pytest.approx(0.95, abs=0.01) and ind.std() < 2 * np.sqrt(0.95 * 0.05 / len(r))
    rng = np.random.default_rng(8)
    L = np.linalg.cholesky(cov + 1e-30 * np.eye(len(x)))
    pv = []
    for _ in range(40):
        b = M.build_map(kin, names, x, cov, q_cal, truth=(kin, x - L @ rng.normal(size=len(x))))
        u = b["coverage"]["under_the_map"]
        assert u["mean"] == pytest.approx(0.95, abs=0.01) and len(u["draws"]) == M.LAW_KEPT
        pv.append(u["p_at_least_observed"])
    assert 0.2 < np.mean(pv) < 0.85  # uniform p-values (ties at full coverage push the mean above 0.5)


def test_map_refuses_a_non_finite_covariance(fitted):
    kin, names, x, cov, q_cal = fitted
    bad = cov.copy()
    bad[0, 0] = np.nan
    with pytest.raises(Exception, match="not a finite"):
        M.build_map(kin, names, x, bad, q_cal)


# ------------------------------------------------------------------------------------------------ compare
def _pose_file(path, seed: int, x_true=None, n: int = 30):
    """A process-poses file of the RX-90 scene: n random joint sets, T_cam_target of the truth x_true (default the
    scene's) with 0.1 mm / 0.3 mrad noise (the file's declared sigma)."""
    scene = load_scene(RX90)
    rp, rn, _ = rngs(seed)
    q = scene_poses(scene, rp, n)
    x_true = scene_truth(scene) if x_true is None else x_true
    noise = np.concatenate([rn.normal(scale=1e-4, size=(n, 3)), rn.normal(scale=3e-4, size=(n, 3))], axis=1)
    T = F.perturb_pose(scene.setup.T_cam_target(q, x_true), noise)
    return write_measured_poses(path, str(RX90), [f"p{i:02d}" for i in range(n)], q, T, "T_cam_target",
                                default_sigma=(1e-4, 3e-4), folds=3)


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """{A, B: same truth, other noise and poses; C: another true robot}: process-poses result folders."""
    d = tmp_path_factory.mktemp("compare")
    scene = load_scene(RX90)
    x_other = scene_truth(scene).copy()
    ps = scene.setup.params
    x_other[ps.index("theta3")] += np.radians(0.2)
    x_other[ps.index("a3")] += 0.5e-3
    out = {}
    for name, seed, xt in (("A", 8, None), ("B", 9, None), ("C", 10, x_other)):
        f = _pose_file(d / f"{name}.yaml", seed, xt)
        assert main(["process-poses", str(f), "--out", str(d / name), "--no-plots"]) == 0
        out[name] = d / name
    return out


def test_map_in_report_and_page(results):
    rep = json.loads((results["A"] / "report.json").read_text())
    m = rep["accuracy_map"]
    assert m["n_points"] == len(m["points"]) and m["r95_mm"]["inside"]["n"] >= 30
    assert all(p["r95_mm"] > 0 and len(p["q_rad"]) == 6 for p in m["points"])
    assert "accuracy map (" in rep["summary_text"]
    html = (results["A"] / "report.html").read_text()  # a --no-plots run: the table, not the slices
    assert "<h2>Accuracy map</h2>" in html and "r95 position [mm] median" in html and "not drawn with --no-plots" in html
    from vision_calib.report.html import report_html

    assert 'alt="accuracy map"' in report_html(rep, results["A"])  # with the pictures


def test_compare_exit_codes(results, tmp_path, capsys):
    assert main(["compare", str(results["A"]), str(results["B"]), "--out", str(tmp_path / "ab")]) == 0
    ab = json.loads((tmp_path / "ab" / "compare.json").read_text())
    assert ab["decision"]["consistent"] and ab["parameters"]["dof"] == len(ab["parameters"]["compared"])
    assert {r["name"] for r in ab["parameters"]["not_compared"]} == {"d6", "theta6"}  # they carry the camera mount
    assert "<h2>Accuracy map: normalised difference" in (tmp_path / "ab" / "report.html").read_text()
    assert main(["compare", str(results["A"]), str(results["C"]), "--out", str(tmp_path / "ac")]) == 3
    ac = json.loads((tmp_path / "ac" / "compare.json").read_text())
    assert not ac["decision"]["consistent"]
    assert ac["decision"]["moved"][0] == "theta3"  # C's truth: theta3 + 0.2 deg (and a3 + 0.5 mm, 1.5 std)
    t3 = next(r for r in ac["parameters"]["compared"] if r["name"] == "theta3")
    assert abs(t3["moved_by"] - np.radians(0.2)) < 4 * t3["moved_by_std"]
    assert ac["map"]["share_beyond_95"] > ab["map"]["share_beyond_95"]
    capsys.readouterr()
    # bad input: named, exit 2
    assert main(["compare", str(results["A"]), str(tmp_path / "missing"), "--out", str(tmp_path / "x")]) == 2
    assert "missing: no such result folder" in capsys.readouterr().err
    other = tmp_path / "other_robot"
    shutil.copytree(results["B"], other)
    robot = next((other / "robot").glob("*.yaml"))
    doc = yaml.safe_load(robot.read_text())
    robot.write_text(robot.read_text().replace("a: 45,", "a: 46,", 1))  # a3 = 0.46 m: another robot model
    assert doc != yaml.safe_load(robot.read_text())
    assert main(["compare", str(results["A"]), str(other), "--out", str(tmp_path / "y")]) == 2
    assert "not the same robot" in capsys.readouterr().err
    nan = tmp_path / "nan_cov"
    shutil.copytree(results["B"], nan)
    mp = nan / "calibrated_model.yaml"
    m = yaml.safe_load(mp.read_text())
    m["covariance"]["matrix"][0][0] = float("nan")
    mp.write_text(yaml.safe_dump(m, sort_keys=False))
    assert main(["compare", str(results["A"]), str(nan), "--out", str(tmp_path / "z")]) == 2
    assert "calibrated_model.yaml" in capsys.readouterr().err


def test_parameter_test_of_a_result_against_itself_and_one_shift():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(6, 6))
    S = A @ A.T + 0.1 * np.eye(6)
    names = [f"p{i}" for i in range(6)]
    same = parameter_test(names, np.zeros(6), S)
    assert same["chi2"] == 0.0 and not same["differ"] and same["dof"] == 6
    d = np.zeros(6)
    d[2] = 8.0 / np.sqrt(np.linalg.inv(S)[2, 2])  # 8 conditional std on p2 alone
    t = parameter_test(names, d, S)
    assert t["differ"] and t["rows"][2]["shift_z"] == pytest.approx(8.0)
    assert max(t["rows"], key=lambda r: abs(r["shift_z"]))["name"] == "p2"
    assert t["moved"][0] == "p2" and t["rows"][2]["moved_by"] == pytest.approx(d[2])  # named first, its shift exact
