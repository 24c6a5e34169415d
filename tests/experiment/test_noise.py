"""`vision-calib noise`: folders of repeated frames written by the project's own renderer with known sensor settings
-> the measured corner noise, pixel noise, blur and levels recover them within their reported uncertainty, the
simulator with the fitted settings gives the measured corner and pose scatter; the error cases; the real photo."""

import json
import re
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from scipy import stats

from vision_calib.camera import CameraIntrinsics
from vision_calib.cli import main
from vision_calib.errors import ConfigError, DataError
from vision_calib.experiment.noise import measure_noise
from vision_calib.experiment.noise_sim import simulate_scatter, simulate_frames
from vision_calib.measure.detect import DetectConfig
from vision_calib.render import look_at_target
from vision_calib.rig.scene import EFFECT_ALIASES
from vision_calib.sensor import SensorEffects
from vision_calib.targets import load_target

REAL = Path(os.environ["VISION_CALIB_SHARED_DATA"]) / "real" / "rosi_noise_qualification"  # tests/conftest.py
CAM = CameraIntrinsics(640, 480, 600, 600, 319.5, 239.5, (-0.1, 0.05, 0.0, 0.0, 0.0))
TRUTH = SensorEffects(blur_sigma_px=1.3, read_noise_grey=3.0, full_well_e=5000.0, exposure=0.6, black_level_grey=30.0)
CHARUCO = "targets/charuco_a5.yaml"
DOTS = "targets/modified_circle_grid_a4.yaml"


def _write_frames(folder: Path, imgs) -> list:
    (folder / "images").mkdir(parents=True, exist_ok=True)
    paths = []
    for i, im in enumerate(imgs):
        paths.append(folder / "images" / f"{i}.png")
        cv2.imwrite(str(paths[-1]), im)
    return paths


def _camera_yaml(path: Path) -> Path:
    path.write_text(yaml.safe_dump({"format": "vision_calib.camera/1", **CAM.to_dict()}))
    return path


def _rosi(folder: Path, names, finder: dict) -> Path:
    doc = {"data": [{"image": n} for n in names], "intrinsics": {k: getattr(CAM, k) for k in ("fx", "fy", "cx", "cy")},
           "distortion": list(CAM.dist), "target_finder": finder}
    (folder / "cal_data.yaml").write_text(yaml.safe_dump(doc))
    return folder


def _sim(target_file, seed, n=10, distance=0.35, effects=TRUTH):
    t = load_target(target_file)
    T = look_at_target(t, distance, (0.3, -0.2, 0.1))
    return t, T, simulate_frames(t, CAM, T, effects, n, seed)


def _z(value, truth, se):
    return (value - truth) / se


@pytest.mark.parametrize("seed", [11, 12])
def test_charuco_folder_recovers_the_settings_and_the_scatter(tmp_path, seed):
    t, T, imgs = _sim(CHARUCO, seed)
    _write_frames(tmp_path / "set", imgs)
    res = measure_noise(tmp_path / "set" / "images", tmp_path / "out", target=CHARUCO,
                        camera=_camera_yaml(tmp_path / "camera.yaml"), seed=seed)
    pn, fb, sim = res["pixel_noise"], res["image_fit"], res["simulator"]
    assert abs(_z(pn["read_noise_grey"], 3.0, pn["read_noise_se"])) < 3
    assert abs(_z(pn["full_well_e"], 5000.0, pn["full_well_se"])) < 3
    assert abs(_z(fb["blur_sigma_px"], 1.3, fb["blur_se_px"])) < 3
    assert abs(_z(fb["black_level_grey"], 30.0, fb["black_se"])) < 3
    assert abs(_z(fb["exposure"], 0.6, fb["exposure_se"])) < 3
    v = sim["settings"]["value_and_se"]  # the noise that reproduces the corner scatter
    assert abs(_z(v["read_noise_grey"][0], 3.0, v["read_noise_grey"][1])) < 3
    assert abs(_z(v["full_well_e"][0], 5000.0, v["full_well_e"][1])) < 3
    # the measured corner noise against the true settings' (a fresh 40-frame simulation)
    true = simulate_scatter(t, CAM, T, TRUTH, 40, 999, DetectConfig())
    c = res["corner_noise"]["xy"]
    t_xy = true["corners"]["xy"]
    z = np.log(c["std_px"] / t_xy.std) / np.hypot(t_xy.rel_se, 1 / np.sqrt(2 * c["dof"]))
    assert abs(z) < 3
    assert c["ci95_px"][0] < c["std_px"] < c["ci95_px"][1]
    # the pose scatter of the simulator with the fitted settings: per axis, an F test of the two variances
    rep = sim["reproduced"]["pose_scatter"]
    for name, a in res["pose_scatter"]["axes"].items():
        unit = "mm" if name.startswith("t") else "mrad"
        f = (a[f"std_{unit}"] / rep[name][f"std_{unit}"]) ** 2
        d1, d2 = a["dof"], rep[name]["dof"]
        assert stats.f.ppf(0.0005, d1, d2) < f < stats.f.ppf(0.9995, d1, d2), name
    # outputs: noise.json, summary, a scene snippet whose blocks load as a scene's
    doc = json.loads((tmp_path / "out" / "noise.json").read_text())
    assert doc["format"] == "vision_calib.noise/1" and doc["n_frames"] == 10
    snip = yaml.safe_load((tmp_path / "out" / "sensor.yaml").read_text())
    eff = SensorEffects.from_dict({EFFECT_ALIASES.get(k, k): w for k, w in snip["effects"].items()})
    assert eff.blur_sigma_px == pytest.approx(fb["blur_sigma_px"], rel=1e-4)
    assert CameraIntrinsics.from_dict(snip["camera"]) == CAM
    assert snip["measurement"]["sigma_mm"] > 0 and snip["measurement"]["sigma_deg"] > 0
    assert "corner noise" in (tmp_path / "out" / "summary.txt").read_text()


def test_rosi_circle_grid_without_dot_diameter_fits_it(tmp_path):
    t, _, imgs = _sim(DOTS, 21, distance=0.4)
    paths = _write_frames(tmp_path, imgs)
    finder = {"type": "ModifiedCircleGridTargetFinder", "rows": t.rows, "cols": t.cols, "spacing": t.spacing_m}
    res = measure_noise(_rosi(tmp_path, [p.relative_to(tmp_path).as_posix() for p in paths], finder), tmp_path / "out")
    d = res["image_fit"]["dot_diameter"]
    assert abs(_z(d["diameter_m"], t.diameter_m, d["diameter_se_m"])) < 3
    fb = res["image_fit"]
    assert abs(_z(fb["blur_sigma_px"], 1.3, fb["blur_se_px"])) < 3
    assert res["simulator"]["target"]["diameter_m"] == pytest.approx(d["diameter_m"])
    r = res["simulator"]["reproduced"]["measured_over_simulated"]
    assert r["ci95"][0] < 1 < r["ci95"][1]


def test_moved_frames_are_named(tmp_path):
    t, T, imgs = _sim(CHARUCO, 31, n=8)
    T2 = T.copy()
    T2[0, 3] += 0.3e-3  # 0.3 mm: about 0.5 px
    moved = simulate_frames(t, CAM, T2, TRUTH, 2, 32)
    _write_frames(tmp_path, list(imgs) + list(moved))
    with pytest.raises(DataError, match=r"moved between frames: frame 8 \(8.png\).*frame 9 \(9.png\)"):
        measure_noise(tmp_path / "images", tmp_path / "out", target=CHARUCO, camera=_camera_yaml(tmp_path / "c.yaml"))
    doc = json.loads((tmp_path / "out" / "noise.json").read_text())
    assert [m["frame"] for m in doc["moved"]["frames"]] == [8, 9]


def test_input_errors_name_the_image(tmp_path):
    _, _, imgs = _sim(CHARUCO, 41, n=3)
    cam = _camera_yaml(tmp_path / "c.yaml")

    def run(folder):
        return measure_noise(folder, tmp_path / "out", target=CHARUCO, camera=cam)

    a = tmp_path / "unreadable"
    _write_frames(a, imgs)
    (a / "images" / "1.png").write_bytes(b"not an image")
    with pytest.raises(DataError, match=r"frame 1: unreadable or corrupt image file: .*1\.png"):
        run(a / "images")
    b = tmp_path / "sizes"
    _write_frames(b, [imgs[0], imgs[1], cv2.resize(imgs[2], (320, 240))])
    res = measure_noise(b / "images", tmp_path / "out_b", target=CHARUCO, camera=cam, sim_frames=2)
    assert res["n_frames"] == 2 and len(res["skipped_frames"]) == 1  # the odd one skipped, named (issue 28)
    assert re.search(r"2\.png: image size 320x240 differs from the majority 640x480 \(2 of 3 frames\)",
                     res["skipped_frames"][0])
    assert "warning: frame skipped: " in res["summary_text"]
    c = tmp_path / "blank"
    _write_frames(c, [imgs[0], np.full_like(imgs[1], 128), imgs[2]])
    with pytest.raises(DataError, match=r"frame 1: .*1\.png: target not detected"):
        run(c / "images")
    d = tmp_path / "copies"
    _write_frames(d, [imgs[0], imgs[0]])
    with pytest.raises(DataError, match=r"needs >= 2 repeated frames .*pixel-identical copies"):
        run(d / "images")
    e = tmp_path / "one"
    _write_frames(e, imgs[:1])
    with pytest.raises(DataError, match=r"needs >= 2 repeated frames of the static target \(1 frame\)"):
        run(e / "images")
    with pytest.raises(ConfigError, match="--target TARGET.yaml --camera CAMERA.yaml"):
        measure_noise(e / "images", tmp_path / "out")


@pytest.mark.skipif(not REAL.is_dir(), reason="real ROS-I photo not available (../shared/data)")
def test_real_single_photo_says_two_frames_are_needed_and_reports_its_detection(tmp_path, capsys):
    rc = main(["noise", str(REAL), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2
    assert "the scatter needs >= 2 repeated frames" in err and "14 entries name 1 image file" in err
    assert "100 of 100 target points detected" in err
    det = json.loads((tmp_path / "out" / "noise.json").read_text())["detection"]
    assert det["valid"] and det["n_corners"] == 100 and det["pnp_rms_px"] < 1.0
    one = json.loads((tmp_path / "out" / "noise.json").read_text())["image_fit_one_frame"]  # blur etc. of this frame
    assert not one["at_grid_edge"] and not one["dot_diameter"]["at_grid_edge"] and one["patches"] == 100
    assert "image fit of this frame: blur" in err


def test_cli_noise_json(tmp_path, capsys):
    _, _, imgs = _sim(CHARUCO, 51, n=4)
    _write_frames(tmp_path / "set", imgs)
    rc = main(["noise", str(tmp_path / "set" / "images"), "--target", CHARUCO, "--camera",
               str(_camera_yaml(tmp_path / "c.yaml")), "--out", str(tmp_path / "out"), "--sim-frames", "10", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n_frames"] == 4 and out["simulator"]["frames"] == 10
    assert (tmp_path / "out" / "sensor.yaml").is_file()
