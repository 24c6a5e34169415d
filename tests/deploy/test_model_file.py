"""calibrated_model.yaml format 2: the identified parameters' full covariance (names order), the fixed parameters
(value, prior std, why), the base-parameter folds, the joint offsets; format 1 files still load (diagonal
covariance, with a note); a pipeline (process-poses) writes the covariance of its fit; bad entries are named."""

import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from vision_calib.cli import main
from vision_calib.deploy import CalibratedRobot
from vision_calib.errors import ConfigError
from vision_calib.io.model_export import FORMAT, read_calibrated_model
from vision_calib.rig import SCENES_DIR

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiment"))
from flange_folder import measured_pose_file  # noqa: E402 (tests/experiment helper)


def test_the_file_holds_the_fit_covariance_in_names_order(result):
    res = result.run.result
    doc = yaml.safe_load((result.folder / "calibrated_model.yaml").read_text())
    assert doc["format"] == FORMAT
    names = doc["covariance"]["names"]
    assert names == [n for n, f in zip(res.names, res.free) if f]
    sym = 0.5 * (res.covariance + res.covariance.T)  # written symmetric (the solver's is to rounding)
    np.testing.assert_array_equal(np.array(doc["covariance"]["matrix"]), sym)
    assert np.abs(sym - res.covariance).max() < 1e-12 * np.abs(sym).max()
    m = read_calibrated_model(result.folder / "calibrated_model.yaml")
    idx = [m.names.index(n) for n in names]
    np.testing.assert_array_equal(m.covariance[np.ix_(idx, idx)], sym)
    assert not np.any(np.delete(np.delete(m.covariance, idx, 0), idx, 1))  # fixed ones: no variance (no prior)
    np.testing.assert_allclose(np.sqrt(np.diag(m.covariance))[idx], res.std[res.free], rtol=1e-12)
    fixed = [n for n, f in zip(res.names, res.free) if not f]
    assert sorted(m.fixed) == sorted(fixed)
    for n in fixed:
        assert m.fixed[n]["value"] == res.identified[res.names.index(n)] and m.fixed[n]["reason"]


def test_ur5e_joint_offsets_folded_into_the_joint_origins_are_listed(results):
    m = results["ur5e_eye_in_hand"].robot.model
    folded = {f["parameter"]: f["into"] for f in m.folded}
    assert folded["q0_2"] == pytest.approx({"j2.rz": 1.0}, rel=1e-9)
    for j in (3, 4, 5, 6):  # every joint offset after the first is folded somewhere (j1's into the base mount)
        assert f"q0_{j}" in folded and "not identifiable" in m.fixed[f"q0_{j}"]["reason"]
    assert m.fixed["q0_1"]["value"] == 0.0
    assert set(m.joint_offsets) == {f"q{j}" for j in range(1, 7)}
    assert m.joint_offsets["q2"]["parameter"] == "q0_2" and m.joint_offsets["q2"]["unit"] == "rad"


def test_rx90_records_the_hayati_d3_and_the_base_folds(results):
    m = results["rx90_eye_in_hand"].robot.model
    assert "redundant with d2" in m.fixed["d3"]["reason"]
    folded = {f["parameter"]: f["into"] for f in m.folded}
    assert folded["theta1"] == pytest.approx({"T_target_base.rz": 1.0}, rel=1e-9)


def test_h4_tilt_priors_are_recorded(results):
    m = results["h4_vision"].robot.model
    pri = m.doc.get("priors", {})
    assert set(pri) == {"B_T_C.tilt_x", "B_T_C.tilt_y", "M_T_E.tilt_x", "M_T_E.tilt_y"}
    assert all(0 < v < 0.01 for v in pri.values())
    assert "M_T_E.z" in m.fixed


def _format1(src: Path, dst: Path) -> Path:
    """The file as format 1 wrote it (no covariance, fixed, priors, folded, joint offsets)."""
    doc = yaml.safe_load(src.read_text())
    doc = {k: v for k, v in doc.items() if k not in ("covariance", "fixed", "priors", "folded", "joint_offsets")}
    doc["format"] = "vision_calib.calibrated_model/1"
    dst.mkdir(exist_ok=True)
    (dst / "robot").mkdir(exist_ok=True)
    for f in (src.parent / "robot").iterdir():
        (dst / "robot" / f.name).write_bytes(f.read_bytes())
    (dst / "calibrated_model.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return dst / "calibrated_model.yaml"


def test_format_1_files_load_with_a_diagonal_covariance_and_a_note(results, tmp_path):
    r = results["rx90_eye_in_hand"]
    old = CalibratedRobot.load(_format1(r.folder / "calibrated_model.yaml", tmp_path / "old"))
    assert any("no covariance" in n for n in old.notes)
    std = r.run.result.std
    np.testing.assert_allclose(np.sqrt(np.diag(old.covariance)), np.where(np.isfinite(std), std, 0.0), rtol=1e-12)
    assert np.count_nonzero(old.covariance - np.diag(np.diag(old.covariance))) == 0
    q = r.run.poses[:5]
    T_new, C_new = r.robot.forward(q)
    T_old, C_old = old.forward(q)
    np.testing.assert_array_equal(T_old, T_new)  # same model
    assert not np.allclose(C_old, C_new, rtol=0.05)  # the correlations matter: the diagonal is only a fallback
    new_off, old_off = r.robot.joint_offsets(), old.joint_offsets()  # computed when the file has none
    assert old_off.keys() == new_off.keys()
    for j in new_off:
        assert old_off[j]["offset"] == pytest.approx(new_off[j]["offset"], abs=1e-15), j


@pytest.mark.parametrize("edit,match", [
    (lambda d: d["covariance"]["matrix"][0].__setitem__(1, 1.0), "not symmetric"),
    (lambda d: d["covariance"]["names"].__setitem__(0, "nope"), "unknown or repeated parameter names"),
    (lambda d: d["covariance"].__setitem__("matrix", [[1.0]]), "matrix: expected a finite"),
    (lambda d: d["covariance"]["matrix"][0].__setitem__(0, -1.0), "not positive semi-definite"),
    (lambda d: d.__setitem__("format", "vision_calib.calibrated_model/9"), "format: expected one of"),
    (lambda d: d["fixed"]["d3"].__setitem__("prior_std", -1), "fixed.d3.prior_std"),
])
def test_bad_model_files_are_named(results, tmp_path, edit, match):
    src = results["rx90_eye_in_hand"].folder / "calibrated_model.yaml"
    doc = yaml.safe_load(src.read_text())
    edit(doc)
    (tmp_path / "robot").mkdir()
    for f in (src.parent / "robot").iterdir():
        (tmp_path / "robot" / f.name).write_bytes(f.read_bytes())
    (tmp_path / "calibrated_model.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=match) as e:
        read_calibrated_model(tmp_path / "calibrated_model.yaml")
    assert "calibrated_model.yaml" in str(e.value)


def test_a_fixed_parameter_with_a_prior_std_adds_its_variance(results, tmp_path):
    src = results["rx90_eye_in_hand"].folder / "calibrated_model.yaml"
    doc = yaml.safe_load(src.read_text())
    doc["fixed"]["d3"]["prior_std"] = 2e-4
    (tmp_path / "robot").mkdir()
    for f in (src.parent / "robot").iterdir():
        (tmp_path / "robot" / f.name).write_bytes(f.read_bytes())
    (tmp_path / "calibrated_model.yaml").write_text(yaml.safe_dump(doc))
    m = read_calibrated_model(tmp_path / "calibrated_model.yaml")
    k = m.names.index("d3")
    assert m.covariance[k, k] == pytest.approx(4e-8) and not np.any(np.delete(m.covariance[k], k))


def test_process_poses_writes_its_fit_covariance(tmp_path):
    """The pipeline passes the fit (covariance, problem, identifiability) to the model file (report.write)."""
    mp = measured_pose_file(tmp_path / "in" / "measured.yaml", SCENES_DIR / "ur5e_eye_in_hand.yaml", n=40)
    assert main(["process-poses", str(mp), "--out", str(tmp_path / "out"), "--no-plots", "--json"]) == 0
    m = read_calibrated_model(tmp_path / "out" / "calibrated_model.yaml")
    assert m.covariance_source.startswith("identification")
    import json

    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    std = {p["name"]: p["std"] for p in rep["parameters"] if p["free"]}
    for n, s in std.items():
        assert np.sqrt(m.covariance[m.names.index(n), m.names.index(n)]) == pytest.approx(s, rel=1e-9)
    C = m.covariance[np.ix_(m.free, m.free)]
    corr = C / np.sqrt(np.outer(np.diag(C), np.diag(C)))
    assert np.max(np.abs(corr - np.eye(len(C)))) > 0.3  # off-diagonal terms are there
    assert {f["parameter"] for f in m.folded} >= {"q0_2", "q0_3"}


def test_the_file_text_is_pyyamls_own(result):
    """The model file is written through libyaml's emitter where PyYAML has it (config.safe_dump): the same text
    as PyYAML's Python emitter gives for the same content."""
    text = (result.folder / "calibrated_model.yaml").read_text()
    assert yaml.safe_dump(yaml.safe_load(text), sort_keys=False, default_flow_style=None) == text


def test_safe_dump_is_yaml_safe_dump():
    from vision_calib.config import safe_dump

    doc = {"name": "a " * 70 + "long note", "unicode": "κ ≤ 1 µm", "multi": "line one\nline two", "empty": "",
           "numbers": [1, -2.5, 1e-300, float("inf"), float("nan"), 0.1 + 0.2], "flags": [True, False, None],
           "nested": {"m": [[1.0, 2.0], [3.0, 4.0]], "k: colon": "x: y", "q": "'quoted' \"both\"", "t": (1, 2)},
           "odd": ["yes", "no", "~", "1.0", "-", "a #b", " lead", "trail ", "@at", "%pc", "&amp", "*star"]}
    for kw in ({}, {"sort_keys": False}, {"sort_keys": False, "default_flow_style": None},
               {"sort_keys": False, "default_flow_style": None, "width": 1000}):
        assert safe_dump(doc, **kw) == yaml.safe_dump(doc, **kw)
