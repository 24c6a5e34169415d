"""CLI commands not covered elsewhere: printable target export, errors without tracebacks; the conventions
(--version, help on every option, an example per command, exit codes documented, --out for every output folder,
the deprecated positional DST)."""

import subprocess
import sys

import pytest

from vision_calib.cli import main
from vision_calib.targets import load_target, read_png_phys


def test_target_export_png_carries_the_physical_scale(tmp_path, capsys):
    out = tmp_path / "a5.png"
    assert main(["target", "targets/charuco_a5.yaml", "--out", str(out), "--dpi", "300"]) == 0
    w_px, h_px, ppm_x, ppm_y = read_png_phys(out)
    w_m, h_m = load_target("targets/charuco_a5.yaml").outline_m()
    assert abs(w_px / ppm_x - w_m) < 1 / ppm_x and abs(h_px / ppm_y - h_m) < 1 / ppm_y


def test_bad_target_file_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "t.yaml"
    bad.write_text("kind: charuco\nrows: 5\ncols: 7\ndictionary: DICT_NOPE\nsquare_m: 0.02\nmarker_m: 0.015\n")
    r = subprocess.run([sys.executable, "-m", "vision_calib.cli", "target", str(bad), "--out", str(tmp_path / "x.png")],
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and "DICT_NOPE" in r.stderr


# ------------------------------------------------------------------------------- conventions (issue 19, item 3)
def _subparsers():
    from vision_calib.cli import build_parser

    ap = build_parser()
    sub = next(a for a in ap._actions if a.__class__.__name__ == "_SubParsersAction")
    return ap, sub.choices


def test_version_prints_the_package_version(capsys):
    import vision_calib

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.split() == ["vision-calib", vision_calib.__version__]


def test_every_option_of_every_command_has_help_and_every_command_an_example(capsys):
    from vision_calib.cli import COMMANDS

    ap, subs = _subparsers()
    assert set(subs) == set(COMMANDS)  # the dispatch table serves every command the parser offers
    for name, p in subs.items():
        for action in p._actions:
            assert action.help and action.help.strip(), f"{name} {action.option_strings or action.dest}: no help"
        with pytest.raises(SystemExit) as e:
            main([name, "--help"])
        assert e.value.code == 0
        text = capsys.readouterr().out
        assert "examples:\n" in text, name
        examples = text.split("examples:\n", 1)[1]
        assert f"vision-calib {name} " in examples or f"vision-calib {name}\n" in examples, name


def test_top_level_help_documents_the_exit_codes_the_code_returns(capsys):
    from vision_calib import cli

    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    for code in (0, 2, cli.EXIT_NOT_CONVERGED, 130):
        assert f"\n  {code} " in text, code
        assert f"\n    {code} " in cli.__doc__, code


def test_folder_outputs_are_named_by_out_everywhere():
    _, subs = _subparsers()
    for name, p in subs.items():
        if name in ("identifiability", "identify-synthetic", "docs"):  # print only
            continue
        assert any("--out" in a.option_strings for a in p._actions), name


def _rosi_set(d):
    """A three-view ROS-I data set (static camera, ChArUco, flat grey images): enough to import and export."""
    import cv2
    import numpy as np
    import yaml

    (d / "images").mkdir(parents=True)
    (d / "poses").mkdir()
    data = []
    for i in range(3):
        cv2.imwrite(str(d / "images" / f"{i}.png"), np.full((48, 64), 100 + i, np.uint8))
        q = np.array([0.1 * i, -0.2, 0.3, 0.9]) / np.linalg.norm([0.1 * i, -0.2, 0.3, 0.9])
        (d / "poses" / f"{i}.yaml").write_text(yaml.safe_dump(
            {"x": 0.1 * i, "y": -0.5, "z": 0.8, "qw": float(q[3]), "qx": float(q[0]), "qy": float(q[1]),
             "qz": float(q[2])}))
        data.append({"image": f"images/{i}.png", "pose": f"poses/{i}.yaml"})
    doc = {"data": data, "intrinsics": {"fx": 60.0, "fy": 61.0, "cx": 32.0, "cy": 24.0}, "static_camera": True,
           "target_finder": {"type": "CharucoGridTargetFinder", "rows": 7, "cols": 5, "chessboard_dim": 0.036195,
                             "aruco_marker_dim": 0.018256, "dictionary": 10}}
    (d / "cal_data.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return d


def _same_tree(a, b):
    fa = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert fa and fa == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for rel in fa:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel


def test_old_positional_dst_still_works_and_warns(tmp_path, capsys):
    """import-rosi / export-rosi SRC DST write what SRC --out DST writes, with a deprecation note on stderr
    naming the new spelling; DST and --out together, or neither, is a usage error (exit 2)."""
    src = _rosi_set(tmp_path / "rosi")
    for cmd, a, b in (("import-rosi", src, "rec"), ("export-rosi", tmp_path / "rec_new", "rosi")):
        assert main([cmd, str(a), "--out", str(tmp_path / f"{b}_new")]) == 0
        assert "deprecated" not in capsys.readouterr().err
        assert main([cmd, str(a), str(tmp_path / f"{b}_old")]) == 0
        err = capsys.readouterr().err
        assert f"`{cmd} SRC DST` is deprecated" in err and "--out" in err
        _same_tree(tmp_path / f"{b}_new", tmp_path / f"{b}_old")
        with pytest.raises(SystemExit) as e:
            main([cmd, str(a), str(tmp_path / "x"), "--out", str(tmp_path / "y")])
        assert e.value.code == 2 and "once" in capsys.readouterr().err
        with pytest.raises(SystemExit) as e:
            main([cmd, str(a)])
        assert e.value.code == 2 and "--out DIR" in capsys.readouterr().err
