"""The CLI on hostile files and runaway work (tests/fuzz/fuzz_hostile.py, issue 28), each case in a child process
bounded in memory and time, a watched folder outside its inputs: a named error or the expected result -- never a
traceback, a hang, an outside access or a runaway. Outcomes join the fuzz tally (``pytest tests/fuzz -rA``)."""

from __future__ import annotations

import os
import re
import resource
import signal
import subprocess
import sys

import pytest
from fuzz_damage import TALLY
from fuzz_hostile import CASES, MEMORY_LIMIT, Watch
from fuzz_inputs import REPO, context

pytestmark = pytest.mark.slow

_MAIN = "import sys\n{prelude}\nfrom vision_calib.cli import main\nsys.exit(main(sys.argv[1:]))\n"
_MEMORY_SIGNS = ("out of memory", "MemoryError", "Insufficient memory", "Failed to allocate", "std::bad_alloc",
                 "Cannot allocate memory")


def _limit():  # in the child, before exec: its data segment bounded
    resource.setrlimit(resource.RLIMIT_DATA, (MEMORY_LIMIT, MEMORY_LIMIT))


def run_hostile(case, argv, tmp):
    """(outcome or None when the child ended normally, exit code, stdout, stderr, files opened in tmp/outside)."""
    watch = Watch(tmp / "outside")
    env = dict(os.environ, PYTHONPATH=str(REPO), **case.env)
    p = subprocess.Popen([sys.executable, "-c", _MAIN.format(prelude=case.prelude), *map(str, argv)], cwd=REPO,
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=_limit, start_new_session=True)
    try:
        out, err = p.communicate(timeout=case.timeout)
        timed_out = False
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)  # the child's own session: it and what it started
        out, err = p.communicate()
        timed_out = True
    opened = watch.opened()
    watch.close()
    outcome = None
    if timed_out:
        outcome = case.on_timeout
    elif any(s in err for s in _MEMORY_SIGNS) or p.returncode < 0:
        outcome = "runaway"
    elif "Traceback" in err:
        outcome = "traceback"
    elif opened:
        outcome = "outside_access"
    return outcome, p.returncode, out, err, opened


@pytest.fixture(scope="session")
def hostile_ctx(recording):
    """fuzz_inputs.context plus ``scheduler()``: a local Dask scheduler without workers (127.0.0.1, started once
    on first use, shut down at the end of the session): (address, its scheduler file)."""
    ctx = context(recording[0])
    state = {}

    def scheduler():
        if "cluster" not in state:
            import tempfile

            from distributed import LocalCluster

            state["dir"] = tempfile.mkdtemp(prefix="hostile_sched")
            state["file"] = os.path.join(state["dir"], "scheduler.json")
            state["cluster"] = LocalCluster(n_workers=0, scheduler_port=0, host="127.0.0.1", dashboard_address=None,
                                            processes=False, protocol="tcp",
                                            scheduler_kwargs={"scheduler_file": state["file"]})
        return state["cluster"].scheduler_address, state["file"]

    ctx["scheduler"] = scheduler
    yield ctx
    if "cluster" in state:
        state["cluster"].close()
        import shutil

        shutil.rmtree(state["dir"], ignore_errors=True)


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in CASES])
def test_hostile(hostile_ctx, tmp_path, case):
    TALLY[case.id] = "crash"
    (tmp_path / "outside").mkdir()
    argv, check = case.build(tmp_path, hostile_ctx)
    outcome, code, out, err, opened = run_hostile(case, argv, tmp_path)
    if outcome is not None:
        TALLY[case.id] = outcome
        pytest.fail(f"{outcome} (exit {code}{', time limit ' + str(case.timeout) + ' s' if code == -9 else ''}; opened "
                    f"outside: {opened}): {err[-3000:]}")
    if code == 0:
        ok = check is None or check(tmp_path)
        if case.expect == "error" or not ok:
            TALLY[case.id] = "silent_wrong"
            pytest.fail(f"exit 0 {'but the check fails' if not ok else f'where an error matching {case.pattern!r} was expected'}: "
                        f"{err[-2000:]}")
        if case.expect == "warned" and not re.search(case.pattern, out + err):
            TALLY[case.id] = "unnamed_warning"  # right result, the skipped input not named as it should be
            pytest.fail(f"no warning matching {case.pattern!r}: {out[-2000:]} {err[-2000:]}")
        TALLY[case.id] = case.expect
        return
    if code not in (2, 3):
        TALLY[case.id] = "other_exit"
        pytest.fail(f"exit {code}: {err[-2000:]}")
    if case.expect != "error":
        TALLY[case.id] = "unexpected_error"
        pytest.fail(f"expected {case.expect}, got exit {code}: {err[-2000:]}")
    if not re.search(case.pattern, err):
        TALLY[case.id] = "unnamed_error"
        pytest.fail(f"message does not match {case.pattern!r}: {err[-2000:]}")
    TALLY[case.id] = "named_error"
    if check is not None:
        assert check(tmp_path), f"{case.id}: the check of the failed run fails"
