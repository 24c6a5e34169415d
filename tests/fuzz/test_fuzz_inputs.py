"""The commands on bad inputs beyond a damaged recording (tests/fuzz/fuzz_inputs.py, issue 21): a named error
(exit 2 or 3, the message matching the case's pattern, no traceback, no numpy warning), or exit 0 with the
case's check holding (a warning on stderr where the case expects one). Outcomes join the fuzz tally."""

from __future__ import annotations

import re

import pytest
from fuzz_damage import TALLY
from fuzz_inputs import CASES, context

from vision_calib.cli import main

pytestmark = pytest.mark.slow


@pytest.fixture(scope="session")
def ctx(recording):
    return context(recording[0])


@pytest.mark.parametrize("build,expect,pattern", [pytest.param(b, e, p, id=c) for c, b, e, p in CASES])
def test_bad_input(ctx, tmp_path, capsys, request, build, expect, pattern):
    case = request.node.callspec.id
    TALLY[case] = "crash"
    argv, check = build(tmp_path, ctx)
    code = main(argv)
    err = capsys.readouterr().err
    assert "Warning" not in err and "Traceback" not in err, err  # no numpy warning, no traceback reaches the user
    if code == 0:
        ok = check is None or check(tmp_path)
        TALLY[case] = ("warned" if expect == "warned" else "correct") if ok else "silent_wrong"
        assert ok, f"exit 0 but the check of {case} fails: {err.strip()}"
        assert expect != "error", f"expected an error matching {pattern!r}, got exit 0"
        if expect == "warned":
            assert re.search(pattern, err), f"no warning matching {pattern!r}: {err.strip()}"
        return
    TALLY[case] = "named_error" if code in (2, 3) else "other_exit"
    assert code in (2, 3), err
    assert expect == "error", f"expected {expect}, got exit {code}: {err.strip()}"
    if not re.search(pattern, err):
        TALLY[case] = "unnamed_error"
    assert re.search(pattern, err), f"message does not match {pattern!r}: {err.strip()}"
    if check is not None:  # a failure keeps its report and writes no calibrated model
        assert check(tmp_path), f"{case}: the failed run must keep report.json and write no calibrated model"
