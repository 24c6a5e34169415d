"""The figures quoted in the documentation pages (vision_calib/docs/*.md), generated: none is typed by hand.

A page holds its figures in blocks

    <!-- figures: NAME -->
    (generated text)
    <!-- /figures -->

where NAME is one of the generators below (``FIGURES``). A generator runs the command(s) its block shows
(shipped scenes, fixed seeds, small sizes) and returns the block's text. From the repository root:

    python docs/figures.py                           # rewrite every block
    python docs/figures.py NAME ...                  # rewrite these blocks
    python docs/figures.py --check [--fast] [NAME ...]   # exit 1 listing the blocks whose text is stale
    python docs/figures.py --list                    # the generators, slow ones marked

Figures from a fixed seed are deterministic and compared exactly as printed; a generator may declare a relative
tolerance (``rtol``) for a stochastic figure, compared number by number (none needs one at present: timings are
not quoted). ``slow`` generators (rendering, studies) are skipped by ``--fast``; one that ``needs`` a data folder
absent here is reported as skipped. ``tests/test_docs.py`` runs the check block by block.

Commands run in this checkout (``vision-calib`` = ``python -m vision_calib.cli``, ``python`` = this interpreter,
PYTHONPATH = the repository) from the repository root; an argument ``out/...`` is written in a scratch folder,
whose path is printed back as ``out/...``.
"""

from __future__ import annotations

import argparse
import atexit
import difflib
import functools
import json
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "vision_calib" / "docs"  # the pages ship with the package
BLOCK = re.compile(r"<!-- figures: (?P<name>[\w.-]+) -->\n(?P<body>.*?)<!-- /figures -->", re.S)
OPEN = re.compile(r"<!-- figures: (?P<name>[^ ]*) -->")
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


# ----------------------------------------------------------------------------------------------- registry
@dataclass(frozen=True)
class Figure:
    name: str
    make: Callable[[], str]
    slow: bool = False
    rtol: float | None = None  # None: the text must be equal; else numbers within rtol, the rest equal
    needs: str | None = None  # a path (relative to the repository) the figure's data come from


FIGURES: dict[str, Figure] = {}


def figure(name: str, slow: bool = False, rtol: float | None = None, needs: str | None = None):
    def deco(fn):
        FIGURES[name] = Figure(name, fn, slow, rtol, needs)
        return fn
    return deco


# ----------------------------------------------------------------------------------------------- running
@functools.lru_cache(maxsize=None)
def scratch() -> Path:
    d = Path(tempfile.mkdtemp(prefix="vc_figures_"))
    atexit.register(shutil.rmtree, d, True)
    (d / "out").mkdir()
    return d


@dataclass(frozen=True)
class Run:
    cmd: str
    rc: int
    stdout: str
    stderr: str
    out: Path | None  # the --out folder (in the scratch folder)

    def report(self) -> dict | None:
        p = self.out / "report.json" if self.out else None
        return json.loads(p.read_text()) if p and p.exists() else None

    def json(self) -> dict:
        return json.loads(self.stdout)

    def shown(self, lines: list[str] | None = None, exit_status: bool = True) -> str:
        """The command and its output (``lines``, default all but the timings), as a terminal shows them."""
        body = untimed(self.stdout) if lines is None else lines
        tail = [f"(exit status {self.rc})"] if exit_status and self.rc else []
        return "\n".join([f"$ {self.cmd}", *body, *tail])


def _env() -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}


def _unscratch(text: str) -> str:
    return text.replace(str(scratch()) + os.sep, "")


@functools.lru_cache(maxsize=None)
def sh(cmd: str) -> Run:
    """Run ``cmd`` as the docs show it (see the module docstring); cached: blocks that quote one run share it."""
    args = shlex.split(cmd)
    head = {"vision-calib": [sys.executable, "-m", "vision_calib.cli"], "python": [sys.executable]}[args[0]]
    argv = head + [str(scratch() / a) if a.startswith("out/") else a for a in args[1:]]
    p = subprocess.run(argv, cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=1800)
    if p.returncode not in (0, 2, 3):  # 2, 3: a verdict the block shows; anything else is a broken generator
        raise RuntimeError(f"{cmd}: exit status {p.returncode}\n{p.stderr[-3000:]}")
    out = args[args.index("--out") + 1] if "--out" in args else None
    return Run(cmd, p.returncode, _unscratch(p.stdout), _unscratch(p.stderr),
               scratch() / out if out and out.startswith("out/") else None)


def run_python_block(page: str, marker: str) -> None:
    """Run the ```python block of vision_calib/docs/PAGE that contains ``marker``, in the scratch folder (its
    ``out/``)."""
    blocks = re.findall(r"^```python\n(.*?)^```", (DOCS / page).read_text(), flags=re.S | re.M)
    (code,) = [b for b in blocks if marker in b]
    p = subprocess.run([sys.executable, "-c", code], cwd=scratch(), env=_env(), capture_output=True, text=True,
                       timeout=600)
    if p.returncode:
        raise RuntimeError(f"the python block of {page} with {marker!r} failed:\n{p.stderr[-3000:]}")


def untimed(text: str) -> list[str]:
    """Output lines without what depends on the machine's speed: ``time: ...`` lines, ``(1.23 s)``."""
    lines = [ln for ln in text.splitlines() if not ln.startswith("time:")]
    return [re.sub(r" \(\d+(?:\.\d+)? s\)", "", ln) for ln in lines]


def text_block(*parts: str) -> str:
    return "```text\n" + "\n".join(parts) + "\n```"


def md_table(head: list, rows: list, align: str | None = None) -> str:
    align = align or "-" + "r" * (len(head) - 1)
    sep = ["---" if a == "-" else "---:" for a in align]
    return "\n".join("| " + " | ".join(str(c) for c in r) + " |" for r in [head, sep, *rows])


# ----------------------------------------------------------------------------------------------- H4 and its paper
BENCH_ID_H4 = "python benchmarks/bench_identifiability.py h4"
PAPER_T1 = {"model 12": 257, "model 31 without d": 421, "model 31 with d": 1900}
PAPER_T3 = dict(zip("ABCDEFGH", (115, 160, 116, 161, 187, 192, 194, 220)))
T1_PARAMS = {"model 12": 12, "model 31 without d": 30, "model 31 with d": 31}


@functools.lru_cache(maxsize=None)
def h4_paper_tables() -> dict:
    """Table 1 and table 3 of ``bench_identifiability.py h4``, parsed: {t1: {model: (SI, unit, weakest)},
    t3: {letter: (n_free, unit, SI, weakest)}, lines: its output lines}."""
    lines = sh(BENCH_ID_H4).stdout.splitlines()
    t1, t3 = {}, {}
    for ln in lines:
        m = re.match(r"\s+(model 12|model 31 without d|model 31 with d)\s+(\d+)\s+(\d+)\s+\d+\s+\d+\s+(.*)$", ln)
        if m:
            t1[m[1]] = (int(m[2]), int(m[3]), m[4].strip())
        m = re.match(r"\s+([A-H]) \((\d+) free\): cond\s+(\d+) unit,\s+(\d+) SI; paper\s+\d+; weakest (.*)$", ln)
        if m:
            t3[m[1]] = (int(m[2]), int(m[3]), int(m[4]), m[5].strip())
    if len(t1) != 3 or len(t3) != 8:
        raise RuntimeError(f"{BENCH_ID_H4}: unexpected output\n" + "\n".join(lines))
    return {"t1": t1, "t3": t3, "lines": lines}


@figure("h4-geometry")
def _h4_geometry() -> str:
    import yaml

    doc = yaml.safe_load((ROOT / "scenes" / "robots" / "h4.yaml").read_text())
    g, w = doc["geometry"], doc["workspace"]
    size = " x ".join(f"{1000 * s:.0f}" for s in w["size"])
    th = max(abs(t) for t in w["theta_deg"])
    return (f"`scenes/robots/h4.yaml`: R = {g['R']:.2f} m, L = {g['L']:.2f} m, l = {g['l']:.2f} m, "
            f"h = {g['h']:.2f} m, d = {g['d']:.2f} m, workspace {size} mm centred {-w['center'][2]:.2f} m below the "
            f"motors, theta in ±{th:.0f} deg.")


@figure("h4-table1")
def _h4_table1() -> str:
    t1 = h4_paper_tables()["t1"]
    rows = [[f"{m} ({T1_PARAMS[m]} parameters)", si, unit, PAPER_T1[m]] for m, (si, unit, _) in t1.items()]
    w, wo = t1["model 31 with d"], t1["model 31 without d"]
    pw, pwo = PAPER_T1["model 31 with d"], PAPER_T1["model 31 without d"]
    rows.append(["factor from adding d", f"{w[0] / wo[0]:.2f}", f"{w[1] / wo[1]:.2f}", f"{pw / pwo:.2f}"])
    return (f"`{BENCH_ID_H4}`:\n\n" + md_table(["model", "SI", "unit", "paper"], rows) +
            f"\n\nOn unit columns our model 31 without d is {wo[1] / pwo:.1f}x the paper's, and adding d multiplies the "
            f"condition number by {w[1] / wo[1]:.2f} where the paper's grows {pw / pwo:.2f}x.")


@figure("h4-table3")
def _h4_table3() -> str:
    t3 = h4_paper_tables()["t3"]
    L = "ABCDEFGH"
    rows = [["free parameters", *(t3[c][0] for c in L)], ["ours (unit)", *(t3[c][1] for c in L)],
            ["ours (SI)", *(t3[c][2] for c in L)], ["paper", *(PAPER_T3[c] for c in L)]]
    u = {c: t3[c][1] for c in L}
    return (f"`{BENCH_ID_H4}`:\n\n" + md_table(["", *L], rows) +
            f"\n\nFreeing l: B / A = {u['B'] / u['A']:.2f} here, {PAPER_T3['B'] / PAPER_T3['A']:.2f} in the paper; the "
            f"full model: H / D = {u['H'] / u['D']:.2f} here, {PAPER_T3['H'] / PAPER_T3['D']:.2f} in the paper.")


@figure("h4-weakest")
def _h4_weakest() -> str:
    t = h4_paper_tables()
    rows = [f"{m:<20} {v[2]}" for m, v in t["t1"].items()]
    rows += [f"{'variant ' + c:<20} {v[3]}" for c, v in t["t3"].items()]
    return text_block(f"$ {BENCH_ID_H4}   (the weakest direction of each row: unit columns)", *rows)


@figure("h4-geometry-sensitivity")
def _h4_geometry_sensitivity() -> str:
    lines = h4_paper_tables()["lines"]
    start = next(i for i, ln in enumerate(lines) if ln.startswith("H4 effect of d"))
    return text_block(f"$ {BENCH_ID_H4}   (last part)", *lines[start:])


@figure("identifiability-ranks")
def _identifiability_ranks() -> str:
    r = sh("python benchmarks/bench_identifiability.py")
    lines = r.stdout.splitlines()
    stop = next(i for i, ln in enumerate(lines) if ln.startswith("H4 table 1"))
    return text_block(f"$ {r.cmd}   (first part; the rest: h4_fidelity.md)", *lines[:stop])


CAMERA_AXIS_TEST = "tests/identify/test_camera_axis.py"


@figure("camera-axis-accuracy")
def _camera_axis_accuracy() -> str:
    cmd = f"python -m pytest -q -s -p no:cacheprovider {CAMERA_AXIS_TEST} -k \"restores or within_predicted\""
    p = subprocess.run([sys.executable, *shlex.split(cmd)[1:]], cwd=ROOT, env=_env(), capture_output=True,
                       text=True, timeout=600)
    if p.returncode:
        raise RuntimeError(f"{cmd}:\n{p.stdout[-3000:]}")
    m = re.search(r"5 seeds: no tilt ([\d.]+) mm, 0.5 deg tilt unmodelled ([\d.]+) mm, 0.5 deg tilt estimated "
                  r"first ([\d.]+) mm", p.stdout)
    s = re.search(r"predicted std \[([\d.]+) ([\d.]+)\] deg; mean chi2 \(2 dof\) camera ([\d.]+), target ([\d.]+)",
                  p.stdout)
    table = md_table(["true camera tilt (variant D, 81 noisy poses, 5 seeds)", "validation RMS position error"],
                     [["none", f"{m[1]} mm"], ["0.5 deg, R_BC0 left at the scene file's value", f"{m[2]} mm"],
                      ["0.5 deg, R_BC0 set from the measured axis first", f"{m[3]} mm"]])
    return (f"`{cmd}` prints\n\n{table}\n\nand, for the axis itself (81 poses, 0.03 deg rotation noise, 20 seeds): "
            f"a tilt measured to {s[1]} deg (1 sigma), mean chi-square of the errors against the predicted covariance "
            f"{s[3]} (camera) and {s[4]} (target) for 2 degrees of freedom.")


# ----------------------------------------------------------------------------------------------- demo and the H4 model error
DEMO = "vision-calib demo --out out/demo --no-plots"
UNMODELLED = "vision-calib simulate scenes/h4_unmodelled.yaml --out out/h4_unmodelled --no-plots"
UNMODELLED_SYN = "vision-calib identify-synthetic scenes/h4_unmodelled.yaml --json"
UNMODELLED_SYN_PRECISE = "vision-calib identify-synthetic scenes/h4_unmodelled.yaml --sigma-mm 0.02 --sigma-deg 0.003 --json"


@figure("demo-summary", slow=True)
def _demo_summary() -> str:
    return text_block(sh(DEMO).shown())


def _row(cmd: str, what: str) -> list:
    r = sh(cmd)
    rep = r.report() if r.out else (r.json() if r.rc in (0, 3) and r.stdout.lstrip().startswith("{") else None)
    if rep is None:
        return [f"`{cmd}` ({what})", "-", "-", "-", "-", f"error (exit {r.rc})"]
    if "sigma_mm" in rep:
        what = f"{what}, {rep['sigma_mm']:g} mm / {rep['sigma_deg']:g} deg"
    acc, ad, v = rep["accuracy"], rep.get("adequacy") or {}, rep["verdict"]
    b, a = acc["before"], acc["after"]
    outl = ", ".join(o["pose_id"] for o in rep.get("outliers") or []) or "none"
    chi = f"{ad['verdict']} ({ad['chi2_dof']:.3g})" if ad else "-"
    return [f"`{cmd}` ({what})", f"{b['position_rms_mm']:.3f} -> {a['position_rms_mm']:.3f} mm",
            f"{b['rotation_rms_deg']:.3g} -> {a['rotation_rms_deg']:.3g} deg", chi, outl,
            f"{v['status']} (exit {r.rc})"]


@figure("h4-unmodelled", slow=True)
def _h4_unmodelled() -> str:
    rows = [_row(UNMODELLED, "images"), _row(UNMODELLED_SYN, "no images"),
            _row(UNMODELLED_SYN_PRECISE, "no images"),
            _row(DEMO, "h4_vision.yaml: model shared but the tilts")]
    table = md_table(["command", "validation position RMS", "rotation RMS", "adequacy (chi2/dof)", "outlier poses",
                      "verdict"], rows, "-" * 6)
    r = sh(UNMODELLED)
    keep = [ln for ln in untimed(r.stdout) if ln.startswith(("verdict:", "validation", "H4 criteria", "method check"))]
    axis = []
    for name, run in (("h4_unmodelled", r), ("demo", sh(DEMO))):
        rep = run.report() or {}
        test = (rep.get("prepared") or {}).get("axis_test")
        if test:
            axis.append(f"{name} {test['chi2_dof']:.2f}")
    return (table + "\n\n" + text_block(r.shown(keep)) +
            ("\n\nRotation-axis test (`prepared.axis_test` of report.json), chi2/dof: " + ", ".join(axis) + "."
             if axis else ""))


# ----------------------------------------------------------------------------------------------- other commands
@figure("ur5e-synthetic")
def _ur5e_synthetic() -> str:
    return text_block(sh("vision-calib identify-synthetic scenes/ur5e_eye_in_hand.yaml").shown())


@figure("urdf-identifiability")
def _urdf_identifiability() -> str:
    r = sh("python benchmarks/bench_urdf.py")
    return text_block(r.shown([ln for ln in r.stdout.splitlines() if not ln.startswith("pose_jacobian")]))


EXAMPLE = "vision-calib process examples/rx90_eye_in_hand --out out/example --no-plots"


@figure("example-condition-number")
def _example_condition_number() -> str:
    r = sh(EXAMPLE)
    lines = r.stdout.splitlines()
    i = next(i for i, ln in enumerate(lines) if ln.startswith("identifiability:"))
    return text_block(r.shown(lines[i:i + 2]))


@figure("condition-unweighted-vs-whitened", slow=True)
def _condition_unweighted_vs_whitened() -> str:
    plan = sh("vision-calib identifiability scenes/rx90_eye_in_hand.yaml --poses 12")
    sim = sh("vision-calib simulate scenes/rx90_eye_in_hand.yaml --poses 12 --frames 2 --out out/rx90_12 "
             "--export-recording out/rx90_12_rec --no-plots")
    proc = sh("vision-calib process out/rx90_12_rec --out out/rx90_12_process --no-plots")

    def cond(run):
        m = re.search(r"condition number (\S+) \(", run.stdout)
        return m[1]
    return (f"`{plan.cmd}` prints {cond(plan)} (unweighted), and `{sim.cmd}` and `{proc.cmd}` print "
            f"{cond(sim)} and {cond(proc)} (whitened by the measured covariances)")


VISP = "../shared/data/real/visp_eye_to_hand_apriltag"


@figure("visp-real", slow=True, needs=VISP)
def _visp_real() -> str:
    imp = sh(f"vision-calib import-visp {VISP} --out out/visp")
    proc = sh("vision-calib process out/visp --out out/visp_report --no-plots")
    return text_block(imp.shown(), proc.shown())


@figure("detect-accuracy", slow=True)
def _detect_accuracy() -> str:
    r = sh("python benchmarks/bench_detect.py --targets chessboard,circles_asymmetric,modified_circle_grid "
           "--poses 8 --seeds 2 --frames 5")
    lines = []
    for ln in r.stdout.splitlines():
        if not ln.strip() or "time per frame" in ln:
            continue
        parts = ln.split("|")
        if len(parts) > 2:  # the table rows: drop the timing column
            ln = "|".join(parts[:1] + parts[2:])
        lines.append(ln)
    return text_block(r.shown(lines) + "\n(the ms/frame column left out: timings are not quoted)")


PROCESS_POSES = "vision-calib process-poses out/rx90_poses.yaml --out out/rx90_poses_report --no-plots"
PLANTED = "vision-calib process-poses out/rx90_planted.yaml --out out/rx90_planted_report --no-plots"


@figure("process-poses-example")
def _process_poses_example() -> str:
    run_python_block("measured_poses.md", '"out/rx90_poses.yaml"')
    r = sh(PROCESS_POSES)
    lines = untimed(r.stdout)
    i = next(i for i, ln in enumerate(lines) if ln.startswith("  fold 1 "))
    return text_block(r.shown(lines[:i + 1] + ["  ..."]))


@figure("process-poses-planted")
def _process_poses_planted() -> str:
    run_python_block("measured_poses.md", '"out/rx90_planted.yaml"')
    r = sh(PLANTED)
    lines = untimed(r.stdout)
    i = next(i for i, ln in enumerate(lines) if ln.startswith("held-out"))
    held = lines[i:i + 3] + [next(ln for ln in lines[i + 3:] if "1 flagged outlier" in ln)]
    return text_block(r.shown([lines[0], "...", *held, "  ..."]))


# ----------------------------------------------------------------------------------------------- studies
def study(name: str) -> Run:
    return sh(f"vision-calib study scenes/studies/{name}.yaml --out out/{name} --workers 2 --no-plots")


@figure("study-h4-pose-count", slow=True)
def _study_h4_pose_count() -> str:
    r = study("h4_pose_count")
    f = {int(m[1]): float(m[2]) for m in re.finditer(r"n_poses=(\d+): predicted std \S+, .*? predicted std x(\S+) "
                                                      r"of the first cell", r.stdout)}
    return (text_block(r.shown()) +
            f"\n\nThe predicted parameter std fall {f[6] / f[15]:.1f}x from 6 to 15 poses and {f[15] / f[71]:.1f}x "
            f"more from 15 to 71.")


@figure("study-h4-models", slow=True)
def _study_h4_models() -> str:
    r = study("h4_models")
    lines = r.stdout.splitlines()
    head = re.split(r"\s{2,}", lines[1].strip())
    rows = {c[0]: c for c in (re.split(r"\s{2,}", ln.strip()) for ln in lines[2:10])}
    v2 = head.index("V2 mrad")
    return (text_block(r.shown()) +
            f"\n\nV2 (mean ± std, mrad): variant D {rows['D'][v2]}, variant H {rows['H'][v2]}.")


@figure("study-image-spec")
def _study_image_spec() -> str:
    import yaml

    spec = yaml.safe_load((ROOT / "scenes" / "studies" / "h4_image_noise.yaml").read_text())
    sw, n = spec["sweep"], spec["repetitions"]
    cells = math.prod(len(v) for v in sw.values())
    fmt = lambda v: "[" + ", ".join(f"{x:g}" for x in v) + "]"
    (key, val), = spec["target"].items()
    return (f"(`scenes/studies/h4_image_noise.yaml`) grey noise {fmt(sw['noise_grey'])} x frames per pose "
            f"{fmt(sw['frames'])} x number of poses {fmt(sw['n_poses'])}, {n} runs per cell ({n * cells} runs), "
            f"target `{key}: {val:g}`.")


@figure("study-h4-noise", slow=True)
def _study_h4_noise() -> str:
    return text_block(study("h4_noise").shown())


# ----------------------------------------------------------------------------------------------- check / write
def blocks(text: str) -> list:
    return [(m["name"], m["body"], m.span("body")) for m in BLOCK.finditer(text)]


def pages() -> list[Path]:
    return sorted(DOCS.glob("*.md"))


def markers() -> dict[str, list[Path]]:
    """{figure name: pages that quote it}; raises on an unknown name or an unclosed block."""
    used: dict[str, list[Path]] = {}
    for p in pages():
        text = p.read_text()
        opened = [m["name"] for m in OPEN.finditer(text)]
        found = [n for n, _, _ in blocks(text)]
        if opened != found or text.count("<!-- /figures -->") != len(found):
            raise ValueError(f"{p.name}: unbalanced figure markers ({opened} opened, {found} closed properly)")
        for n in found:
            if n not in FIGURES:
                raise ValueError(f"{p.name}: unknown figure {n!r} (known: {', '.join(FIGURES)})")
            used.setdefault(n, []).append(p)
    return used


@functools.lru_cache(maxsize=None)
def generate(name: str) -> str:
    return FIGURES[name].make().strip("\n")


def same(a: str, b: str, rtol: float | None) -> bool:
    if rtol is None:
        return a.strip("\n") == b.strip("\n")
    if NUMBER.split(a) != NUMBER.split(b):
        return False
    return all(math.isclose(float(x), float(y), rel_tol=rtol) for x, y in zip(NUMBER.findall(a), NUMBER.findall(b)))


def available(name: str) -> bool:
    need = FIGURES[name].needs
    return need is None or (ROOT / need).exists()


def check(name: str) -> list[str]:
    """Problems of figure NAME in every page that quotes it: [] when current."""
    problems = []
    for p in markers().get(name, []):
        for n, body, _ in blocks(p.read_text()):
            if n != name:
                continue
            new = generate(name)
            if not same(body, new, FIGURES[name].rtol):
                diff = difflib.unified_diff(body.strip("\n").splitlines(), new.splitlines(), "in the page",
                                            "generated now", lineterm="", n=0)
                problems.append(f"{p.relative_to(ROOT)}: block {name!r} is stale "
                                f"(python docs/figures.py {name} rewrites it)\n" + "\n".join(list(diff)[:40]))
    return problems


def write(names: list[str]) -> list[Path]:
    changed = []
    for p in pages():
        text = p.read_text()
        parts, last = [], 0
        for n, body, (a, b) in blocks(text):
            if n in names:
                parts += [text[last:a], generate(n) + "\n"]
                last = b
        new = "".join(parts) + text[last:]
        if new != text:
            p.write_text(new)
            changed.append(p)
    return changed


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("names", nargs="*", help="figures to check or write (default: all)")
    ap.add_argument("--check", action="store_true", help="compare, write nothing; exit 1 if a block is stale")
    ap.add_argument("--fast", action="store_true", help="leave out the slow figures")
    ap.add_argument("--list", action="store_true", help="list the figures and the pages quoting them")
    a = ap.parse_args(argv)
    used = markers()
    if a.list:
        for n, f in FIGURES.items():
            print(f"{n:<36} {'slow' if f.slow else '    '}  {', '.join(p.name for p in used.get(n, [])) or '(unused)'}")
        return 0
    unknown = [n for n in a.names if n not in FIGURES]
    if unknown:
        ap.error(f"unknown figures: {', '.join(unknown)}")
    unused = [n for n in FIGURES if n not in used]
    names = [n for n in (a.names or FIGURES) if not (a.fast and FIGURES[n].slow)]
    skipped = [n for n in names if not available(n)]
    names = [n for n in names if n not in skipped]
    for n in skipped:
        print(f"skipped {n}: {FIGURES[n].needs} not here", file=sys.stderr)
    if not a.check:
        for p in write(names):
            print(f"wrote {p.relative_to(ROOT)}")
        return 0
    problems = [f"figure {n!r} is quoted by no page" for n in unused if not a.names]
    for n in names:
        problems += check(n)
    for pr in problems:
        print(pr, file=sys.stderr)
    print(f"{len(names)} figures checked, {len(problems)} problems", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
