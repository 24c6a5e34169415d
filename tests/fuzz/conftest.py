"""Fuzz suite fixtures: one small recorded folder per session, built with the CLI from a shipped
scene, and the report of its undamaged processing (the reference of every damage case); the bad-input
cases of the other commands (fuzz_inputs.py) share it.

The tally of outcomes (named errors, correct results, silent wrong results that are xfail) is
printed at the end of the run (``pytest tests/fuzz -q -rA``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCENE = REPO / "scenes" / "rx90_eye_in_hand.yaml"
N_POSES = 10
FRAMES = 2

from fuzz_damage import TALLY  # noqa: E402  (tests/fuzz is on sys.path: pytest's rootdir-relative imports)


def run_cli(*args, timeout=600):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "vision_calib.cli", *map(str, args)], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="session")
def recording(tmp_path_factory):
    """(recorded folder, reference report dict) of the undamaged run; the folder must not be modified."""
    d = tmp_path_factory.mktemp("fuzz")
    r = run_cli("simulate", SCENE, "--poses", N_POSES, "--frames", FRAMES, "--seed", 3, "--workers", 2,
                "--out", d / "sim", "--export-recording", d / "rec", "--json")
    assert r.returncode == 0, r.stderr[-2000:]
    r = run_cli("process", d / "rec", "--out", d / "ref", "--json")
    assert r.returncode == 0, r.stderr[-2000:]
    return d / "rec", json.loads((d / "ref" / "report.json").read_text())


def pytest_terminal_summary(terminalreporter):
    if not TALLY:
        return
    counts: dict[str, int] = {}
    for outcome in TALLY.values():
        counts[outcome] = counts.get(outcome, 0) + 1
    tr = terminalreporter
    tr.section("fuzz tally (vision-calib on damaged recordings and bad inputs)")
    tr.write_line(f"cases: {len(TALLY)}; " + ", ".join(f"{k}: {v}" for k, v in sorted(counts.items())))
    for case, outcome in sorted(TALLY.items()):
        if outcome not in ("named_error", "correct", "warned"):
            tr.write_line(f"  {outcome}: {case}")
