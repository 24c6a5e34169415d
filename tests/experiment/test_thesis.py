"""Thesis (seed 003) chapters 3-4 on scenes/thesis_arm_ch3.yaml: what a position-measuring device
identifies on the thesis' configurations, recovery of its deviation vectors, LSE vs EKF, and the
study runner's ``trial`` axis."""

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from vision_calib.errors import ConfigError
from vision_calib import study as S
from vision_calib.rig import load_scene, scene_poses
from vision_calib.experiment.steps import scene_truth
from vision_calib.experiment.synthetic import identifiability_json, run_synthetic

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "thesis_arm_ch3.yaml"


@pytest.fixture(scope="module")
def scene():
    return load_scene(SCENE)


def test_identifiability_names_thesis_couplings(scene):
    out = identifiability_json(scene)
    assert out["residual"] == "position" and out["n_poses"] == 7 and out["n_equations"] == 21
    assert out["n_params"] == 17 and out["rank"] == 15
    coup = {c["parameter"]: c for c in out["couplings"]}
    assert set(coup) == set(out["non_identifiable"])
    assert not coup["theta6"]["combination"]  # no effect: the measured point is on the z6 axis
    # one of (a6, theta5, d6) is dropped and expressed with the two others
    (dropped,) = set(coup) & {"a6", "theta5", "d6"}
    assert set(coup[dropped]["combination"]) == {"a6", "theta5", "d6"} - {dropped}
    # the exact pairs the thesis estimates separately are fixed by the model
    pairs = {frozenset(p[:2]) for p in scene.setup.chain.redundant_pairs()}
    assert {frozenset({"d3", "d2"}), frozenset({"l5", "d4"})} <= pairs
    # the other trial's configuration set has the same structure
    sc2 = S.scene_with_trial(scene, "lse_essai_2")
    out2 = identifiability_json(sc2)
    assert out2["rank"] == 15 and set(out2["non_identifiable"]) == set(out["non_identifiable"])


def test_trial_scene_uses_trial_configurations(scene):
    sc = S.scene_with_trial(scene, "ekf_essai_3")
    conf = scene.setup.chain.meta["configurations"]
    np.testing.assert_array_equal(scene_poses(sc, np.random.default_rng(0)), conf["annex_6_36"]["q"])
    x = scene_truth(sc)
    dev = scene.setup.chain.meta["trials"]["ekf_essai_3"]["deviation"]
    ps = scene.setup.params
    for k, v in dev.items():
        assert x[ps.index(k)] - ps.nominal[ps.index(k)] == pytest.approx(v, abs=1e-15)


@pytest.mark.parametrize("trial", ["lse_essai_1", "ekf_essai_2"])
def test_noise_free_recovers_identifiable_part(scene, trial):
    sc = S.scene_with_trial(scene, trial)
    ps = sc.setup.params
    o = run_synthetic(sc, sigma_t_m=0.0, sigma_r_rad=0.0)
    assert o.result.converged
    assert o.before["position_rms_mm"] > 1.0
    assert o.after["position_rms_mm"] < 1e-6  # every identifiable combination recovered
    xi, xt = o.result.identified, o.x_true
    dev = sc.setup.chain.meta["trials"][trial]["deviation"]
    # the exact duplicates are absorbed by their partners
    assert xi[ps.index("d2")] - ps.nominal[ps.index("d2")] == pytest.approx(dev["d2"] + dev["d3"], abs=1e-9)
    assert xi[ps.index("d4")] - ps.nominal[ps.index("d4")] == pytest.approx(dev["d4"] + dev["l5"], abs=1e-9)
    # joints 1-5 except theta5 are recovered as they are
    for n in ("a1", "a2", "a3", "a4", "a5", "theta1", "theta2", "theta3", "theta4", "d1", "d5"):
        assert xi[ps.index(n)] == pytest.approx(xt[ps.index(n)], abs=1e-9), n


def test_truth_without_non_identifiable_parts_recovered_exactly(scene):
    dev = dict(scene.setup.chain.meta["trials"]["lse_essai_1"]["deviation"])
    for n in ("d3", "l5", "theta6", "d6"):
        dev[n] = 0.0
    sc = replace(scene, truth=replace(scene.truth, trial=None, deviations=dev))
    o = run_synthetic(sc, sigma_t_m=0.0, sigma_r_rad=0.0)
    res, xt = o.result, o.x_true
    ps = sc.setup.params
    assert int(res.free.sum()) == 15
    for i in np.flatnonzero(res.free):
        assert res.identified[i] == pytest.approx(xt[i], abs=1e-9), ps.names[i]
    np.testing.assert_allclose(res.identified[~res.free], ps.nominal[~res.free])


def test_lse_and_ekf_agree(scene):
    a = run_synthetic(scene, method="lse", seed=3)
    b = run_synthetic(scene, method="ekf", seed=3)
    ra, rb = a.result, b.result
    np.testing.assert_array_equal(ra.free, rb.free)
    f = ra.free
    d = np.abs(ra.identified[f] - rb.identified[f]) / ra.std[f]
    assert d.max() < 0.05
    np.testing.assert_allclose(rb.std[f], ra.std[f], rtol=0.05)
    # the noise (0.1 mm) moves the estimate: a real, not a trivial, agreement
    assert np.max(np.abs(ra.identified[f] - a.x_true[f]) / ra.std[f]) > 0.1


def _spec(tmp_path, **kw):
    d = {"name": "thesis_tiny", "scene": str(SCENE), "repetitions": 2, "seed": 1,
         "sweep": {"trial": ["lse_essai_1", "lse_essai_2"], "method": ["lse", "ekf"]},
         "outputs": ["parameters", "accuracy"]}
    d.update(kw)
    p = tmp_path / "thesis_tiny.yaml"
    p.write_text(yaml.safe_dump(d, sort_keys=False))
    return p


def test_trial_axis_study(tmp_path, scene):
    spec = S.load_study(_spec(tmp_path))
    assert spec.axes == ("trial", "method")
    res = S.run_study(spec, tmp_path / "out", workers=1, plots=False)
    assert res["n_failed"] == 0 and res["n_runs"] == 8
    with open(tmp_path / "out" / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    # every identifiable parameter of every run lies within its predicted uncertainty of the trial's truth
    # (the non-identifiable parts of the truth are absorbed exactly: d3 by d2, l5 by d4, so those are excluded)
    r = next(r for r in rows if r["trial"] == "lse_essai_2" and r["method"] == "ekf" and r["repetition"] == "1")
    z = [float(x[f"err:{n}"]) / float(x[f"std:{n}"]) for x in rows for n in ("a2", "a3", "theta2", "d4")
         if x[f"std:{n}"] not in ("", "nan")]
    assert len(z) > 20 and np.max(np.abs(z)) < 5, np.max(np.abs(z))
    assert float(r["after_position_rms_mm"]) < float(r["before_position_rms_mm"])
    # same deviation vector, other identification configurations: other estimates
    r1 = next(x for x in rows if x["trial"] == "lse_essai_1" and x["method"] == "ekf" and x["repetition"] == "1")
    assert r1["before_position_rms_mm"] == r["before_position_rms_mm"]  # same truth, same validation joints
    assert r1["err:a2"] != r["err:a2"]
    # parameters.csv: truth, identifiability, noise-free value, thesis estimate per (cell, parameter)
    with open(tmp_path / "out" / "parameters.csv") as fh:
        prow = {(p["trial"], p["method"], p["parameter"]): p for p in csv.DictReader(fh)}
    dev = scene.setup.chain.meta["trials"]["lse_essai_1"]
    for n, v in dev["deviation"].items():
        p = prow[("lse_essai_1", "lse", n)]
        assert float(p["true_deviation"]) == pytest.approx(v, abs=1e-12)
        assert float(p["thesis_reported"]) == pytest.approx(dev["reported"][n], abs=1e-12)
    assert prow[("lse_essai_1", "lse", "theta6")]["identifiable"] == "no"
    assert "no effect" in prow[("lse_essai_1", "lse", "theta6")]["note"]
    assert "d2" in prow[("lse_essai_1", "lse", "d3")]["note"] and "d4" in prow[("lse_essai_1", "lse", "l5")]["note"]
    p = prow[("lse_essai_1", "ekf", "d2")]
    assert p["identifiable"] == "yes"
    assert float(p["noise_free"]) == pytest.approx(dev["deviation"]["d2"] + dev["deviation"]["d3"], abs=1e-9)
    # mean identified = true + mean error of the runs
    errs = [float(x["err:a2"]) for x in rows if x["trial"] == "lse_essai_1" and x["method"] == "ekf"]
    assert float(prow[("lse_essai_1", "ekf", "a2")]["identified_mean"]) == pytest.approx(
        dev["deviation"]["a2"] + np.mean(errs), abs=1e-12)
    assert "[trial=lse_essai_1]" in res["summary_text"] and "no effect" in res["summary_text"]


@pytest.mark.parametrize("sweep,key", [
    ({"trial": ["lse_essai_1", "essai_9"]}, "sweep.trial"),
    ({"trial": [3]}, "sweep.trial[0]"),
])
def test_bad_trial_names_spec_and_key(tmp_path, sweep, key):
    with pytest.raises(ConfigError) as ei:
        S.load_study(_spec(tmp_path, sweep=sweep))
    msg = str(ei.value)
    assert "thesis_tiny.yaml" in msg and key in msg


def test_trial_on_h4_scene_is_refused(tmp_path):
    p = _spec(tmp_path, scene=str(ROOT / "scenes" / "h4_vision.yaml"), sweep={"trial": ["lse_essai_1"]})
    with pytest.raises(ConfigError, match="sweep.trial.*unknown trial"):
        S.load_study(p)
