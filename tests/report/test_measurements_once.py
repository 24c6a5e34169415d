"""Per-pose measurements are written once: measurements.json holds them, report.json names that file."""

import json
from pathlib import Path

from vision_calib.experiment.process import process_folder
from vision_calib.report.write import on_disk

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "rx90_eye_in_hand"


def test_report_json_names_measurements_json_instead_of_repeating_it(tmp_path):
    rep = process_folder(EXAMPLE, tmp_path / "out", plots=False)
    on_file = json.loads((tmp_path / "out" / "report.json").read_text())["measurements"]
    meas = json.loads((tmp_path / "out" / "measurements.json").read_text())
    assert "poses" not in on_file and on_file["poses_file"] == "measurements.json"
    assert {k: v for k, v in rep["measurements"].items() if k != "poses"} == {
        k: v for k, v in on_file.items() if k != "poses_file"}
    assert [p["pose_id"] for p in meas["poses"]] == [p["pose_id"] for p in rep["measurements"]["poses"]]
    assert meas["poses"] == json.loads(json.dumps(rep["measurements"]["poses"]))


def test_report_keeps_its_poses_without_a_matching_measurements_file(tmp_path):
    report = {"measurements": {"n_poses": 2, "poses": [{"pose_id": "a"}, {"pose_id": "b"}]}}
    assert on_disk(report, tmp_path) is report  # no file: kept
    (tmp_path / "measurements.json").write_text(json.dumps({"poses": [{"pose_id": "a"}]}))
    assert on_disk(report, tmp_path) is report  # another run's file: kept
    (tmp_path / "measurements.json").write_text(json.dumps({"poses": [{"pose_id": "a"}, {"pose_id": "b"}]}))
    assert on_disk(report, tmp_path)["measurements"] == {"n_poses": 2, "poses_file": "measurements.json"}
