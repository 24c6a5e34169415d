"""Measured poses without images (io/measured_poses.py, experiment/poses.py, ``process-poses``): files
written from synthetic measurements of shipped scenes with a known truth are read back, mapped to the
setup's problem in either pose direction, identified within their predicted std, validated by k-fold,
and bad files give one line naming the file and key / pose, exit 2."""

import json

import numpy as np
import pytest

from vision_calib import cli
from vision_calib import frames as F
from vision_calib.experiment.poses import process_poses
from vision_calib.experiment.steps import analyze_setup, identify_measurements, rngs, scene_truth, truth_poses
from vision_calib.io.measured_poses import read_measured_poses
from vision_calib.io.measured_poses_writer import write_measured_poses
from vision_calib.io.model_export import load_calibrated_model
from vision_calib.rig import SCENES_DIR, load_scene, scene_poses, true_parameters

RX90 = str(SCENES_DIR / "rx90_eye_in_hand.yaml")
UR5E = str(SCENES_DIR / "ur5e_eye_in_hand.yaml")
ST, SR = 1e-4, float(np.radians(0.02))  # 0.1 mm, 0.02 deg per component


@pytest.fixture(scope="module")
def truths():
    """{scene path: (scene, x_true)} with the scene's truth (truth seed)."""
    out = {}
    for p in (RX90, UR5E):
        sc = load_scene(p)
        out[p] = (sc, scene_truth(sc))
    return out


def _ids(n):
    return [f"p{i:03d}" for i in range(n)]


def _data(scene, x_true, seed, n=40, direction="T_cam_target"):
    """(q (n, 6) rad, rows T (n, 4, 4) of ``direction`` with N(0, ST/SR) noise per component in that
    direction's reference frame)."""
    rp, rn, _ = rngs(seed)
    q = scene_poses(scene, rp, n)
    T = scene.setup.T_cam_target(q, x_true)
    if direction == "T_target_cam":
        T = F.inv_T(T)
    d = np.concatenate([rn.normal(scale=ST, size=(n, 3)), rn.normal(scale=SR, size=(n, 3))], axis=1)
    return q, F.perturb_pose(T, d)


def _identify(path):
    mp = read_measured_poses(path)
    res = identify_measurements(mp.scene.setup, mp.measurements, "lse", mp.residual, robust=False).result
    return mp, res


def _z(res, x_true):
    f = res.free
    return (res.identified[f] - x_true[f]) / res.std[f]


@pytest.mark.parametrize("scene_path", [RX90, UR5E])
def test_both_pose_directions_give_identical_parameters(tmp_path, truths, scene_path):
    """T_cam_target rows with per-component sigmas and the same data as T_target_cam rows with the same
    noise carried over (full covariance, frames.inverse_error_map) identify the same robot."""
    scene, x_true = truths[scene_path]
    q, T = _data(scene, x_true, seed=5)
    sig = np.tile([ST] * 3 + [SR] * 3, (len(q), 1))
    a = write_measured_poses(tmp_path / "a.yaml", scene_path, _ids(len(q)), q, T, "T_cam_target", sigmas=sig)
    G = F.inverse_error_map(T)
    cov = G @ np.einsum("ni,ij->nij", sig**2, np.eye(6)) @ np.swapaxes(G, 1, 2)
    b = write_measured_poses(tmp_path / "b.yaml", scene_path, _ids(len(q)), q, F.inv_T(T), "T_target_cam", cov=cov)
    mpa, ra = _identify(a)
    mpb, rb = _identify(b)
    np.testing.assert_allclose(mpb.measurements.T_cam_target, T, atol=1e-12)
    np.testing.assert_allclose(mpb.measurements.cov, mpa.measurements.cov, rtol=1e-9, atol=1e-20)
    assert np.array_equal(ra.free, rb.free) and ra.free.sum() == 30
    # the same minimum: both solves stop within the solver's tolerance of it (differences ~5e-9 of the std)
    assert np.max(np.abs(rb.identified - ra.identified)[ra.free] / ra.std[ra.free]) < 1e-7
    np.testing.assert_allclose(rb.std[ra.free], ra.std[ra.free], rtol=1e-9)


def test_mm_and_deg_units_give_the_same_robot(tmp_path, truths):
    scene, x_true = truths[RX90]
    q, T = _data(scene, x_true, seed=6)
    sig = np.tile([ST] * 3 + [SR] * 3, (len(q), 1))
    a = write_measured_poses(tmp_path / "m.yaml", RX90, _ids(len(q)), q, T, "T_cam_target", sigmas=sig)
    b = write_measured_poses(tmp_path / "mm.yaml", RX90, _ids(len(q)), q, T, "T_cam_target", sigmas=sig,
                             units={"length": "mm", "angle": "deg"})
    (_, ra), (_, rb) = _identify(a), _identify(b)
    f = ra.free
    np.testing.assert_allclose(rb.std[f], ra.std[f], rtol=1e-6)  # sigma columns converted from mm / deg
    assert np.max(np.abs(rb.identified[f] - ra.identified[f]) / ra.std[f]) < 1e-3  # solver tolerance only


@pytest.mark.parametrize("direction", ["T_cam_target", "T_target_cam"])
def test_full_pose_recovery_within_predicted_std(tmp_path, truths, direction):
    """Noise drawn in the frame the file names: identified - truth within 4 predicted std, z-score RMS
    near 1 over 4 seeds (a covariance mapped to the wrong frame would mis-weight and mis-predict)."""
    scene, x_true = truths[RX90]
    z = []
    for seed in range(4):
        q, T = _data(scene, x_true, seed=10 + seed, direction=direction)
        p = write_measured_poses(tmp_path / f"s{seed}.yaml", RX90, _ids(len(q)), q, T, direction,
                                 default_sigma=(ST, SR))
        _, res = _identify(p)
        assert res.converged
        z.append(_z(res, x_true))
    z = np.concatenate(z)
    assert np.abs(z).max() < 4.0
    assert 0.5 <= np.sqrt(np.mean(z**2)) <= 1.6


def test_position_only_recovery_in_mm(tmp_path, truths):
    """p_target_cam rows in mm (eye-in-hand: the camera's position in the target frame), default sigma
    in the YAML: the 27 position-only base parameters recovered within their predicted std."""
    scene, _ = truths[RX90]
    setup = scene.setup
    rep, _ = analyze_setup(setup, truth_poses(scene), "position")
    x_true = true_parameters(scene, np.random.default_rng(3), setup.params.mask(rep.base_parameters))
    z = []
    for seed in range(4):
        rp, rn, _ = rngs(20 + seed)
        q = scene_poses(scene, rp, 40)
        T = F.inv_T(setup.T_cam_target(q, x_true))
        T[:, :3, 3] += rn.normal(scale=ST, size=(len(q), 3))
        p = write_measured_poses(tmp_path / f"p{seed}.yaml", RX90, _ids(len(q)), q, T, "p_target_cam",
                                 units={"length": "mm", "angle": "deg"}, default_sigma=(ST, None))
        mp, res = _identify(p)
        assert mp.residual == "position" and res.free.sum() == 27
        z.append(_z(res, x_true))
    z = np.concatenate(z)
    assert np.abs(z).max() < 4.0
    assert 0.5 <= np.sqrt(np.mean(z**2)) <= 1.6


def test_kfold_held_out_residuals_drop(tmp_path, truths):
    scene, x_true = truths[RX90]
    q, T = _data(scene, x_true, seed=7)
    p = write_measured_poses(tmp_path / "k.yaml", RX90, _ids(len(q)), q, T, "T_cam_target",
                             default_sigma=(ST, SR), folds=4, seed=3)
    rep = process_poses(p, tmp_path / "out", plots=False)
    kf = rep["holdout"]
    assert kf["folds"] == 4 and sum(f["n_test"] for f in kf["per_fold"]) == len(q)
    n_free = sum(r["free"] for r in rep["parameters"])
    for f in kf["per_fold"] + [kf["overall"]]:
        assert f.get("n_identified", n_free) == n_free  # the same base set in every fold
        assert f["after"]["position_rms_mm"] < 0.5 * f["before"]["position_rms_mm"]
        assert f["after"]["rotation_rms_deg"] < 0.5 * f["before"]["rotation_rms_deg"]
    assert "held-out 4-fold validation" in rep["summary_text"]
    assert not rep["outliers"] and kf["without_outliers"] is None and kf["overall"]["n_poses"] == len(q)
    assert f"all {len(q)} poses (none flagged as an outlier)" in rep["summary_text"]
    on_disk = json.loads((tmp_path / "out" / "report.json").read_text())
    assert on_disk["kind"] == "process_poses" and on_disk["holdout"]["overall"] == kf["overall"]


def test_cli_process_poses_end_to_end(tmp_path, truths, capsys):
    scene, x_true = truths[UR5E]
    q, T = _data(scene, x_true, seed=8, n=30)
    sig = np.tile([ST] * 3 + [SR] * 3, (len(q), 1))
    p = write_measured_poses(tmp_path / "u.yaml", UR5E, _ids(len(q)), q, F.inv_T(T), "T_target_cam",
                             units={"length": "mm", "angle": "deg"}, sigmas=sig)
    out = tmp_path / "out"
    rc = cli.main(["process-poses", str(p), "--out", str(out), "--folds", "3", "--method", "lse"])
    text = capsys.readouterr().out
    assert rc == 0 and "held-out 3-fold validation" in text
    rep = json.loads((out / "report.json").read_text())
    assert rep["verdict"]["converged"] and rep["settings"]["measured"] == "T_target_cam"
    assert {"model", "urdf", "residuals_plot"} <= set(rep["files"])
    chain = load_calibrated_model(out / "calibrated_model.yaml")
    ident = {r["name"]: r["identified"] for r in rep["parameters"]}
    assert np.allclose(chain.params.nominal, [ident[n] for n in chain.params.names])


# ----------------------------------------------------------------------------- bad input: exit 2, named
def _edit_csv(text, row, col, value):
    lines = text.splitlines()
    head = lines[0].split(",")
    cells = lines[row + 1].split(",")
    cells[head.index(col)] = value
    lines[row + 1] = ",".join(cells)
    return "\n".join(lines) + "\n"


def _drop_col(text, name):
    rows = [ln.split(",") for ln in text.splitlines()]
    k = rows[0].index(name)
    return "\n".join(",".join(r[:k] + r[k + 1:]) for r in rows) + "\n"


def _add_col(text, name, value):
    lines = text.splitlines()
    return "\n".join([lines[0] + f",{name}"] + [ln + f",{value}" for ln in lines[1:]]) + "\n"


BAD = {  # name: (writer kwargs, yaml edit, csv edit, needles)
    "yaml typo": ({}, lambda y: y.replace("folds:", "fold:"), None, ["a.yaml", "fold", "did you mean 'folds'"]),
    "no units": ({}, lambda y: y.replace("units:\n  length: m\n  angle: rad\n", ""), None,
                 ["a.yaml", "units", "missing"]),
    "format": ({}, lambda y: y.replace("measured_poses/1", "measured_poses/9"), None, ["a.yaml", "format"]),
    "direction": ({}, lambda y: y.replace("T_cam_target", "T_cam_flange"), None, ["a.yaml", "measured"]),
    "unknown column": ({}, None, lambda c: c.replace("sigma_rx", "sigma_rot_x"), ["a.csv", "sigma_rot_x"]),
    "non-unit quaternion": ({}, None, lambda c: _edit_csv(c, 2, "qw", "2.0"), ["a.csv", "line 4", "p002", "quaternion"]),
    "NaN": ({}, None, lambda c: _edit_csv(c, 1, "x", "nan"), ["a.csv", "line 3", "p001", "column x"]),
    "text": ({}, None, lambda c: _edit_csv(c, 1, "q2", "abc"), ["a.csv", "p001", "column q2", "not a number"]),
    "7 joints": ({}, None, lambda c: _add_col(c, "q7", "0.0"), ["a.csv", "q7", "6 joints"]),
    "missing joint": ({}, None, lambda c: _drop_col(c, "q6"), ["a.csv", "missing column 'q6'"]),
    "duplicate id": ({}, None, lambda c: _edit_csv(c, 1, "pose_id", "p000"), ["a.csv", "duplicate", "p000"]),
    "sigma <= 0": ({}, None, lambda c: _edit_csv(c, 3, "sigma_y", "0"), ["a.csv", "p003", "sigma_y"]),
    "deg read as rad": ({"units": {"length": "m", "angle": "deg"}}, lambda y: y.replace("angle: deg", "angle: rad"),
                        None, ["a.csv", "outside the robot's limits"]),
    "mm read as m": ({"units": {"length": "mm", "angle": "rad"}}, lambda y: y.replace("length: mm", "length: m"),
                     None, ["a.csv", "x,y,z", "units.length"]),
    "missing sigmas": ({"sigmas": None}, None, None, ["a.yaml", "default_sigma", "required"]),
    "sigmas twice": ({"default_sigma": (ST, SR)}, None, None, ["a.yaml", "default_sigma", "remove one"]),
    "position from the wrong side": ({"measured": "p_cam_target"}, None, None, ["a.yaml", "measured", "p_target_cam"]),
    "rotation sigma for positions": ({"measured": "p_target_cam", "sigmas": None, "default_sigma": (ST, SR)},
                                     lambda y: y.replace("default_sigma:\n", "default_sigma:\n  r_deg: 0.02\n"),
                                     None, ["a.yaml", "default_sigma.r_deg", "position-only"]),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_files_exit_2_naming_file_and_key(tmp_path, truths, capsys, case):
    kw, yedit, cedit, needles = BAD[case]
    scene, x_true = truths[RX90]
    q, T = _data(scene, x_true, seed=9, n=12)
    args = {"measured": "T_cam_target", "sigmas": np.tile([ST] * 3 + [SR] * 3, (12, 1)), **kw}
    if args["measured"].startswith("p_") and args["sigmas"] is not None:
        args["sigmas"] = args["sigmas"][:, :3]
    if args["measured"] == "p_target_cam":
        T = F.inv_T(T)
    p = write_measured_poses(tmp_path / "a.yaml", RX90, _ids(12), q, T, **args)
    if yedit:
        p.write_text(yedit(p.read_text()))
    if cedit:
        c = tmp_path / "a.csv"
        c.write_text(cedit(c.read_text()))
    rc = cli.main(["process-poses", str(p), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    for n in needles:
        assert n in err, (n, err)
    assert not (tmp_path / "out" / "report.json").exists()


def test_kfold_holds_out_every_pose_planted_outliers_labelled(tmp_path, truths):
    """Two poses with a planted 5 mm gross error: the whole-data fit flags them; the held-out figure counts
    all 40 poses (each outlier predicted by a model fitted without it, so its held-out error is the planted
    one), the figure without them counts 38 and names them, mean <= RMS <= max, and the summary gives one
    rejected count."""
    import re

    scene, x_true = truths[RX90]
    n, bad, gross = 40, (5, 21), 5e-3
    q, T = _data(scene, x_true, seed=12, n=n)
    for k in bad:  # translation-only error: its norm is the same in either pose direction
        d = np.random.default_rng(k).normal(size=3)
        T[k, :3, 3] += gross * d / np.linalg.norm(d)
    p = write_measured_poses(tmp_path / "o.yaml", RX90, _ids(n), q, T, "T_cam_target",
                             default_sigma=(ST, SR), folds=5, seed=1)
    rep = process_poses(p, tmp_path / "out", plots=False)
    planted = [_ids(n)[k] for k in bad]
    assert sorted(o["pose_id"] for o in rep["outliers"]) == planted
    kf = rep["holdout"]
    o, c = kf["overall"], kf["without_outliers"]
    assert sorted(kf["outliers"]) == planted and c["excluded"] == planted
    assert o["n_poses"] == n and sum(f["n_test"] for f in kf["per_fold"]) == n
    assert c["n_poses"] == n - 2 and sum(f["n_outliers_held_out"] for f in kf["per_fold"]) == 2
    assert all(f["n_train"] == n - f["n_test"] - (2 - f["n_outliers_held_out"]) for f in kf["per_fold"])
    for blk in (o, c, *kf["per_fold"]):
        for s in (blk["before"], blk["after"]):
            for key in ("position", "rotation"):
                u = "mm" if key == "position" else "deg"
                assert 0 < s[f"{key}_mean_{u}"] <= s[f"{key}_rms_{u}"] <= s[f"{key}_max_{u}"]
    a_all, a_clean = o["after"], c["after"]
    # the overall figure is the per-fold ones pooled, and its excess over the clean one is the outliers' error
    assert np.isclose(sum(f["n_test"] * f["after"]["position_rms_mm"] ** 2 for f in kf["per_fold"]),
                      n * a_all["position_rms_mm"] ** 2)
    excess = np.sqrt((n * a_all["position_rms_mm"] ** 2 - (n - 2) * a_clean["position_rms_mm"] ** 2) / 2)
    assert abs(excess - gross * 1e3) < 0.1 * gross * 1e3, excess
    assert a_all["position_max_mm"] > 0.9 * gross * 1e3 > 5 * a_clean["position_max_mm"]
    text = rep["summary_text"]
    assert f"all {n} poses (the 2 flagged outliers included)" in text
    assert f"without the 2 flagged outliers ({', '.join(planted)}), {n - 2} poses" in text
    assert "position mean" in text and "RMS" in text and "max" in text
    counts = re.findall(r"\b(\d+) (?:\w+ )?(?:poses? )?rejected", text)
    assert counts and set(counts) == {"2"}, counts
    assert "0 rejected" not in text


def test_kfold_validation_rejects_unknown_outlier_labels(truths):
    from vision_calib.experiment.holdout import holdout_validation
    from vision_calib.experiment.steps import analyze_setup

    scene, x_true = truths[RX90]
    q, T = _data(scene, x_true, seed=13, n=12)
    setup = scene.setup
    meas = setup.synthetic_measurements(q, x_true, np.random.default_rng(0), ST, SR)
    with pytest.raises(ValueError, match="p999"):
        holdout_validation(setup, meas, "lse", "pose", analyze_setup(setup, q), 3, 0, outliers=["p999"])


def test_fold_fit_without_diagnostics_and_generic_rank_once(truths):
    """diagnostics=False (a held-out fold's fit) gives the same parameters without the lack-of-fit tests; the
    generic poses' rank is the same for a setup and its copy with another camera (computed once)."""
    from dataclasses import replace

    from vision_calib.experiment.steps import generic_rank

    scene, x_true = truths[RX90]
    setup = scene.setup
    q, T = _data(scene, x_true, seed=3, n=30)
    meas = setup.synthetic_measurements(q, x_true, np.random.default_rng(0), ST, SR)
    a = identify_measurements(setup, meas, "lse", "pose", robust=False)
    b = identify_measurements(setup, meas, "lse", "pose", robust=False, diagnostics=False)
    assert a.lack_of_fit is not None and b.lack_of_fit is None
    assert np.array_equal(a.result.identified, b.result.identified)
    assert np.array_equal(a.result.std, b.result.std, equal_nan=True)
    ref, _ = analyze_setup(setup, setup.generic_poses(np.random.default_rng(12345), 200), "pose")
    cam = replace(setup.camera, fx=setup.camera.fx * 1.05)
    assert generic_rank(setup, "pose") == generic_rank(setup.with_camera(cam), "pose") == (
        ref.rank, tuple(ref.non_identifiable))


@pytest.mark.parametrize("scene_key", [RX90, UR5E])
def test_fold_fit_from_the_whole_fit_reaches_the_same_minimum(truths, scene_key):
    """identify_measurements(start=): the least squares started from a nearby fit (the whole data's, as the held-out
    folds do) ends at the same minimum as from the nominal model (1e-6 std), in no more steps (measured: the same 3
    Jacobians, 4 residual evaluations instead of 4 / 7); the held-out block
    of holdout_validation with the whole fit given equals the one without (1e-6 relative)."""
    from vision_calib.experiment.holdout import holdout_validation
    from vision_calib.experiment.steps import analyze_setup

    scene, x_true = truths[scene_key]
    setup = scene.setup
    q, T = _data(scene, x_true, seed=5, n=30)
    meas = setup.synthetic_measurements(q, x_true, np.random.default_rng(1), ST, SR)
    whole = identify_measurements(setup, meas, "lse", "pose", robust=False)
    res = whole.result
    start = {nm: v for nm, v, f in zip(res.names, res.identified, res.free) if f}
    sub = meas.subset(np.arange(24))
    a = identify_measurements(setup, sub, "lse", "pose", robust=False, diagnostics=False)
    b = identify_measurements(setup, sub, "lse", "pose", robust=False, diagnostics=False, start=start)
    free = a.result.free
    assert np.max(np.abs(b.result.info["x0"] - a.result.info["x0"])[free] / a.result.std[free]) > 0.5  # moved start
    assert np.max(np.abs(b.result.identified - a.result.identified)[free] / a.result.std[free]) < 1e-6
    assert b.result.info["nfev"] <= a.result.info["nfev"] and b.result.info["njev"] <= a.result.info["njev"]
    rep, _ = analyze_setup(setup, q, "pose")
    h0 = holdout_validation(setup, meas, "lse", "pose", rep, 3, 0)
    h1 = holdout_validation(setup, meas, "lse", "pose", rep, 3, 0, result=res, fitted_setup=whole.setup)
    for f0, f1 in zip(h0["per_fold"], h1["per_fold"]):
        for key, v in f0["after"].items():
            assert f1["after"][key] == pytest.approx(v, rel=1e-6), key
