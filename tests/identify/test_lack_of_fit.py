"""Lack-of-fit tests (identify/lack_of_fit.py) on the planar 3R toy: null distribution of the p-values, a
planted joint harmonic found and named, a constant joint error absorbed by the joint offset, the
detectable amplitudes against the measured detection rate, the verdict text."""

import dataclasses

import numpy as np
import pytest
from scipy import stats
from toy_models import NAMES, planar_model, planar_params, planar_problem, true_deviation

from vision_calib.errors import ConfigError
from vision_calib.identify import solve_lse
from vision_calib.identify.lack_of_fit import lack_of_fit, parameter_shift
from vision_calib.report.build import verdict
from vision_calib.report.summary import verdict_line

#: base.theta and q0_1 enter only through their sum: identify q0_1
FREE = [n for n in NAMES if n != "base.theta"]
OFFSETS = [NAMES.index(f"q0_{j}") for j in (1, 2, 3)]
SIGMA_ANG = 2e-4


def _run(seed, amp=0.0, phase=0.0, order=2, joint=1, offset=0.0, free=FREE, n_poses=40, cov_factor=1.0,
         test="F", level=0.01):
    """(lack_of_fit dict, problem, result): the toy arm whose TRUE joint ``joint`` (0-based) is at
    q + offset + amp sin(order q + phase) while the reported joint is q; noise 0.1 mm / 0.2 mrad; obs_cov x
    cov_factor (wrong scale)."""
    rng = np.random.default_rng(seed)
    x_true = true_deviation(rng)
    x_true[NAMES.index("base.theta")] = 0.0
    prob, q = planar_problem(x_true, n_poses=n_poses, rng=rng, params=planar_params().only_free(free),
                             sigma_ang=SIGMA_ANG)
    qt = q.copy()
    qt[:, joint] += offset + amp * np.sin(order * q[:, joint] + phase)
    y = prob.meta["y"]  # the toy residual reads this array
    y[:] = planar_model(x_true, qt)[0] + rng.standard_normal(y.shape) @ np.linalg.cholesky(prob.obs_cov[0]).T
    prob = dataclasses.replace(prob, obs_cov=prob.obs_cov * cov_factor, meta=dict(prob.meta, x_true=x_true))
    res = solve_lse(prob)
    G = -np.asarray(prob.jacobian(res.identified))[:, :, OFFSETS]  # d residual / d true joint error
    return lack_of_fit(prob, res, joints=q, joint_response=G, level=level, test=test), prob, res


@pytest.mark.parametrize("cov_factor,test", [(1.0, "F"), (0.25, "F"), (1.0, "chi2")])
def test_null_p_values_uniform(cov_factor, test):
    """A right model: the group p-values are uniform (KS) and the family-wise flag rate stays at the level,
    for the F test also with obs_cov 4x too optimistic (the F test does not trust its scale; chi2 does)."""
    n = 150
    ps, flagged = [], 0
    for s in range(n):
        lof, _, _ = _run(1000 + s, cov_factor=cov_factor, test=test)
        ps += [g["p_value"] for g in lof["groups"]]
        flagged += lof["significant"]
    ps = np.array(ps)
    assert stats.kstest(ps, "uniform").pvalue > 1e-3
    frac = np.mean(ps < 0.05)
    band = 3.3 * np.sqrt(0.05 * 0.95 / ps.size)
    assert abs(frac - 0.05) < band, frac
    assert flagged <= stats.binom.isf(1e-3, n, 0.01), flagged


def test_optimistic_covariance_breaks_chi2_variant_only():
    """The chi2 variant trusts obs_cov: 4x too optimistic it flags clean data; the default F test does not."""
    lof_c, _, _ = _run(7, cov_factor=0.25, test="chi2")
    lof_f, _, _ = _run(7, cov_factor=0.25, test="F")
    assert lof_c["significant"] and not lof_f["significant"]


@pytest.mark.parametrize("joint,order", [(1, 2), (2, 1)])
def test_detects_planted_harmonic_and_names_joint(joint, order):
    amp, phase = 1.5e-3, 0.7
    lof, _, _ = _run(3, amp=amp, phase=phase, order=order, joint=joint)
    assert lof["significant"]
    top = min(lof["groups"], key=lambda g: g["p_value"])
    assert top["name"] == f"joint {joint + 1}" and top["significant"] and top["best_order"] == order
    h = next(h for h in top["harmonics"] if h["order"] == order)
    assert abs(h["amplitude_deg"] - np.degrees(amp)) < 4 * h["amplitude_std_deg"]
    assert h["amplitude_std_deg"] < 0.2 * np.degrees(amp)
    assert abs(np.angle(np.exp(1j * (np.radians(h["phase_deg"]) - phase)))) < 0.3
    assert f"residuals depend on joint {joint + 1} (sin/cos {order} q{joint + 1}, amplitude" in lof["message"]


def test_constant_joint_error_is_absorbed_by_the_offset():
    """A constant error on joint 2 is a joint offset: with q0_2 free nothing is flagged (and q0_2 takes it);
    with q0_2 fixed the same data flag joint 2."""
    off = 1e-2  # 0.57 deg
    lof, prob, res = _run(5, offset=off)
    assert not lof["significant"]
    assert abs(res.value("q0_2") - prob.meta["x_true"][NAMES.index("q0_2")] - off) < 4 * res.std_of("q0_2")
    fixed, _, _ = _run(5, offset=off, free=[n for n in FREE if n != "q0_2"])
    top = min(fixed["groups"], key=lambda g: g["p_value"])
    assert fixed["significant"] and top["name"] == "joint 2" and top["best_order"] == 0
    assert "residuals depend on joint 2 (a constant q2 offset" in fixed["message"]


def test_detectable_amplitude_matches_detection_rate():
    """At the reported worst-phase detectable amplitude (power 0.8 whatever the phase) joint 2 is flagged in
    most draws; at a third of the best-phase one (noncentrality / 9) rarely."""
    lof0, _, _ = _run(11, n_poses=20)
    h = next(h for h in next(g for g in lof0["groups"] if g["name"] == "joint 2")["harmonics"] if h["order"] == 2)
    best, worst = (np.radians(a) for a in h["detectable_amplitude_deg"])
    assert 0 < best <= worst
    hit_big = hit_small = 0
    n = 60
    for s in range(n):  # same poses (seed 11's q come first from the rng): phases and noise vary via the seed
        ph = np.random.default_rng(s).uniform(0, 2 * np.pi)
        g_big = next(g for g in _run(11, amp=worst, phase=ph, n_poses=20)[0]["groups"] if g["name"] == "joint 2")
        g_small = next(g for g in _run(11, amp=best / 3, phase=ph, n_poses=20)[0]["groups"] if g["name"] == "joint 2")
        hit_big += g_big["significant"]
        hit_small += g_small["significant"]
    assert hit_big >= 0.65 * n and hit_small <= 0.25 * n, (hit_big, hit_small)


def test_image_and_depth_groups_and_bad_input():
    """Image-position and depth regressors: a residual proportional to the depth is flagged as 'depth'."""
    rng = np.random.default_rng(2)
    x_true = true_deviation(rng)
    x_true[NAMES.index("base.theta")] = 0.0
    prob, q = planar_problem(x_true, n_poses=40, rng=rng, params=planar_params().only_free(FREE))
    z = rng.uniform(0.5, 1.0, len(q))
    xy = rng.uniform(-0.3, 0.3, (len(q), 2))
    prob.meta["y"][:, 0] += 3e-4 * (z / z.mean() - 1) / 0.15  # 0.3 mm per 15 % of depth on x
    res = solve_lse(prob)
    lof = lack_of_fit(prob, res, image_xy=xy, depth=z)
    names = {g["name"]: g for g in lof["groups"]}
    assert set(names) == {"image position", "depth"} and lof["n_tests"] == 2  # the overall test informs only
    assert names["depth"]["significant"] and not names["image position"]["significant"]
    assert "depth" in lof["message"]
    with pytest.raises(ConfigError):
        lack_of_fit(prob, res, depth=z, level=0)
    from vision_calib.errors import DataError

    with pytest.raises(DataError, match="image_xy"):
        lack_of_fit(prob, res, image_xy=xy[:5])


def test_parameter_shift_matches_refit():
    """First-order parameter shift for a residual change dR = the actual change of a refit."""
    lof, prob, res = _run(4)
    dR = np.zeros((prob.n_obs, prob.m))
    dR[:, 2] = 2e-4  # every orientation measurement 0.2 mrad more: a joint offset takes it
    pred = parameter_shift(prob, res, dR)[:, 0]
    y = prob.meta["y"]
    y += dR
    refit = solve_lse(prob, res.identified)
    actual = refit.identified - res.identified
    assert np.allclose(pred, actual, atol=1e-3 * np.abs(actual).max() + 1e-12)
    assert abs(pred[NAMES.index("q0_1")] + pred[NAMES.index("q0_2")] + pred[NAMES.index("q0_3")] - 2e-4) < 2e-5


def test_verdict_names_the_term():
    lof, _, res = _run(3, amp=1.5e-3, phase=0.7)
    v = verdict(res, lack_of_fit=lof)
    assert v["status"] == "warning" and not v["ok"] and v["lack_of_fit"] is True
    assert v["message"].startswith("residuals depend on joint 2 (sin/cos 2 q2, amplitude 0.0")
    assert v["message"].endswith("an error the model lacks")
    assert verdict_line(v).startswith("verdict: WARNING: residuals depend on joint 2")
    clean, _, res0 = _run(1000)
    v0 = verdict(res0, lack_of_fit=clean)
    assert v0["status"] == "ok" and v0["message"] == "" and v0["lack_of_fit"] is False
