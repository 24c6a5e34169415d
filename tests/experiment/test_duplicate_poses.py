"""Poses copied under new ids, and poses measured again at the same joints (experiment/checks.py drop_copies,
same_joint_groups; experiment/holdout.py fold_indices groups; issue 28): a copy (same joints, measured pose within
a fraction of the noise, even with 1e-6 jitter) is named and counted once -- the std is not flattered by 1/sqrt(2);
a genuine repeat is kept, and a repeated set always lands in ONE held-out fold."""

from __future__ import annotations

import numpy as np
import pytest

from vision_calib import frames as F
from vision_calib.experiment.checks import (COPY_CHI2, SAME_JOINTS_TOL, drop_copies, duplicate_poses,
                                            same_joint_groups)
from vision_calib.experiment.holdout import fold_indices
from vision_calib.rig import Measurements

ST, SR = 1e-4, np.radians(0.02)


def _meas(n=30, seed=0, labels=None):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2, 2, size=(n, 6))
    T = F.perturb_pose(np.tile(np.eye(4), (n, 1, 1)), np.concatenate([rng.normal(scale=0.2, size=(n, 3)),
                                                                       rng.normal(scale=0.5, size=(n, 3))], axis=1))
    cov = np.tile(np.diag([ST**2] * 3 + [SR**2] * 3), (n, 1, 1))
    return Measurements(q, q, T, cov, tuple(labels or (f"p{i:02d}" for i in range(n))))


def _stack(a: Measurements, b: Measurements) -> Measurements:
    return Measurements(np.concatenate([a.poses, b.poses]), np.concatenate([a.joints, b.joints]),
                        np.concatenate([a.T_cam_target, b.T_cam_target]), np.concatenate([a.cov, b.cov]),
                        a.labels + b.labels)


def _jittered_copy(m: Measurements, idx, eps, prefix="copy"):
    sub = m.subset(idx)
    sign = np.where(np.arange(6) % 2, 1.0, -1.0)
    T = F.perturb_pose(sub.T_cam_target, np.tile(eps * sign, (len(idx), 1)))
    return Measurements(sub.poses + eps, sub.joints + eps, T, sub.cov, tuple(f"{prefix}{k}" for k in range(len(idx))))


@pytest.mark.parametrize("eps", [0.0, 1e-6])
def test_copies_are_named_and_counted_once(eps):
    m = _meas()
    both = _stack(m, _jittered_copy(m, range(30), eps))
    kept, copies = drop_copies(both)
    assert kept.labels == m.labels
    assert [c[0] for c in copies] == [f"copy{k}" for k in range(30)]
    assert copies[4][1].startswith("a copy of pose p04 (the same joints and measured pose, within")
    w = duplicate_poses(kept, copies)
    assert len(w) == 1 and w[0].startswith("30 poses are copies of another pose") and "copy0 = p00" in w[0]


def test_a_genuine_repeat_is_kept_and_grouped():
    """Same joints, measured again (independent noise at the stated sigma): not a copy."""
    m = _meas()
    rng = np.random.default_rng(5)
    again = m.subset(range(10))
    d = np.concatenate([rng.normal(scale=ST, size=(10, 3)), rng.normal(scale=SR, size=(10, 3))], axis=1)
    again = Measurements(again.poses, again.joints, F.perturb_pose(again.T_cam_target, d), again.cov,
                         tuple(f"again{k}" for k in range(10)))
    both = _stack(m, again)
    kept, copies = drop_copies(both)
    assert copies == [] and kept is both
    g = same_joint_groups(both)
    assert len(set(g.tolist())) == 30 and all(g[30 + k] == g[k] for k in range(10))
    w = duplicate_poses(both)
    assert len(w) == 1 and "10 poses were measured again at the same joints" in w[0] and "p00, again0" in w[0]


def test_joint_tolerance_and_chi2_threshold_are_what_they_say():
    m = _meas(2)
    assert np.all(same_joint_groups(m) == [0, 1])
    near = Measurements(m.poses, np.array([m.joints[0], m.joints[0] + 0.9 * SAME_JOINTS_TOL]), m.T_cam_target, m.cov,
                        m.labels)
    far = Measurements(m.poses, np.array([m.joints[0], m.joints[0] + 1.1 * SAME_JOINTS_TOL]), m.T_cam_target, m.cov,
                       m.labels)
    assert len(set(same_joint_groups(near).tolist())) == 1 and len(set(same_joint_groups(far).tolist())) == 2
    # a measured pose 0.9 / 1.1 x the copy threshold away (Mahalanobis^2 of the pair, covariances summed)
    for f, is_copy in ((0.9, True), (1.1, False)):
        step = np.sqrt(f * COPY_CHI2 * 2) * ST  # along x: d^2 / (2 ST^2) = f * COPY_CHI2
        T = np.array([m.T_cam_target[0], F.perturb_pose(m.T_cam_target[0], np.array([step, 0, 0, 0, 0, 0]))])
        pair = Measurements(m.poses, np.array([m.joints[0]] * 2), T, m.cov, m.labels)
        assert (len(drop_copies(pair)[1]) == 1) is is_copy


def test_grouped_folds_keep_repeats_together_and_stay_balanced():
    n = 40
    groups = np.arange(n)
    assert all(np.array_equal(a, b) for a, b in zip(fold_indices(n, 5, 3, groups), fold_indices(n, 5, 3)))
    groups = np.concatenate([np.arange(30), np.arange(10)])  # 10 poses measured twice
    parts = fold_indices(n, 5, 3, groups)
    assert sorted(np.concatenate(parts).tolist()) == list(range(n))
    for k in range(10):
        assert sum((k in p) and (30 + k in p) for p in parts) == 1  # the pair in one fold
    sizes = [len(p) for p in parts]
    assert max(sizes) - min(sizes) <= 2


def test_copies_do_not_flatter_the_std_and_holdout_keeps_them_in_one_fold():
    """End to end on the serial scene: all rows copied with 1e-6 jitter give the clean run's std (not x0.71)."""
    from vision_calib.experiment.steps import identify_measurements, rngs, scene_truth
    from vision_calib.rig import SCENES_DIR, load_scene, scene_poses

    scene = load_scene(SCENES_DIR / "rx90_eye_in_hand.yaml")
    setup = scene.setup
    rp, rn, _ = rngs(4)
    q = scene_poses(scene, rp, 30)
    d = np.concatenate([rn.normal(scale=ST, size=(30, 3)), rn.normal(scale=SR, size=(30, 3))], axis=1)
    T = F.perturb_pose(setup.T_cam_target(q, scene_truth(scene)), d)
    cov = np.tile(np.diag([ST**2] * 3 + [SR**2] * 3), (30, 1, 1))
    m = Measurements(q, q, T, cov, tuple(f"p{i:02d}" for i in range(30)))
    both = _stack(m, _jittered_copy(m, range(30), 1e-6))
    kept, copies = drop_copies(both)
    assert len(copies) == 30
    ref = identify_measurements(setup, m, "lse", None).result
    got = identify_measurements(setup, kept, "lse", None).result
    doubled = identify_measurements(setup, both, "lse", None).result
    free = ref.free
    np.testing.assert_allclose(got.std[free], ref.std[free], rtol=1e-9)
    assert np.median(doubled.std[free] / ref.std[free]) == pytest.approx(1 / np.sqrt(2), rel=0.05)  # what it was
