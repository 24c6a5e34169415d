"""The shared pieces of summary.txt and report.html (report/text.py): the one std formatter (significant digits),
the one table of figure labels (with a readable fallback), angles in deg wherever a person reads them (an H4 run's
V1/V2/V3 criteria), and the lack-of-fit line without absurd detectable amplitudes (process --refine-intrinsics of
the shipped example, issue 25: 'q2 0.011-1.9e+06')."""

import json
import re

import numpy as np
import pytest

from vision_calib.cli import main
from vision_calib.identify.lack_of_fit import MAX_DETECTABLE_DEG
from vision_calib.report.text import FIGURE_LABELS, figure_head, figure_label, fmt_sig, lack_of_fit_line
from vision_calib.rig import SCENES_DIR

ROOT = SCENES_DIR.parent


@pytest.mark.parametrize("x, text", [(0.0036123, "0.0036"), (3.6e-3, "0.0036"), (1.03, "1.0"), (0.0947, "0.095"),
                                     (0.00996, "0.010"), (12.345, "12"), (450.2, "450"), (-0.00622, "-0.0062"),
                                     (3.6e-7, "3.6e-07"), (0.0, "0"), (None, "n/a"), (float("nan"), "n/a"),
                                     (np.float64(0.25), "0.25")])
def test_fmt_sig_gives_two_significant_digits(x, text):
    assert fmt_sig(x) == text


def test_unknown_keys_read_as_words_in_display_units():
    assert figure_label("V3_m") == FIGURE_LABELS["V3_m"] and FIGURE_LABELS["V3_m"][1:] == ("mm", 1e3)
    assert figure_label("V1_rad")[1:] == ("deg", pytest.approx(np.degrees(1.0)))
    assert figure_label("gap_to_wall_m") == ("gap to wall", "mm", 1e3)
    assert figure_label("tilt_rad") == ("tilt", "deg", pytest.approx(np.degrees(1.0)))
    assert figure_label("mystery") == ("mystery", "", 1.0)
    assert figure_head("gap_to_wall_m") == "gap to wall [mm]" and figure_head("mystery") == "mystery"
    for key, (label, unit, f) in FIGURE_LABELS.items():  # every label is words, its unit mm / deg / px or none
        assert "_" not in label and unit in ("", "mm", "deg", "px") and f > 0, key


def test_lack_of_fit_line_omits_amplitudes_that_mean_nothing():
    """A report written before the bound (its worst-phase amplitude 1.9e+06 deg) prints 'any', as one written after
    it (None); a best-phase amplitude beyond MAX_DETECTABLE_DEG drops the term."""
    def lof(amps):
        return {"test": "F", "level": 0.01, "significant": False, "message": "", "groups": [
            {"name": f"joint {j + 1}", "term": f"q{j + 1}", "p_value": 0.5,
             "harmonics": [{"order": 2, "detectable_amplitude_deg": a}]} for j, a in enumerate(amps)]}

    line = lack_of_fit_line(lof([[0.011, 1.9e6], [0.02, None], [2 * MAX_DETECTABLE_DEG, None], [0.01, 0.03]]))
    assert "q1 0.011-any, q2 0.02-any, q4 0.01-0.03" in line and "q3" not in line and "e+" not in line


@pytest.mark.slow
def test_refined_intrinsics_give_no_absurd_detectable_amplitude(tmp_path):
    """process --refine-intrinsics of the shipped example: joint 2's 2nd harmonic is absorbed at one phase (the
    test sees round-off of it): no amplitude there, and every amplitude given is below MAX_DETECTABLE_DEG."""
    out = tmp_path / "r"
    assert main(["process", str(ROOT / "examples" / "rx90_eye_in_hand"), "--out", str(out), "--refine-intrinsics",
                 "--json", "--no-plots"]) == 0
    rep = json.loads((out / "report.json").read_text())
    amps = [a for g in rep["lack_of_fit"]["groups"] for h in g.get("harmonics", [])
            for a in h["detectable_amplitude_deg"]]
    assert amps and all(a is None or 0 < a <= MAX_DETECTABLE_DEG for a in amps)
    assert None in amps  # some phase is absorbed
    line = next(ln for ln in (out / "summary.txt").read_text().splitlines() if ln.startswith("lack of fit"))
    assert re.search(r"q2 [0-9.]+-any", line) and not re.search(r"\de\+\d", line), line


@pytest.mark.slow
def test_h4_criteria_in_deg_and_mm_with_labels(tmp_path):
    """An H4 simulation's validation criteria V1/V2 (stored in rad) and V3 (m) read in deg and mm, by their labels,
    in summary.txt and on the page; no figure of the summary is in rad."""
    out = tmp_path / "h4"
    assert main(["simulate", str(SCENES_DIR / "h4_vision.yaml"), "--poses", "12", "--frames", "1", "--workers", "1",
                 "--no-plots", "--json", "--out", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text())
    a = rep["accuracy"]["after"]
    assert {"V1_rad", "V2_rad", "V3_m"} <= set(a) and set(a) <= set(FIGURE_LABELS)
    summary = (out / "summary.txt").read_text()
    assert not re.search(r"\d rad\b", summary), summary
    crit = next(ln for ln in summary.splitlines() if ln.startswith("criteria"))
    assert f"V2: RMS joint residual {rep['accuracy']['before']['V2_rad'] * np.degrees(1):.3g} -> " \
           f"{a['V2_rad'] * np.degrees(1):.3g} deg" in crit
    assert f"-> {a['V3_m'] * 1e3:.3g} mm" in crit
    page = (out / "report.html").read_text()
    more = re.search(r'<section id="more".*?</section>', page, re.S).group(0)
    row = re.search(r"<tr><td class=\"l\">V3: straight-line deviation</td><td class=\"l\">mm</td>(.*?)</tr>", more)
    assert row, more[:2000]
    vals = [float(v) for v in re.findall(r"<td>([^<]+)</td>", row.group(1))]
    assert vals == pytest.approx([rep["accuracy"]["before"]["V3_m"] * 1e3, a["V3_m"] * 1e3], rel=1e-3)
    assert "V3_m" not in more
