"""report.json of real runs (simulate, process of its exported recording, process of a hand-eye recording,
process-poses) validates against the shipped JSON Schema (report/schema.json); the schema itself is a
valid draft 2020-12 schema that refuses reports missing what every run writes."""

import copy
import json

import jsonschema
import pytest

from vision_calib.cli import main
from vision_calib.report.build import SCHEMA_PATH
from vision_calib.rig import SCENES_DIR

from flange_folder import flange_pose_folder, measured_pose_file  # noqa: E402 (tests/experiment helper)

RX90 = str(SCENES_DIR / "rx90_eye_in_hand.yaml")


@pytest.fixture(scope="module")
def validator():
    schema = json.loads(SCHEMA_PATH.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """{kind: report.json dict} of one run of each command that writes a report (CLI, as a user runs it)."""
    d = tmp_path_factory.mktemp("schema")
    assert main(["simulate", RX90, "--poses", "12", "--frames", "2", "--seed", "3", "--workers", "1", "--json",
                 "--no-plots", "--out", str(d / "sim"), "--export-recording", str(d / "rec")]) == 0
    assert main(["process", str(d / "rec"), "--out", str(d / "proc"), "--json"]) == 0  # with its plots
    flange, _, _ = flange_pose_folder(d / "rec", d / "flange", robot_std_mm=0.2, robot_std_deg=0.02)
    assert main(["process", str(flange), "--out", str(d / "handeye"), "--json", "--no-plots"]) == 0
    mp = measured_pose_file(d / "mp.yaml", RX90)
    assert main(["process-poses", str(mp), "--out", str(d / "poses"), "--json", "--no-plots"]) == 0
    return {name: json.loads((d / name / "report.json").read_text()) for name in ("sim", "proc", "handeye", "poses")}


@pytest.mark.slow
@pytest.mark.parametrize("name, kind", [("sim", "simulation"), ("proc", "process"), ("handeye", "process_handeye"),
                                        ("poses", "process_poses")])
def test_report_of_a_real_run_validates(reports, validator, name, kind):
    rep = reports[name]
    assert rep["kind"] == kind
    errors = [f"{'/'.join(map(str, e.absolute_path))}: {e.message[:200]}" for e in validator.iter_errors(rep)]
    assert not errors, errors
    # the blocks the kind-specific rules require are there (the if/then of the schema took effect)
    want = {"simulation": "accuracy", "process": "intrinsics", "process_handeye": "handeye", "process_poses": "holdout"}
    assert rep[want[kind]] is not None


@pytest.mark.slow
def test_schema_refuses_reports_that_break_the_contract(reports, validator):
    """Each mutation of a valid report breaks one promise of the schema, and the validator names it."""
    sim, he = reports["sim"], reports["handeye"]
    cases = [
        (sim, lambda r: r.pop("verdict"), "verdict"),
        (sim, lambda r: r["verdict"].update(status="fine"), "status"),
        (sim, lambda r: r.pop("seed"), "seed"),  # simulation-only requirement
        (sim, lambda r: r["parameters"][0].pop("std"), "std"),
        (sim, lambda r: r["parameters"][0].update(identified="1.0"), "identified"),
        (sim, lambda r: r["verdict"].update(status="failed", ok=False), "model"),  # no calibrated model when failed
        (he, lambda r: r.pop("handeye"), "handeye"),
        (he, lambda r: r["settings"].update(method="gauss"), "method"),
    ]
    for rep, mutate, where in cases:
        bad = copy.deepcopy(rep)
        mutate(bad)
        errors = list(validator.iter_errors(bad))
        assert errors, where
        assert any(where in e.message or where in map(str, e.absolute_path) for e in errors), (where, errors)


def test_identify_synthetic_verdict_and_parameter_rows_follow_the_schema(validator, capsys):
    """identify-synthetic --json is not a report.json (no kind, source, files), but its verdict and parameter
    rows are the same blocks: they validate against the schema's $defs."""
    assert main(["identify-synthetic", RX90, "--poses", "20", "--method", "lse", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    defs = validator.schema["$defs"]
    for sub, value in [("verdict", out["verdict"])] + [("parameter", row) for row in out["parameters"]]:
        v = jsonschema.Draft202012Validator({**defs[sub], "$defs": defs})
        assert not list(v.iter_errors(value)), (sub, value)
