"""Per-view acceptance rule (measure/view_checks.py): too few corners, corners that do not span the board,
and corners inconsistent with one plane seen by a pinhole are rejected or dropped, with the reason."""

import numpy as np
import pytest

from vision_calib import frames
from vision_calib.measure import Detection, MeasureConfig, measure_pose
from vision_calib.targets.spec import TargetSpec

from measure_helpers import random_pose
from test_pnp import DIST_INTR


def _view(target, sel=None, sigma=0.05, seed=0, n=3, move=None):
    """n frames of the target's corners (subset ``sel`` of the corner indices) with Gaussian noise;
    ``move``: (index into the selection, 2-D offset px) added to one corner in every frame."""
    rng = np.random.default_rng(seed)
    T = random_pose(rng, target)
    ids, p = target.corner_points()
    sel = np.arange(len(ids)) if sel is None else np.asarray(sel)
    uv = DIST_INTR.project(frames.transform_points(T, p[sel]))
    if move is not None:
        uv[move[0]] += move[1]
    return T, [Detection(True, "", ids[sel], uv + rng.normal(0, sigma, uv.shape), DIST_INTR.size, f)
               for f in range(n)]


def _grid_index(target, cells):
    """Indices of the corners at (column, row) positions of the inner-corner grid."""
    ids, p = target.corner_points()
    xs, ys = np.unique(np.round(p[:, 0], 6)), np.unique(np.round(p[:, 1], 6))
    out = []
    for c, r in cells:
        out.append(int(np.flatnonzero((np.abs(p[:, 0] - xs[c]) < 1e-9) & (np.abs(p[:, 1] - ys[r]) < 1e-9))[0]))
    return out


def test_good_view_is_accepted_with_its_diagnostics(charuco):
    T, dets = _view(charuco)
    m = measure_pose(dets, charuco, DIST_INTR)
    assert m.valid, m.reason
    f = m.frames[0]
    assert f["area_fraction"] == pytest.approx(1.0) and f["homography_rms_px"] < 0.1 and "dropped_corners" not in f


def test_four_corner_view_is_rejected(charuco):
    _, dets = _view(charuco, _grid_index(charuco, [(3, 2), (4, 2), (3, 3), (4, 3)]))
    m = measure_pose(dets, charuco, DIST_INTR)
    assert not m.valid and "too few corners: 4 < 6" in m.reason
    assert measure_pose(dets, charuco, DIST_INTR, config=MeasureConfig(min_view_corners=4,
                                                                       min_area_fraction=0)).valid


def test_clustered_eight_corner_view_is_rejected(charuco):
    # 4 x 2 corners in one part of a 9 x 6 inner-corner board: 3 / 40 = 7.5 % of its corner area
    cells = [(c, r) for c in range(4) for r in range(2)]
    _, dets = _view(charuco, _grid_index(charuco, cells))
    m = measure_pose(dets, charuco, DIST_INTR)
    assert not m.valid and "corners span 7.5 % of the board < 10 %" in m.reason
    assert m.frames[0]["area_fraction"] == pytest.approx(3 / 40)
    # the same count spread over the board passes
    spread = [(0, 0), (8, 0), (0, 5), (8, 5), (4, 2), (4, 3), (2, 1), (6, 4)]
    assert measure_pose(_view(charuco, _grid_index(charuco, spread))[1], charuco, DIST_INTR).valid


def test_collinear_corners_are_rejected(charuco):
    _, dets = _view(charuco, _grid_index(charuco, [(c, 2) for c in range(9)]))
    m = measure_pose(dets, charuco, DIST_INTR)
    assert not m.valid and "corners span 0.0 %" in m.reason


def test_outlier_corner_is_dropped_and_named(charuco):
    T, dets = _view(charuco, move=(17, np.array([4.0, -3.0])))
    ids = dets[0].ids
    m = measure_pose(dets, charuco, DIST_INTR)
    assert m.valid, m.reason
    dropped = m.frames[0]["dropped_corners"]
    assert [d["id"] for d in dropped] == [int(ids[17])] and dropped[0]["residual_px"] == pytest.approx(5.0, abs=0.5)
    e = frames.pose_error(T, m.T_cam_target)
    assert np.all(np.abs(e) < 5 * m.std)  # the pose is not pulled by the moved corner


def test_view_inconsistent_with_one_plane_is_rejected(charuco):
    _, dets = _view(charuco, sigma=1.0)
    m = measure_pose(dets, charuco, DIST_INTR)
    assert not m.valid and "one plane" in m.reason


def test_single_tag_target_keeps_its_four_corners():
    tag = TargetSpec(kind="apriltag_grid", name="one_tag", rows=1, cols=1, dictionary="DICT_APRILTAG_36h11",
                     tag_m=0.048, spacing_m=0.01)
    _, dets = _view(tag, n=1)
    m = measure_pose(dets, tag, DIST_INTR)
    assert m.valid, m.reason


def test_dropped_corners_and_rejections_reach_the_report(charuco):
    from vision_calib.report.build import measurements_block

    _, dets = _view(charuco, move=(17, np.array([4.0, -3.0])))
    good = measure_pose(dets, charuco, DIST_INTR, pose_id="a")
    few = measure_pose(_view(charuco, _grid_index(charuco, [(3, 2), (4, 2), (3, 3), (4, 3)]))[1], charuco,
                       DIST_INTR, pose_id="b")
    mb = measurements_block([good, few])
    assert mb["rejected"] == [{"pose_id": "b", "reason": few.reason}] and "4 < 6" in few.reason
    assert [(d["pose_id"], len(d["corners"])) for d in mb["dropped_corners"]] == [("a", 1)] * 3  # 3 frames


def test_remeasure_with_a_selection_keeps_the_corners_and_frames_of_the_first_measurement(charuco):
    """measure_pose(selection=): a re-measurement of the same detections (other intrinsics, e.g. the intrinsics'
    derivative) keeps the first measurement's frames and corners, without running the view rule again: the same
    intrinsics give the same pose to rounding; a corner the rule dropped stays dropped, a frame it rejected stays
    out, even when the rule would now decide otherwise."""
    from dataclasses import replace

    T, dets = _view(charuco, move=(17, np.array([4.0, -3.0])))
    dets = [*dets, replace(dets[0], frame_index=3, uv_px=dets[0].uv_px + np.random.default_rng(1).normal(0, 2.0,
                                                                                                     dets[0].uv_px.shape))]
    m = measure_pose(dets, charuco, DIST_INTR)
    assert m.valid and m.n_frames_used == 3 and not m.frames[3]["valid"]  # the noisy frame is rejected
    again = measure_pose(dets, charuco, DIST_INTR, selection=m.frames, covariance=False)
    np.testing.assert_allclose(again.T_cam_target, m.T_cam_target, atol=1e-12)
    assert again.n_frames_used == 3 and again.frames[3]["reason"] == m.frames[3]["reason"]
    assert again.frames[0]["dropped_corners"] == m.frames[0]["dropped_corners"]
    # a tighter corner noise: the rule itself would now reject every frame; the selection does not run it
    strict = MeasureConfig(corner_noise_px=0.005)
    assert not measure_pose(dets, charuco, DIST_INTR, config=strict).valid
    kept = measure_pose(dets, charuco, DIST_INTR, config=strict, selection=m.frames, covariance=False)
    np.testing.assert_allclose(kept.T_cam_target, m.T_cam_target, atol=1e-12)
    # without the moved corner's selection the pose moves: the selection is what kept it out
    free = measure_pose(dets, charuco, DIST_INTR, config=MeasureConfig(corner_noise_px=50.0), covariance=False)
    assert np.abs(frames.pose_error(free.T_cam_target, m.T_cam_target)).max() > 1e-6


@pytest.mark.parametrize("mode", ["corners", "poses"])
def test_light_remeasure_equals_measure_pose_with_the_selection(charuco, mode):
    """measure.remeasure.remeasure_pose (corners gathered once, undistorted with each camera, PnP refined from the
    measured pose) equals measure_pose(selection=) under cameras a few px away, in both modes (the same minimum:
    1e-10 in the pose, 1e-8 rad for the mean of per-frame poses, whose refinements stop at OpenCV's tolerance; the
    pose's std here is ~1e-4 rad); with a dropped corner and a rejected frame kept out; None where measure_pose would reject
    the pose (reprojection RMS over the limit), so that the caller's full measurement names why."""
    from dataclasses import replace

    from vision_calib.measure.remeasure import remeasurable, remeasure_pose

    T, dets = _view(charuco, move=(17, np.array([4.0, -3.0])))
    dets = [*dets, replace(dets[0], frame_index=3, uv_px=dets[0].uv_px + np.random.default_rng(1).normal(0, 2.0,
                                                                                                     dets[0].uv_px.shape))]
    cfg = MeasureConfig(mode=mode)
    m = measure_pose(dets, charuco, DIST_INTR, config=cfg)
    assert m.valid and not m.frames[3]["valid"] and m.frames[0]["dropped_corners"]
    rm = remeasurable(dets, charuco, m, cfg)
    assert rm is not None and rm.frame.max() == 2  # the 3 accepted frames
    for change in ({"fx": DIST_INTR.fx + 3.0}, {"cx": DIST_INTR.cx - 2.0, "cy": DIST_INTR.cy + 1.5},
                   {"dist": tuple(np.asarray(DIST_INTR.dist) * 1.02)}):
        cam = replace(DIST_INTR, **change)
        ref = measure_pose(dets, charuco, cam, config=cfg, selection=m.frames, covariance=False)
        light = remeasure_pose(rm, cam)
        assert np.abs(frames.pose_error(light, m.T_cam_target)).max() > 1e-6  # the camera moved the pose
        assert np.abs(frames.pose_error(light, ref.T_cam_target)).max() < (1e-10 if mode == "corners" else 1e-8)
    strict = replace(cfg, max_rms_px=1e-3)
    assert remeasure_pose(remeasurable(dets, charuco, m, strict), DIST_INTR) is None
    assert not measure_pose(dets, charuco, DIST_INTR, config=strict, selection=m.frames, covariance=False).valid


def test_poses_remeasured_together_equal_each_alone(charuco):
    """measure.remeasure.remeasure_many (the poses' pixels undistorted in one call, one batched Gauss-Newton PnP,
    pnp.refine_pnp_many) gives each pose's remeasure_pose (OpenCV's refinement) to 1e-8 (both at the minimum to
    their tolerances: the costs agree to 1e-12 relative; the poses' std here are ~1e-4), with poses of different
    corner counts (padding), and None where a pose's RMS is over its limit."""
    from dataclasses import replace

    from vision_calib.measure.remeasure import remeasurable, remeasure_many, remeasure_pose

    rms, ms = [], []
    for seed, sel in ((0, None), (1, np.arange(20)), (2, None)):
        _, dets = _view(charuco, sel=sel, seed=seed)
        m = measure_pose(dets, charuco, DIST_INTR)
        assert m.valid
        rms.append(remeasurable(dets, charuco, m))
        ms.append(m)
    assert len({rm.p_target.shape[0] for rm in rms}) == 2
    cam = replace(DIST_INTR, fx=DIST_INTR.fx + 3.0, cy=DIST_INTR.cy - 2.0)
    together = remeasure_many(rms, cam)
    for rm, m, T in zip(rms, ms, together):
        alone = remeasure_pose(rm, cam)
        assert np.abs(frames.pose_error(T, m.T_cam_target)).max() > 1e-6
        assert np.abs(frames.pose_error(T, alone)).max() < 1e-8
    strict = [rms[0], replace(rms[1], max_rms_px=1e-3), rms[2]]
    out = remeasure_many(strict, cam)
    assert out[1] is None and out[0] is not None and out[2] is not None
