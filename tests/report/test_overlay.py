"""Overlay images of report.html (report/overlay.py): which poses, what is drawn where (against OpenCV's own
projection), the frame shown of a recording, and the simulated frame rendered again = the frame the run measured."""

import cv2
import numpy as np
import pytest

from vision_calib.camera import CameraIntrinsics
from vision_calib.report.overlay import FULL_MAX_ENLARGE, FULL_MAX_WIDTH_PX, FULL_MIN_WIDTH_PX, MAX_WIDTH_PX, \
    build_overlays, draw_overlay, overlay_selection, recording_frames, OverlaySource
from vision_calib.measure import Detection
from vision_calib.rig import SCENES_DIR
from vision_calib.targets import load_target

ROOT = SCENES_DIR.parent
CAM = CameraIntrinsics(1280, 960, 1000.0, 1010.0, 650.0, 470.0, (-0.1, 0.05, 0.001, -0.0005, 0.0))


def _target_pose(target, z=0.5, tilt_deg=10.0):
    """T_cam_target (4, 4): the target's corner centroid on the optical axis at z m, tilted about x."""
    _, p = target.corner_points()
    T = np.eye(4)
    a = np.radians(tilt_deg)
    T[:3, :3] = [[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]
    T[:3, 3] = np.array([0.0, 0.0, z]) - T[:3, :3] @ np.mean(p, axis=0)
    return T


def _cv_project(T, p):
    uv, _ = cv2.projectPoints(np.asarray(p, float), cv2.Rodrigues(T[:3, :3])[0], T[:3, 3],
                              np.array([[CAM.fx, 0, CAM.cx], [0, CAM.fy, CAM.cy], [0, 0, 1]]), np.array(CAM.dist))
    return uv.reshape(-1, 2)


def test_draw_overlay_measures_the_model_offset_and_stays_small():
    target = load_target(ROOT / "targets" / "charuco_a5.yaml")
    ids, p = target.corner_points()
    T = _target_pose(target)
    det_uv = _cv_project(T, p)
    keep = np.arange(len(ids)) % 3 != 0  # the detector found two thirds of the corners
    det = Detection(True, "", np.asarray(ids)[keep], det_uv[keep], (CAM.width, CAM.height), 1)
    img = np.full((CAM.height, CAM.width), 90, np.uint8)
    T_model = T.copy()
    T_model[:3, 3] += [0.001, -0.0005, 0.002]  # the model's pose 1 mm / 0.5 mm / 2 mm off
    jpeg, info = draw_overlay(img, det, T, T_model, target, CAM, label="pose x")
    want = np.linalg.norm(_cv_project(T_model, p)[keep] - det_uv[keep], axis=1)
    assert info["model_rms_px"] == pytest.approx(np.sqrt(np.mean(want ** 2)), rel=1e-6)
    assert info["model_max_px"] == pytest.approx(want.max(), rel=1e-6)
    assert info["vector_gain"] == pytest.approx(25.0 / (want.max() * info["scale"]), rel=1e-9)
    assert (info["n_detected"], info["n_measured"], info["n_model"]) == (keep.sum(), len(ids), len(ids))
    x0, y0, x1, y1 = info["crop"]  # cropped around the target, every drawn corner inside
    both = np.concatenate([det_uv, _cv_project(T_model, p)])
    assert x0 <= both[:, 0].min() and both[:, 0].max() <= x1 and y0 <= both[:, 1].min() and both[:, 1].max() <= y1
    assert (x1 - x0) < CAM.width
    im = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert im.shape[:2] == (info["height"], info["width"]) and im.shape[1] <= MAX_WIDTH_PX
    # a detected corner is drawn where it is: green at its display position, grey background far from any corner
    u, v = (det_uv[keep][0] - [x0, y0]) * info["scale"]
    b, g, r = im[int(round(v)), int(round(u))].astype(int)
    assert g > 150 and g > r + 60 and g > b + 60
    # with the model at the measured pose there is nothing to see: no offset
    _, same = draw_overlay(img, det, T, T, target, CAM)
    assert same["model_rms_px"] < 1e-9


def test_draw_overlay_without_detection_or_model_shows_the_whole_image():
    img = np.zeros((300, 2000), np.uint8)
    jpeg, info = draw_overlay(img, None, None, None, None, None)
    assert info["crop"] == [0, 0, 2000, 300] and info["width"] == MAX_WIDTH_PX
    assert info["model_rms_px"] is None and info["n_detected"] == 0
    assert cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_GRAYSCALE).shape == (96, 640)


def test_full_size_overlay_enlarges_small_crops_with_square_pixels():
    """The full-size overlay (max_width FULL_MAX_WIDTH_PX, min_width FULL_MIN_WIDTH_PX): a 230 px crop is enlarged by
    the whole factor 4 (FULL_MAX_ENLARGE), each camera pixel a 4 x 4 block, and a detected corner drawn where its
    pixel (integer coordinates = pixel centres) lies in the enlarged image; a wide crop keeps its camera pixels."""
    img = np.zeros((480, 640), np.uint8)
    img[200:280, 300:420:2] = 255  # one-pixel stripes: their edges survive only a whole-factor nearest enlargement
    uv = np.array([[330.0, 240.0], [400.0, 300.0]])
    det = Detection(True, "", np.array([1, 2]), uv, (640, 480), 0)
    jpeg, info = draw_overlay(img, det, max_width=FULL_MAX_WIDTH_PX, min_width=FULL_MIN_WIDTH_PX)
    x0, y0, x1, y1 = info["crop"]
    k = min(FULL_MAX_ENLARGE, FULL_MIN_WIDTH_PX // (x1 - x0))
    assert x1 - x0 < FULL_MIN_WIDTH_PX // 2 and k >= 2
    assert info["scale"] == k and (info["width"], info["height"]) == ((x1 - x0) * k, (y1 - y0) * k)
    im = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert im.shape[:2] == (info["height"], info["width"])
    # a stripe column (camera x = 302) is white over its k display columns, its dark neighbour (303) dark
    row = int((250 - y0 + 0.5) * k)
    col = [int(im[row, (302 - x0) * k + j, 1]) for j in range(k)] + [int(im[row, (303 - x0) * k + j, 1])
                                                                      for j in range(k)]
    assert min(col[:k]) > 150 and max(col[k:]) < 100, col
    # the green cross of the detected corner at (400, 300) is centred on ((u - x0 + 0.5) k - 0.5, ...) (to the
    # display pixel: the cross is 1 px thick, its arms 4 px); 2 px away on its arms still green, off them dark
    u, v = np.floor((uv[1] - [x0, y0] + 0.5) * k - 0.5).astype(int)
    for du, dv in ((0, 0), (2, 0), (-2, 0), (0, 2), (0, -2)):  # (JPEG chroma blurs a 1 px line: looser bounds)
        b, g, r = im[v + dv, u + du].astype(int)
        assert g > 120 and g > r + 30 and g > b + 30, (du, dv)
    assert im[v + 2, u + 2, 1] < 80 and im[v - 2, u - 2, 1] < 80
    # a crop wider than FULL_MIN_WIDTH_PX / 2: at its own pixels (factor 1), never downscaled below them
    _, wide = draw_overlay(np.zeros((960, 1280), np.uint8), None, max_width=FULL_MAX_WIDTH_PX,
                           min_width=FULL_MIN_WIDTH_PX)
    assert wide["scale"] == 1 and wide["width"] == 1280


def test_selection_rejected_first_then_worst_without_duplicates():
    rep = {"measurements": {"rejected": [{"pose_id": "a", "reason": "no target"}, {"pose_id": "b", "reason": "blur"}]},
           "outliers": [{"pose_id": "c", "reason": "motion"}, {"pose_id": "a", "reason": "again"}],
           "pose_residuals": {"poses": [{"pose_id": "d", "chi2": 30.0, "translation_mm": 0.5, "rotation_deg": 0.1},
                                        {"pose_id": "c", "chi2": 20.0}, {"pose_id": "e", "chi2": 9.0},
                                        {"pose_id": "f", "chi2": 3.0}]}}
    sel = overlay_selection(rep, n_worst=2)
    assert [(p, r) for p, r, _ in sel] == [("a", "rejected"), ("b", "rejected"), ("c", "outlier"), ("d", "worst"),
                                           ("e", "worst")]
    assert sel[0][2] == "no target" and sel[3][2] == "final residual: chi2 30, translation 0.5 mm, rotation 0.1 deg"
    assert [p for p, _, _ in overlay_selection(rep, n_worst=0, max_rejected=2)] == ["a", "b"]


def test_recording_frames_show_the_first_detected_frame(tmp_path):
    d = tmp_path / "images" / "p1"
    d.mkdir(parents=True)
    for k, val in enumerate((10, 200)):
        cv2.imwrite(str(d / f"{k:02d}.png"), np.full((40, 60), val, np.uint8))
    dets = {"p1": [Detection(False, "no target", np.zeros(0, int), np.zeros((0, 2)), (60, 40), 0),
                   Detection(True, "", np.array([3]), np.array([[5.0, 6.0]]), (60, 40), 1)]}
    frames = recording_frames({"p1": sorted(d.iterdir()), "p2": []}, dets)(["p1", "p2"])
    img, det, note = frames["p1"]
    assert int(img[0, 0]) == 200 and det.frame_index == 1 and note == ""
    assert frames["p2"][:2] == (None, None) and "images/p2" in frames["p2"][2]
    # a pose without an image keeps its reason in the overlay list, no picture
    rep = {"measurements": {"rejected": [{"pose_id": "p2", "reason": "no images"}], "poses": []}}
    ov = build_overlays(rep, OverlaySource(recording_frames({"p2": []}, {}), None, None))
    assert ov[0]["jpeg"] is None and ov[0]["role"] == "rejected" and "images/p2" in ov[0]["note"]


@pytest.mark.slow
def test_simulated_overlay_frame_is_the_frame_the_run_measured(tmp_path):
    """The simulation keeps no frames: the overlay renders its few poses again with the same per-pose seed. That
    frame is the one the worker wrote (and measured) byte for byte, and its detection has the corners the worker's
    first frame had."""
    from vision_calib.experiment.image_chain import measure_poses, overlay_frames
    from vision_calib.experiment.simulate import image_chain_of
    from vision_calib.experiment.steps import rngs, scene_truth
    from vision_calib.rig import load_scene, scene_poses

    scene = load_scene(SCENES_DIR / "rx90_eye_in_hand.yaml")
    chain = image_chain_of(scene)
    rp, _, _ = rngs(4)
    T = scene.setup.T_cam_target(scene_poses(scene, rp, 3), scene_truth(scene))
    labels = ["000", "001", "002"]
    pms, _ = measure_poses(chain, T, labels, seed=11, frames=2, workers=1, image_dir=tmp_path)
    got = overlay_frames(chain, T, labels, 11, 2, ["002", "000", "zzz"])
    assert set(got) == {"000", "002"}
    for lab in ("000", "002"):
        img, det, _ = got[lab]
        written = cv2.imread(str(tmp_path / lab / "00.png"), cv2.IMREAD_GRAYSCALE)
        np.testing.assert_array_equal(img, written)
        pm = pms[labels.index(lab)]
        assert det.valid and det.n_corners == pm.frames[0]["n_corners"]
