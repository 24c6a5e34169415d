"""Images-mode studies at scale: one execution model (the image chain runs in the study worker itself, never in a
nested pool), for real -- a local ``--workers 2`` study in a subprocess, Ctrl-C then resume, a Dask
``LocalCluster(processes=True)`` (daemonic workers, as ``dask worker`` has) -- each giving the rows of
``--workers 1`` (timings aside) and leaving no process behind (checked by process group); an error in the main
process stops the local workers at once; the in-thread image chain gives the process pool's numbers."""

import json
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from vision_calib import study as S

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "h4_vision.yaml"
HANG_GUARD_S = 600  # only against a hang: these runs take seconds
pytestmark = [pytest.mark.slow, pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc, setsid")]


def _env():
    return {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


def _run_in_own_group(args: list) -> tuple:
    """(Popen, stdout, stderr) of ``python ARGS`` run to its end in a new process group (killed whole on a hang)."""
    p = subprocess.Popen([sys.executable, *args], cwd=ROOT, env=_env(), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = p.communicate(timeout=HANG_GUARD_S)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    return p, out, err


def write_spec(tmp_path, repetitions=2, name="img"):
    """2 noise levels x ``repetitions`` images-mode runs of 8 poses x 2 frames (+ the scene's validation poses)."""
    p = tmp_path / f"{name}_r{repetitions}.yaml"
    p.write_text(yaml.safe_dump({
        "name": name, "scene": str(SCENE), "mode": "images", "repetitions": repetitions, "seed": 3,
        "settings": {"n_poses": 8, "frames": 2}, "sweep": {"noise_grey": [1.0, 6.0]},
        "outputs": ["accuracy", "criteria", "condition", "parameters"]}, sort_keys=False))
    return p


def rows(out) -> dict:
    return {p.stem: json.loads(p.read_text())["row"] for p in sorted((Path(out) / "runs").glob("*.json"))}


def assert_same_rows(a: dict, b: dict):
    """Same runs, same values (bit for bit: a run is a pure function of spec, cell, seed) but ``seconds``."""
    assert sorted(a) == sorted(b)
    for k in a:
        ra, rb = dict(a[k]), dict(b[k])
        ra.pop("seconds"), rb.pop("seconds")
        assert ra == rb or json.dumps(ra, sort_keys=True) == json.dumps(rb, sort_keys=True), k


def group_members(pgid: int) -> list[str]:
    """Live (non-zombie) processes of process group ``pgid``: 'pid cmdline'."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text().rsplit(")", 1)[1].split()
            if int(stat[2]) == pgid and stat[0] != "Z":
                out.append(f"{d.name} {(d / 'cmdline').read_bytes().replace(bytes(1), b' ').decode()[:120]}")
        except (OSError, IndexError, ValueError):
            continue
    return out


def assert_group_gone(pgid: int, grace_s: float = 10.0):
    deadline = time.time() + grace_s
    while group_members(pgid) and time.time() < deadline:
        time.sleep(0.2)
    assert not group_members(pgid), group_members(pgid)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The ``--workers 1`` study (this process, the chain in this thread): (spec path, rows)."""
    tmp = tmp_path_factory.mktemp("ref")
    spec = write_spec(tmp)
    res = S.run_study(spec, tmp / "w1", workers=1, plots=False)
    assert res["n_failed"] == 0 and res["n_computed"] == 4
    r = rows(tmp / "w1")
    # the runs are real: the noise axis is applied (common random numbers: same seed, other numbers)
    lo, hi = r["noise_grey=1,rep=0000"], r["noise_grey=6,rep=0000"]
    assert lo["seed"] == hi["seed"] and lo["err:h4.L"] != hi["err:h4.L"]
    assert all(np.isfinite(x["after_V1_rad"]) and np.isfinite(x["after_position_rms_mm"]) for x in r.values())
    return spec, r


def test_local_two_workers_subprocess(reference, tmp_path):
    """``vision-calib study --workers 2``: exits, same rows, no leaked semaphore, no process left in its group."""
    spec, ref = reference
    p, out, err = _run_in_own_group(["-m", "vision_calib.cli", "study", str(spec), "--out", str(tmp_path / "w2"),
                                     "--workers", "2", "--no-plots", "--json"])
    assert p.returncode == 0, err
    assert json.loads(out)["n_computed"] == 4
    assert "leaked" not in err, err
    assert_group_gone(p.pid)
    assert_same_rows(ref, rows(tmp_path / "w2"))


# The interrupted study's entry point: ``vision-calib study`` with every run but the first held at a gate (a file the
# test removes only after the signal). Spawned study workers import this file as ``__mp_main__`` before their first
# task, so the module-level wrapper is in force there too; a held run first marks its worker as parked.
_GATED_STUDY = r"""
import os, sys, time
from pathlib import Path
from vision_calib.study import run as R

GATE = Path(os.environ["VC_TEST_GATE"])
_run_cell = R.run_cell


def _gated_run_cell(spec, cell, rep):
    if (cell, rep) != (R.study_cells(spec)[0], 0):  # the plan's first run goes through, every other one waits
        (GATE.parent / f"parked_{os.getpid()}").touch()
        while GATE.exists():
            time.sleep(0.05)
    return _run_cell(spec, cell, rep)


R.run_cell = _gated_run_cell

if __name__ == "__main__":
    from vision_calib.cli import run

    run()
"""


def test_ctrl_c_stops_promptly_then_resume_is_exact(reference, tmp_path):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) during a ``--workers 2`` images study:
    exit 130 within seconds, nothing left behind; the study then resumes from runs/ and every row equals the
    uninterrupted ``--workers 1`` one. The signal arrives at a known point, not raced against the study's end: the
    first run has been written and both workers are parked inside a run that cannot end before the signal."""
    spec, ref = reference
    spec8 = write_spec(tmp_path, repetitions=4)  # same hash as the reference (repetitions only select runs)
    out = tmp_path / "int"
    gate_dir = tmp_path / "gate"
    gate_dir.mkdir()
    gate = gate_dir / "closed"
    gate.touch()
    script = tmp_path / "gated_study.py"
    script.write_text(_GATED_STUDY)
    # SIGINT as a terminal delivers it: a test runner started in the background (``cmd &`` in a script) hands its
    # children SIGINT *ignored*, and Python then installs no KeyboardInterrupt handler: restore the default first
    p = subprocess.Popen([sys.executable, str(script), "study", str(spec8), "--out", str(out), "--workers", "2",
                          "--no-plots", "--json"], cwd=ROOT, env={**_env(), "VC_TEST_GATE": str(gate)},
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.time() + HANG_GUARD_S
        while p.poll() is None and time.time() < deadline and not (
                list((out / "runs").glob("*.json")) and len(list(gate_dir.glob("parked_*"))) == 2):
            time.sleep(0.1)
        assert p.poll() is None, p.communicate()
        assert len(list(gate_dir.glob("parked_*"))) == 2, "the two workers never parked at the gate"
        os.killpg(p.pid, signal.SIGINT)
        t0 = time.time()
        _, err = p.communicate(timeout=HANG_GUARD_S)
        stop_s = time.time() - t0
    finally:
        gate.unlink(missing_ok=True)
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    assert p.returncode == 130, err
    assert "interrupted" in err
    # the runs in flight are stopped, not waited for (they would wait for the gate: the hang guard); generous bound
    # for a loaded machine
    assert stop_s < 30, stop_s
    assert_group_gone(p.pid)
    done = len(list((out / "runs").glob("*.json")))
    assert done == 1  # the first run; the other seven were held
    res = S.run_study(spec8, out, workers=2, plots=False)
    assert (res["n_reused"], res["n_computed"], res["n_failed"]) == (done, 8 - done, 0)
    resumed = rows(out)
    assert len(resumed) == 8
    assert_same_rows(ref, {k: v for k, v in resumed.items() if v["repetition"] < 2})
    assert not mp.active_children()


_DASK = r"""
import json, multiprocessing as mp, sys
from distributed import Client, LocalCluster
from vision_calib.study import run_study
if __name__ == "__main__":
    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        daemonic = sorted(client.run(lambda: mp.current_process().daemon).values())
        res = run_study(sys.argv[1], sys.argv[2], scheduler=client, plots=False)
        children = sorted(client.run(lambda: len(mp.active_children())).values())
    print(json.dumps({"daemonic": daemonic, "n_computed": res["n_computed"], "children": children}))
"""


def test_dask_local_cluster_processes(reference, tmp_path):
    """A LocalCluster of 2 worker processes (daemonic, may not have children): same rows, workers without
    children after the study, nothing left in the process group once the client and cluster are closed."""
    spec, ref = reference
    p, out, err = _run_in_own_group(["-c", _DASK, str(spec), str(tmp_path / "dask")])
    assert p.returncode == 0, err
    info = json.loads(out.strip().splitlines()[-1])
    assert info == {"daemonic": [True, True], "n_computed": 4, "children": [0, 0]}, info
    assert "daemonic processes are not allowed" not in err
    assert_group_gone(p.pid)
    assert_same_rows(ref, rows(tmp_path / "dask"))


def test_error_in_main_stops_local_workers(reference, tmp_path, monkeypatch):
    """An error in this process while local workers run (here: writing a run's file fails) propagates, and the
    workers are stopped and joined before run_study returns."""
    from vision_calib.study import run as R

    spec, _ = reference
    calls = []

    def fail(path, data):
        calls.append(path)
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(R, "write_json_atomic", fail)
    with pytest.raises(OSError, match="No space left"):
        S.run_study(spec, tmp_path / "err", workers=2, plots=False)
    assert len(calls) == 1 and not mp.active_children()


def test_inline_chain_equals_process_pool():
    """The chain in this thread (InlineImagePool, validation poses measured after the identification) gives the
    numbers of ``simulate``'s process pool (validation poses measured beside the identification)."""
    from vision_calib.experiment.image_chain import InlineImagePool
    from vision_calib.experiment.simulate import image_chain_of, run_simulation
    from vision_calib.rig import load_scene

    scene = load_scene(SCENE)
    a = run_simulation(scene, seed=11, n_poses=8, frames=2, workers=2, reference=False)
    with InlineImagePool(image_chain_of(scene)) as pool:
        b = run_simulation(scene, seed=11, n_poses=8, frames=2, pool=pool, reference=False)
    assert "synthetic_reference" not in a and "validation_measurements" in b
    a["identification"].pop("seconds"), b["identification"].pop("seconds")
    for k in ("parameters", "accuracy", "identification", "validation_measurements", "measurements"):
        assert json.dumps(a[k], sort_keys=True, default=str) == json.dumps(b[k], sort_keys=True, default=str), k
