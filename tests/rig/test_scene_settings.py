"""Scenes load once into typed SI settings; a key that does not apply is an error naming it."""

import numpy as np
import pytest

from vision_calib.errors import ConfigError
from vision_calib.rig import SCENES_DIR, load_scene
from vision_calib.study import load_study

ROOT = SCENES_DIR.parent


def _scene(tmp_path, base: str, extra: str, replace: tuple = ()) -> str:
    text = (SCENES_DIR / base).read_text()
    text = text.replace("robot: robots/", f"robot: {SCENES_DIR}/robots/").replace("target: ../targets/",
                                                                                    f"target: {ROOT}/targets/")
    for a, b in replace:
        assert a in text
        text = text.replace(a, b)
    p = tmp_path / "s.yaml"
    p.write_text(text + "\n" + extra)
    return str(p)


def test_settings_are_typed_and_in_si():
    sc = load_scene(SCENES_DIR / "rx90_eye_in_hand.yaml")
    assert sc.measurement.sigma_t_m == pytest.approx(0.1e-3) and sc.measurement.sigma_r_rad == pytest.approx(
        np.radians(0.02))
    assert sc.truth.sigma_length_m == pytest.approx(0.5e-3) and sc.truth.seed == 11
    assert sc.poses.kind == "random" and sc.poses.count == 50 and sc.validation.count == 50
    assert sc.effects.read_noise_grey == 2.0 and sc.effects.blur_sigma_px == 0.6  # scene aliases resolved
    np.testing.assert_allclose(sc.setup.q_center, np.radians([0.0, 35.0, 95.0, 0.0, 50.0, 0.0]))


@pytest.mark.parametrize("base,extra,replace,needle", [
    ("h4_vision.yaml", "measurment: {frames: 2}\n", (), "did you mean 'measurement'"),
    ("h4_vision.yaml", "", (("  frames: 10\n", "  frames_per_poses: 2\n"),), "measurement.frames_per_poses"),
    ("rx90_eye_in_hand.yaml", "", (("dist: [-0.05", "k9: 1, dist: [-0.05"),), "camera.k9"),
    ("h4_vision.yaml", "mounts: {camera_in_base: {xyz: [0, 0, 1]}}\n", (), "mounts"),  # a serial key in an H4 scene
    ("rx90_eye_in_hand.yaml", "variant: D\n", (), "variant"),  # an H4 key in a serial scene
    ("rx90_eye_in_hand.yaml", "truth: {sigma_length_mm: -1}\n", (), "truth.sigma_length_mm"),
    ("rx90_eye_in_hand.yaml", "truth: {perturb: free}\n", (), "truth.perturb"),  # a setting nothing reads
    ("h4_vision.yaml", "identification: {method: igm, residual: pose}\n", (), "identification.residual"),
    ("rx90_eye_in_hand.yaml", "identification: {method: igm}\n", (), "identification.method"),
    ("rx90_eye_in_hand.yaml", "poses: {kind: grid81}\n", (), "poses.kind"),
    ("thesis_arm_ch3.yaml", "truth: {trial: no_such_trial}\n", (), "truth.trial"),
])
def test_keys_that_do_not_apply_are_named(tmp_path, base, extra, replace, needle):
    with pytest.raises(ConfigError, match=needle.replace(".", r"\.").replace("'", "'")):
        load_scene(_scene(tmp_path, base, extra, replace))


def test_scene_without_camera_for_measured_poses(tmp_path):
    """A synthetic-only scene (no images) needs no camera section."""
    p = _scene(tmp_path, "thesis_arm_ch3.yaml", "", (("camera: {width: 1280, height: 960, fx: 1000.0, fy: 1000.0, "
                                                     "cx: 639.5, cy: 479.5}\n", ""),))
    assert load_scene(p).setup.camera is None


@pytest.mark.parametrize("line,needle", [
    ("settings: {sigma_mm: 0.01}\n", "sigma_mm"),
    ("sweep: {sigma_deg: [0.01, 0.1]}\n", "sigma_deg"),
    ("settings: {pose_selection: D}\n", "pose_selection"),
    ("truth: per_run\n", "truth"),
])
def test_images_study_refuses_synthetic_only_settings(tmp_path, line, needle):
    """sigma_mm in an images-mode study used to be silently ignored (0.01 and 5.0 gave the same results)."""
    p = tmp_path / "st.yaml"
    p.write_text(f"scene: {SCENES_DIR / 'h4_vision.yaml'}\nmode: images\nrepetitions: 1\n{line}")
    with pytest.raises(ConfigError, match=needle):
        load_study(p)
