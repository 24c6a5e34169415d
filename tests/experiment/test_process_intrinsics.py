"""process on a recording without intrinsics: calibrated from its own images, parameters close to the
run with the true intrinsics; a camera size that disagrees with the images is refused."""

import json
import shutil

import numpy as np
import pytest
import yaml

from vision_calib.cli import main
from vision_calib.errors import ConfigError
from vision_calib.experiment.process import process_folder

pytestmark = pytest.mark.slow
RX90 = "scenes/rx90_eye_in_hand.yaml"


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from vision_calib.experiment.simulate import run_simulation

    d = tmp_path_factory.mktemp("intr")
    run_simulation(RX90, out_dir=d / "sim", seed=3, n_poses=24, frames=1, export_recording=d / "rec", workers=2,
                   plots=False)
    return d


def _edit_camera(src, dst, **camera):
    shutil.copytree(src, dst)
    doc = yaml.safe_load((dst / "recording.yaml").read_text())
    doc["camera"] = camera
    (dst / "recording.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return doc


def test_process_calibrates_missing_intrinsics_and_agrees_with_the_true_ones(recording, tmp_path):
    ref = process_folder(recording / "rec", tmp_path / "ref", plots=False)
    assert ref["intrinsics"]["source"] == "recording.yaml" and ref["intrinsics"]["std"] is None
    _edit_camera(recording / "rec", tmp_path / "rec", width=1024)  # no fx/fy/cx/cy/dist; height from the images
    out = process_folder(tmp_path / "rec", tmp_path / "out", plots=False)
    intr = out["intrinsics"]
    assert intr["source"] == "calibrated from the recording" and intr["n_views_used"] >= 20
    truth = yaml.safe_load((recording / "rec" / "recording.yaml").read_text())["camera"]
    for k in ("fx", "fy", "cx", "cy"):
        assert abs(intr["values"][k] - truth[k]) < 3 * intr["std"][k], (k, intr["values"][k], truth[k])
    # k1, k2, k3 are strongly correlated when the corners reach only part of the image (warned): compare the
    # radial distortion they give at the largest radius the corners reached instead (px)
    assert any("extrapolated" in w for w in intr["warnings"])
    r_px = intr["coverage"]["radius_frac"] * np.hypot(truth["cx"] + 0.5, truth["cy"] + 0.5)

    def radial_px(f, k1, k2, k3):
        r2 = (r_px / f) ** 2
        return r_px * (k1 * r2 + k2 * r2**2 + k3 * r2**3)

    v = intr["values"]
    t = truth["dist"]
    assert abs(radial_px(v["fx"], v["k1"], v["k2"], v["k3"]) - radial_px(truth["fx"], t[0], t[1], t[4])) < 0.5
    assert out["settings"]["camera"]["fx"] == intr["values"]["fx"]
    assert "intrinsics (calibrated from the recording" in out["summary_text"]
    # robot parameters: the run with calibrated intrinsics agrees with the reference run within their std,
    # which carry the intrinsics' own uncertainty (a 0.15 % focal error alone moves the camera distance, d6
    # here, by ~0.8 mm = 60 x its std): process fits it as one nuisance coefficient per eigen-direction of the
    # intrinsics covariance (GLS with the poses' plus the intrinsics' covariance)
    r = {p["name"]: p for p in ref["parameters"]}
    prop = out["intrinsics"]["propagated"]
    assert prop["n_directions"] >= 4 and prop["in_fit"] and "included in the fit" in out["summary_text"]
    assert max(prop["std_inflation"].values()) > 3, prop["std_inflation"]
    true = {p["name"]: p["true"] for p in json.loads((recording / "sim" / "report.json").read_text())["parameters"]}
    z = []
    for p in out["parameters"]:
        if p["free"]:
            q = r[p["name"]]
            tol = 3 * np.sqrt(p["std"] ** 2 + q["std"] ** 2)
            assert abs(p["identified"] - q["identified"]) < tol, (p["name"], p["identified"], q["identified"], tol)
            z.append((p["identified"] - true[p["name"]]) / p["std"])
    # ... and with the simulation truth within their std: z-scores of the ~30 parameters (RMS over seeds 3-8:
    # 1.03, largest |z| 2.6; without the intrinsics' uncertainty in the std, d6 alone is tens of std off).
    # 4.5: a 30-parameter family-wise bound at ~2e-4; RMS of 30 N(0, 1): 1 +- 0.13 (correlated: wider)
    z = np.array(z)
    assert z.size >= 20 and np.max(np.abs(z)) < 4.5 and np.sqrt(np.mean(z**2)) < 1.8, np.round(z, 2)
    # the intrinsics' error moves every pose in a correlated way the per-pose covariances miss: it is a term
    # of the fit, so the chi-square adequacy is that of the poses' plus the intrinsics' covariance and stays
    # in its band (without it chi2/dof was 2-11 on seeds 3-8: a false "model does not explain the data"),
    # no good pose is taken for an outlier, and the std are not scaled by a variance factor on top
    for rep in (ref, out):
        a = rep["adequacy"]
        assert a["verdict"] == "consistent", a
        assert a["dof"] == ref["adequacy"]["dof"]  # the nuisance coefficients take no degree of freedom
        assert rep["outliers"] == [] and rep["verdict"]["status"] == "ok", (rep["outliers"], rep["verdict"])
    assert out["variance_factor"] == 1.0
    # reprojection of the identified chain: with the intrinsics the fit ended at (calibrated, moved by the fitted
    # shared-error coefficients) it is that of the run with the true intrinsics (seed 3: 0.0352 vs 0.0350 px);
    # through the intrinsics calibrated before the fit the same, equally good chain showed 0.62 px (17x)
    rp, rp0 = out["reprojection"], ref["reprojection"]
    assert "with_calibrated_intrinsics" not in rp0 and "intrinsics" not in rp0
    assert abs(rp["rms_px"] - rp0["rms_px"]) < 0.2 * rp0["rms_px"], (rp["rms_px"], rp0["rms_px"])
    assert rp["with_calibrated_intrinsics"]["rms_px"] > 3 * rp0["rms_px"], rp
    assert rp["n_corners"] == rp0["n_corners"] == rp["with_calibrated_intrinsics"]["n_corners"]
    assert "intrinsics calibrated before the fit" in out["summary_text"]
    # ... and the fitted intrinsics are closer to the truth than the calibrated ones where the fit sees them
    fit = out["intrinsics"]["propagated"]["fitted_values"]
    assert abs(fit["fx"] - truth["fx"]) < abs(intr["values"]["fx"] - truth["fx"]), (fit["fx"], intr["values"]["fx"])

def test_refine_intrinsics_flag_and_wrong_image_size(recording, tmp_path, capsys):
    assert main(["process", str(recording / "rec"), "--out", str(tmp_path / "o"), "--refine-intrinsics", "--json",
                 "--no-plots"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["intrinsics"]["source"] == "calibrated from the recording"
    assert rep["intrinsics"]["given"]["fx"] == 1100.0
    doc = yaml.safe_load((recording / "rec" / "recording.yaml").read_text())
    _edit_camera(recording / "rec", tmp_path / "bad", **{**doc["camera"], "height": 720})
    with pytest.raises(ConfigError, match=r"recording.yaml: camera.height: 720 px but the images are 1024x768"):
        process_folder(tmp_path / "bad", tmp_path / "o2", plots=False)
    assert main(["process", str(tmp_path / "bad"), "--out", str(tmp_path / "o3")]) == 2
    assert "camera.height" in capsys.readouterr().err
    cam = {k: v for k, v in doc["camera"].items() if k not in ("width", "height")}
    _edit_camera(recording / "rec", tmp_path / "nosize", **cam)
    out = process_folder(tmp_path / "nosize", tmp_path / "o4", plots=False)
    assert out["settings"]["camera"]["width"] == 1024 and out["intrinsics"]["source"] == "recording.yaml"


def test_handeye_process_without_intrinsics_carries_their_uncertainty(recording, tmp_path):
    """Flange-pose folder (hand-eye path) of the same images: without intrinsics the camera is calibrated
    from them and the hand-eye fit includes the intrinsics' uncertainty (nuisance coefficients on the weights of
    the camera + the robot pose error): std larger than with the true intrinsics where the intrinsics
    matter, fitted coefficients within a few of their prior std, and the two results agree within the
    combined std."""
    from flange_folder import assert_mounts_within_std, flange_pose_folder, true_mounts  # tests/experiment helper

    flange, _, _ = flange_pose_folder(recording / "rec", tmp_path / "flange", robot_std_mm=0.2, robot_std_deg=0.02,
                                      declare_std=True)
    ref = process_folder(flange, tmp_path / "ref", plots=False)
    _edit_camera(flange, tmp_path / "nointr", width=1024)
    out = process_folder(tmp_path / "nointr", tmp_path / "out", plots=False)
    assert ref["intrinsics"]["source"] == "recording.yaml" and "propagated" not in ref["intrinsics"]
    prop = out["intrinsics"]["propagated"]
    assert prop["n_directions"] >= 4 and prop["in_fit"] and max(prop["std_inflation"].values()) > 1.5, prop
    # the coefficients' prior is N(0, 1): a misfit absorbed by them (pose covariance scale not estimated) gave 5-13
    assert max(abs(c) for c in prop["coefficients"]) < 4, prop["coefficients"]
    # the robot's std given (0.2 mm / 0.02 deg, as simulated): the fit with the intrinsics' error is adequate
    assert out["adequacy"]["verdict"] == "consistent", out["adequacy"]
    a, b = ref["handeye"]["transforms"], out["handeye"]["transforms"]
    truth = true_mounts(recording / "rec")
    assert_mounts_within_std(a, truth)
    assert_mounts_within_std(b, truth)
    for k in a:
        sa, sb = np.array(a[k]["std_xyz_m"]), np.array(b[k]["std_xyz_m"])
        # not smaller, up to the variance factors (chi2/dof when above 1, each run its own)
        assert np.all(sb >= sa * 0.95), (k, sa, sb)
        d = np.array(b[k]["matrix"])[:3, 3] - np.array(a[k]["matrix"])[:3, 3]
        assert np.all(np.abs(d) < 3 * np.hypot(sa, sb)), (k, d, sa, sb)
    # reprojection with the intrinsics the fit ended at, the calibrated ones' figure beside it (labelled)
    rp, rp0 = out["reprojection"], ref["reprojection"]
    assert rp is out["handeye"]["reprojection"] or rp == out["handeye"]["reprojection"]
    assert rp["rms_px"] < rp["with_calibrated_intrinsics"]["rms_px"] and rp["rms_px"] < 2 * rp0["rms_px"], (rp, rp0)


def test_handeye_process_with_a_camera_file_carries_its_std(recording, tmp_path):
    """Flange-pose folder processed with a camera.yaml holding the true intrinsics and a std (0.5 % of the focal
    length, 2 px on the principal point, diagonal: no covariance): the file's std reported, its uncertainty in the
    fit (nuisance directions, warned that the correlations are taken as zero), the mounts' std larger than with the
    same intrinsics given without std, the mounts within them."""
    from flange_folder import assert_mounts_within_std, flange_pose_folder, true_mounts  # tests/experiment helper

    flange, _, _ = flange_pose_folder(recording / "rec", tmp_path / "flange", robot_std_mm=0.2, robot_std_deg=0.02,
                                      declare_std=True)
    cam = yaml.safe_load((flange / "recording.yaml").read_text())["camera"]
    std = {"fx": 0.005 * cam["fx"], "fy": 0.005 * cam["fy"], "cx": 2.0, "cy": 2.0,
           "dist": [0.005, 0.01, 1e-4, 1e-4, 0.01]}
    cam_file = tmp_path / "camera.yaml"
    cam_file.write_text(yaml.safe_dump({"format": "vision_calib.camera/1", **cam, "std": std}))
    ref = process_folder(flange, tmp_path / "ref", plots=False)
    out = process_folder(flange, tmp_path / "out", plots=False, camera_file=cam_file)
    intr = out["intrinsics"]
    assert intr["std"]["fx"] == pytest.approx(std["fx"]) and intr["propagated"]["in_fit"]
    assert any("correlations are taken as zero" in w for w in out["warnings"])
    a, b = ref["handeye"]["transforms"], out["handeye"]["transforms"]
    assert_mounts_within_std(b, true_mounts(recording / "rec"))
    ratio = max(max(np.array(b[k]["std_xyz_m"]) / np.array(a[k]["std_xyz_m"])) for k in a)
    assert ratio > 1.3, ratio
