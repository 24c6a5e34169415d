"""TransformPairs YAML (handeye_calib_camodocal's pose pairs): the OpenCV header (%YAML:1.0, ---) read by our own
tolerant reader, a written file round-trips, every bad file a DataError naming the file, the key and its line;
import-pairs writes a pose-pair file process-poses reads."""

from __future__ import annotations

import numpy as np
import pytest

from vision_calib import frames
from vision_calib.cli import main
from vision_calib.errors import DataError
from vision_calib.io.measured_poses import PosePairs, read_measured_poses
from vision_calib.io.transform_pairs import import_pairs, read_transform_pairs, write_transform_pairs

#: two pairs in the layout OpenCV's FileStorage writes (data wrapped over lines, "0." for zeros), then a third
CAMODOCAL = """%YAML:1.0
---
frameCount: 3
T1_0: !!opencv-matrix
   rows: 4
   cols: 4
   dt: d
   data: [ 6.3848318753984534e-01, 7.6753379672568189e-01,
       5.6842678621069898e-02, 6.1211838349307879e-01,
       8.5022879393997774e-03, 6.6817928900269719e-02,
       -9.9772895892485458e-01, -3.9910451893784837e-02,
       -7.6958880600535906e-01, 6.3751645881603558e-01,
       3.6136330886072487e-02, 2.6138077789285857e-01, 0., 0., 0., 1. ]
T2_0: !!opencv-matrix
   rows: 4
   cols: 4
   dt: d
   data: [ -1.6438553297344516e-01, -2.1382562129914787e-01,
       -9.6294132750914263e-01, 7.6429097541348479e-01,
       1.6187521450743705e-01, 9.5713857396582280e-01,
       -2.4017111640420524e-01, -1.2248900657489320e-01,
       9.7302302720809630e-01, -1.9535699092355124e-01,
       -1.2272666629582951e-01, 2.0038531707099566e-01, 0., 0., 0., 1. ]
"""


def _pairs(n=6, seed=0):
    rng = np.random.default_rng(seed)
    T1 = frames.make_T(frames.so3_exp(rng.normal(size=(n, 3))), rng.uniform(-0.5, 0.5, (n, 3)))
    T2 = frames.make_T(frames.so3_exp(rng.normal(size=(n, 3))), rng.uniform(0.2, 0.8, (n, 3)))
    return T1, T2


def _camodocal_file(tmp_path, header=CAMODOCAL):
    """CAMODOCAL plus T1_1..T2_2 in the same layout (written from known transforms)."""
    T1, T2 = _pairs(3, 5)
    body = ""
    for i in (1, 2):
        for name, T in (("T1", T1[i]), ("T2", T2[i])):
            vals = [f"{v:.17e}" for v in T.ravel()]
            vals[12:] = ["0.", "0.", "0.", "1."]
            body += (f"{name}_{i}: !!opencv-matrix\n   rows: 4\n   cols: 4\n   dt: d\n   data: [ "
                     + ",\n       ".join(", ".join(vals[k:k + 2]) for k in range(0, 16, 2)) + " ]\n")
    p = tmp_path / "TransformPairsInput.yml"
    p.write_text(header + body)
    return p, T1, T2


def test_opencv_header_and_layout_are_read(tmp_path):
    p, T1, T2 = _camodocal_file(tmp_path)
    A, B = read_transform_pairs(p)
    assert A.shape == B.shape == (3, 4, 4)
    np.testing.assert_allclose(A[0, 0, :4], [0.63848318753984534, 0.76753379672568189, 0.056842678621069898,
                                             0.61211838349307879], atol=1e-12)  # row-major
    np.testing.assert_allclose(A[1:], T1[1:], atol=1e-14)
    np.testing.assert_allclose(B[1:], T2[1:], atol=1e-14)
    for header in (CAMODOCAL.replace("%YAML:1.0\n", ""), CAMODOCAL.replace("---\n", "")):  # either line alone
        q, _, _ = _camodocal_file(tmp_path, header)
        np.testing.assert_allclose(read_transform_pairs(q)[0], A, atol=0)


def test_written_file_round_trips(tmp_path):
    T1, T2 = _pairs(7)
    p = write_transform_pairs(tmp_path / "pairs.yml", T1, T2)
    text = p.read_text()
    assert text.startswith("%YAML:1.0\n---\nframeCount: 7\nT1_0: !!opencv-matrix\n")
    A, B = read_transform_pairs(p)
    assert np.max(np.abs(A - T1)) < 1e-15 and np.max(np.abs(B - T2)) < 1e-15


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("frameCount: 3", "frameCount: 4"), "frameCount is 4 but the file holds 3 pairs"),
    (lambda t: t.replace("   rows: 4", "   rows: 3", 1), "line 5: T1_0.rows: expected 4"),
    (lambda t: t.replace("   dt: d", "   dt: u", 1), "line 7: T1_0.dt: expected d (double) or f (float)"),
    (lambda t: t.replace(", 0., 0., 0., 1. ]", ", 0., 0., 1. ]", 1), "line 8: T1_0.data: expected 16 numbers"),
    (lambda t: t.replace("8.5022879393997774e-03", "x8.5e-03", 1), "line 10: T1_0.data[4]: not a number"),
    (lambda t: t.replace("6.3848318753984534e-01", "1.6384831875398453e+00", 1),
     "line 4: T1_0: the rotation block is not a rotation"),
    (lambda t: t.replace(", 0., 0., 0., 1. ]", ", 0., 0., 0.5, 1. ]", 1), "line 4: T1_0: last row"),
    (lambda t: t.replace("T2_0:", "T3_0:"), "unknown key 'T3_0'"),
    (lambda t: t.replace("T2_0:", "T2_7:"), "T2_0: the pairs must be numbered 0..2 without holes, each with its T1"),
    (lambda t: t.replace("   cols: 4\n", "   cols: 4\n   step: 1\n", 1), "line 4: T1_0: unknown key(s) step"),
    (lambda t: t.replace("   dt: d\n", "", 1), "line 4: T1_0: missing 'dt'"),
    (lambda t: t + "T1_0: 1\n", "key 'T1_0' given twice"),
    (lambda t: t.replace("data: [ -1.6", "data: [ [ -1.6", 1), "not a readable YAML file"),
])
def test_bad_files_are_named(tmp_path, edit, message):
    p, _, _ = _camodocal_file(tmp_path)
    p.write_text(edit(p.read_text()))
    with pytest.raises(DataError) as exc:
        read_transform_pairs(p)
    assert str(exc.value).startswith(f"{p}: ") and message in str(exc.value), str(exc.value)


def test_too_few_pairs_and_missing_file(tmp_path):
    T1, T2 = _pairs(2)
    p = write_transform_pairs(tmp_path / "two.yml", T1, T2)
    with pytest.raises(DataError, match="2 transform pairs; a hand-eye calibration needs at least 3"):
        read_transform_pairs(p)
    with pytest.raises(DataError, match="file not found"):
        read_transform_pairs(tmp_path / "none.yml")


def test_import_pairs_writes_a_pose_pair_file(tmp_path, capsys):
    """T1 -> the flange poses, T2 -> the measured T_cam_target, exactly; the noise to be estimated per axis."""
    T1, T2 = _pairs(8)
    src = write_transform_pairs(tmp_path / "in.yml", T1, T2)
    assert main(["import-pairs", str(src), "--mount", "fixed", "--out", str(tmp_path / "pp" / "pairs.yaml")]) == 0
    assert "wrote pose-pair file" in capsys.readouterr().out
    pp = read_measured_poses(tmp_path / "pp" / "pairs.yaml")
    assert isinstance(pp, PosePairs) and pp.mount == "fixed" and pp.ids == tuple(f"p{i:03d}" for i in range(8))
    assert np.max(np.abs(pp.T_base_flange - T1)) < 1e-12 and np.max(np.abs(pp.T_cam_target - T2)) < 1e-12
    assert pp.cov is None and pp.noise_frame == "target" and pp.sigma_source.startswith("estimated per axis")
    with pytest.raises(SystemExit) as ex:  # argparse: a usage error
        main(["import-pairs", str(src), "--mount", "sideways", "--out", str(tmp_path / "x.yaml")])
    assert ex.value.code == 2
    capsys.readouterr()
    assert main(["import-pairs", str(src), "--mount", "fixed", "--out", str(tmp_path / "x.csv")]) == 2
    assert "must end in .yaml" in capsys.readouterr().err
    with pytest.raises(DataError, match="--mount: expected one of eye_in_hand, fixed"):
        import_pairs(src, "tripod", tmp_path / "y.yaml")


def test_streamed_reading_equals_the_yaml_reading(tmp_path, monkeypatch):
    """The OpenCV layout is streamed line by line (import-pairs of 200,000 pairs); it gives the same arrays, bit
    for bit, as composing the file as YAML, and a layout it does not know (another key order) falls back to YAML."""
    import vision_calib.io.transform_pairs as TP
    from vision_calib import frames

    rng = np.random.default_rng(3)
    T1 = frames.T_from_xyz_rotvec(rng.normal(size=(25, 6)))
    T2 = frames.T_from_xyz_rotvec(rng.normal(size=(25, 6)))
    path = TP.write_transform_pairs(tmp_path / "p.yml", T1, T2)
    assert TP._streamed_pairs(path) is not None
    fast = TP.read_transform_pairs(path)
    monkeypatch.setattr(TP, "_streamed_pairs", lambda *a, **k: None)
    slow = TP.read_transform_pairs(path)
    monkeypatch.undo()
    assert all(np.array_equal(a, b) for a, b in zip(fast, slow))
    np.testing.assert_allclose(fast[0], T1, atol=1e-12)
    text = path.read_text().replace("   rows: 4\n   cols: 4\n", "   cols: 4\n   rows: 4\n").replace(
        "frameCount: 25\n", "")
    (tmp_path / "q.yml").write_text(text + "frameCount: 25\n")
    assert TP._streamed_pairs(tmp_path / "q.yml") is None  # frameCount after the matrices: not the OpenCV layout
    assert all(np.array_equal(a, b) for a, b in zip(TP.read_transform_pairs(tmp_path / "q.yml"), fast))
