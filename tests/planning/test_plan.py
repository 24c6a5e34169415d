"""``vision-calib plan`` (planning.plan): a UR5e cell with a table and obstacles gets N poses within the joint limits,
each with the clearance, the target measurable, in a tour whose moves were checked; the outputs are a recording to
fill and a scene that simulates exactly the plan; the H4 gets a plan checked for visibility and reachability only;
``--check`` names the poses of a list that are not usable."""

import json
import shutil

import numpy as np
import pytest

pytest.importorskip("fcl")

from vision_calib.cli import main  # noqa: E402
from vision_calib.io.recording import read_recording  # noqa: E402
from vision_calib.planning.plan import H4_NOTE, plan_cell  # noqa: E402
from vision_calib.rig import SCENES_DIR, load_scene, scene_poses  # noqa: E402

CELL = SCENES_DIR / "ur5e_cell.yaml"


@pytest.fixture(scope="module")
def ur5e_plan(tmp_path_factory):
    out = tmp_path_factory.mktemp("plan")
    res = plan_cell(CELL, 20, out, seed=0, n_candidates=4000, draws=1, counts=[20])
    return out, res


def test_ur5e_cell_plan_is_within_limits_clear_and_measurable(ur5e_plan):
    out, res = ur5e_plan
    sc = load_scene(CELL)
    setup, ps = sc.setup, sc.planning
    q = np.array([p["joints_rad"] for p in res["poses"]])
    assert q.shape == (20, 6) and setup.chain.within_limits(q).all()
    clear = np.array([p["clearance_m"] for p in res["poses"]])
    assert np.all(clear >= ps.clearance_m)  # the margin, from FCL / exact plane heights
    cm = res["collision_model"]
    names = {b["name"] for b in cm["bodies"]} | {o["name"] for o in cm["obstacles"]}
    assert {"table", "fixture", "lamp", "target board"} <= names
    assert all(set(p["closest"]) <= names for p in res["poses"])
    for p in res["poses"]:
        v = p["view"]
        assert v["margin_px"] >= ps.margin_px and ps.distance_m[0] <= v["distance_m"] <= ps.distance_m[1]
        assert v["incidence_deg"] <= np.degrees(ps.max_incidence_rad) + 1e-9 and v["square_px"] >= 6
    lev = [p["leverage"] for p in res["poses"]]
    assert sum(lev) == pytest.approx(res["design"]["n_base_parameters"], rel=1e-6)  # leverages add up to L
    assert res["design"]["d_efficiency_vs_random"]["median"] > 1  # D-optimal beats random sets
    t = res["tour"]
    assert t["moves_checked"] and len(t["moves"]) == 19 and t["move_samples"] > 0
    assert all(m["collides"] is False for m in t["moves"]) or res["warnings"]
    assert res["screening"]["colliding"] > 0  # the fixture is in the way of some candidates
    assert res["predicted_accuracy"]["rows"][0]["count"] == 20


def test_plan_outputs_a_recording_to_fill_and_a_scene_that_simulates_it(ur5e_plan):
    out, res = ur5e_plan
    q = np.array([p["joints_rad"] for p in res["poses"]])
    rec = read_recording(out)
    assert list(rec.pose_ids) == [p["id"] for p in res["poses"]] and np.allclose(rec.poses, q)
    assert all((out / "images" / pid).is_dir() for pid in rec.pose_ids)
    sim = load_scene(out / "simulate_plan.yaml")
    assert np.array_equal(scene_poses(sim, np.random.default_rng(5)), q)  # exactly the plan, whatever the seed
    assert sim.validation.kind == "random"
    orig = load_scene(CELL).setup  # the random validation poses come from the cell's region, as without the file
    assert np.array_equal(sim.setup.q_center, orig.q_center) and np.array_equal(sim.setup.q_spread, orig.q_spread)
    saved = json.loads((out / "plan.json").read_text())
    assert saved["format"] == "vision_calib.plan/1" and saved["files"]["poses"] == "poses.csv"
    html = (out / "report.html").read_text()
    assert "Predicted accuracy" in html and "data:image/png;base64" in html and "http" not in html.split("<body>")[1]


def test_plan_page_ends_with_next_steps_and_its_pose_table_fits_a_laptop(ur5e_plan):
    import re

    out, res = ur5e_plan
    html = (out / "report.html").read_text()
    body = html.split("<body>")[1]
    last = body[body.rindex("<h2>"):]
    assert last.startswith("<h2>Next steps</h2>") and f"vision-calib process {out.name}" in last
    assert "images/&lt;pose_id&gt;/" in last and f"record {res['design']['frames']} frames" in last
    assert res["accuracy_vs_count"]["rows"] and "How many poses" in html and body.count("data:image/png;base64") >= 2
    # the pose table's width: each column as wide as its longest unbroken line (~7.5 px a character at the page's
    # font, 17 px padding and border), within the page's 1180 px less its padding
    table = body[body.index("<h2>Poses</h2>"):]
    table = table[table.index("<table>"):table.index("</table>")]
    widths = {}
    for row in re.findall(r"<tr[^>]*>(.*?)</tr>", table, re.S):
        for j, cell in enumerate(re.findall(r"<t[hd][^>]*>(.*?)</t[hd]>", row, re.S)):
            lines = [re.sub(r"<[^>]+>", "", ln).replace("&amp;", "&") for ln in cell.split("<br>")]
            widths[j] = max(widths.get(j, 0), max(len(ln) for ln in lines))
    assert len(widths) >= 9
    assert sum(7.5 * w + 17 for w in widths.values()) <= 1180 - 48, widths


def test_h4_plan_checks_visibility_and_reachability(tmp_path):
    res = plan_cell(SCENES_DIR / "h4_vision.yaml", 20, tmp_path, seed=0, n_candidates=2000, draws=0)
    setup = load_scene(SCENES_DIR / "h4_vision.yaml").setup
    X = np.array([p["commanded"] for p in res["poses"]])
    assert X.shape == (20, 4) and setup.reachable(X).all()
    assert H4_NOTE in res["notes"] and res["collision_model"] is None and not res["tour"]["moves_checked"]
    sim = load_scene(tmp_path / "simulate_plan.yaml")  # joints in poses.csv, back to X by the forward model
    assert np.allclose(scene_poses(sim, np.random.default_rng(0)), X, atol=1e-9)


def test_cli_plan_and_check(tmp_path, capsys):
    out = tmp_path / "plan"
    assert main(["plan", str(CELL), "--poses", "8", "--out", str(out), "--candidates", "3000", "--draws", "1",
                 "--no-plots"]) == 0
    assert "planned 8 poses" in capsys.readouterr().out
    # the plan's own list passes the check
    shutil.copy(out / "poses.csv", tmp_path / "mine.csv")
    assert main(["plan", str(CELL), "--check", str(tmp_path / "mine.csv"), "--angle-unit", "rad", "--out",
                 str(tmp_path / "check"), "--candidates", "2000", "--draws", "1", "--no-plots"]) == 0
    res = json.loads((tmp_path / "check" / "plan.json").read_text())
    assert res["verdict"]["ok"] and res["verdict"]["usable_poses"] == 8
    assert res["predicted_accuracy"]["given"]["draws"] == 1
    # a list with a pose into the table and one that does not see the board: exit 3, both named
    lines = (tmp_path / "mine.csv").read_text().splitlines()
    bad = [lines[0], lines[1], "low," + ",".join(repr(float(v)) for v in np.radians([0, -30, 130, -90, -90, 0])),
           "away," + ",".join(repr(float(v)) for v in np.radians([180, -90, 90, -90, -90, 0]))]
    (tmp_path / "bad.csv").write_text("\n".join(bad) + "\n")
    capsys.readouterr()
    assert main(["plan", str(CELL), "--check", str(tmp_path / "bad.csv"), "--angle-unit", "rad", "--out",
                 str(tmp_path / "check2"), "--candidates", "2000", "--draws", "1", "--no-plots"]) == 3
    err = capsys.readouterr().err
    assert "pose low: collides" in err and "pose away: target not measurable" in err
    # bad input: exit 2, the file and the pose named
    (tmp_path / "broken.csv").write_text("pose_id,q1,q2,q3,q4,q5,q6\na,0,0,0,0,0,zero\n")
    assert main(["plan", str(CELL), "--check", str(tmp_path / "broken.csv"), "--out", str(tmp_path / "c3")]) == 2
    assert "broken.csv: line 2 (pose 'a')" in capsys.readouterr().err
    assert main(["plan", str(CELL), "--poses", "2", "--out", str(tmp_path / "c4"), "--candidates", "500"]) == 2
    assert "plan at least 5 poses" in capsys.readouterr().err


def test_candidate_sources(tmp_path):
    from vision_calib.errors import ConfigError
    from vision_calib.planning.plan import CandidateSource, candidate_poses

    sc = load_scene(CELL)
    setup = sc.setup
    rng = np.random.default_rng(0)
    home = np.radians([0, -90, 90, -90, -90, 0])
    q = candidate_poses(sc, CandidateSource("around", start_rad=tuple(home), delta_rad=np.radians(10)), 500, rng)
    assert q.shape == (500, 6) and np.all(np.abs(q - home) <= np.radians(10) + 1e-12)
    lo, hi = (0.35, -0.1, 0.3), (0.6, 0.3, 0.7)
    q = candidate_poses(sc, CandidateSource("box", box_lo_m=lo, box_hi_m=hi), 2000, rng)
    p = setup.end_point(q)
    assert 0 < len(q) < 2000 and np.all((p >= lo) & (p <= hi))
    with pytest.raises(ConfigError, match="--box"):
        candidate_poses(sc, CandidateSource("box", box_lo_m=(5, 5, 5), box_hi_m=(6, 6, 6)), 200, rng)
    (tmp_path / "l.csv").write_text("pose_id,q1,q2,q3,q4,q5,q6\na,0,-90,90,-90,-90,0\nb,5,-90,90,-90,-90,0\n")
    q = candidate_poses(sc, CandidateSource("list", path=tmp_path / "l.csv"), 0, rng)  # the scene's deg
    assert np.allclose(q[1], home + np.radians([5, 0, 0, 0, 0, 0]))
    h4 = load_scene(SCENES_DIR / "h4_vision.yaml")  # around a joint set: mapped to nacelle poses by the forward model
    q0 = h4.setup.joints(h4.setup.robot.pose_grid()[:1], h4.setup.params.nominal)[0]
    X = candidate_poses(h4, CandidateSource("around", start_rad=tuple(q0), delta_rad=np.radians(3)), 50, rng)
    assert X.shape[1] == 4 and len(X) > 40


def test_validate_on_a_region_plans_for_it(tmp_path):
    """Poses planned for a user's validation poses (--validate-on) predict a smaller error there than poses planned
    for the scene's whole validation region, judged by the same criterion over the user's poses."""
    from vision_calib.planning import design as D

    sc = load_scene(CELL)
    q = sc.setup.sample_poses(np.random.default_rng(11), 12, check_view=False)
    q[:, 0] = np.radians(15.0)  # a slice of the workspace: joint 1 held
    rows = "\n".join(f"v{i},{','.join(f'{v:.6f}' for v in np.degrees(r))}" for i, r in enumerate(q))
    f = tmp_path / "where.csv"
    f.write_text("pose_id," + ",".join(f"q{j + 1}" for j in range(6)) + "\n" + rows + "\n")
    a = plan_cell(CELL, 12, None, seed=3, n_candidates=3000, draws=0)
    b = plan_cell(CELL, 12, None, seed=3, n_candidates=3000, draws=0, validate_on=f)
    assert str(f) in b["design"]["validation_poses"] and str(f) not in a["design"]["validation_poses"]
    base = sc.setup.params.mask(a["design"]["base_parameters"])
    assert b["design"]["base_parameters"] == a["design"]["base_parameters"]
    W = D.validation_weight(D.validation_blocks(sc, q, base))
    mse = []
    for res in (a, b):
        P = np.array([p["joints_rad"] for p in res["poses"]])
        mse.append(D.validation_mse(D.information(sc, P, base).A, np.arange(len(P)), W))
    assert mse[1] < mse[0]
