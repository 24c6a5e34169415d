"""Studies that cannot start, or should not (study/run.py, study/budget.py; issue 28): a Dask scheduler file is
read for its address; a scheduler that cannot be reached, or has no worker, is named within seconds; a study or a
pose count whose estimated time / memory / run files exceed the machine stops with the estimate unless --yes (or
the study file's max_hours) allows it. The Dask schedulers here are local (127.0.0.1), without workers, shut
down by the test."""

from __future__ import annotations

import importlib
import json
import time

import pytest
import yaml

from vision_calib.cli import main
from vision_calib.errors import ConfigError
from vision_calib.study import budget as B
from vision_calib.study import run_study
from vision_calib.study.spec import load_study

R = importlib.import_module("vision_calib.study.run")
ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def _spec(tmp_path, reps=1, **kw):
    d = {"name": "s", "scene": str(ROOT / "scenes" / "h4_vision.yaml"), "repetitions": reps, "seed": 1,
         "sweep": {"n_poses": [12]}, **kw}
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump(d, sort_keys=False))
    return p


@pytest.fixture(scope="module")
def idle_scheduler(tmp_path_factory):
    """(address, scheduler file) of a local Dask scheduler with no worker."""
    distributed = pytest.importorskip("distributed")
    f = tmp_path_factory.mktemp("sched") / "scheduler.json"
    cluster = distributed.LocalCluster(n_workers=0, scheduler_port=0, host="127.0.0.1", dashboard_address=None,
                                       processes=False, protocol="tcp", scheduler_kwargs={"scheduler_file": str(f)})
    try:
        yield cluster.scheduler_address, f
    finally:
        cluster.close()


def test_scheduler_file_gives_the_address(idle_scheduler, tmp_path):
    addr, f = idle_scheduler
    assert R.scheduler_address(str(f)) == (addr, str(f))
    assert R.scheduler_address("tcp://10.0.0.5:8786") == ("tcp://10.0.0.5:8786", None)
    (tmp_path / "x.json").write_text("not json\n")
    with pytest.raises(ConfigError, match=r"x.json: not a Dask scheduler file .*Expecting value"):
        R.scheduler_address(str(tmp_path / "x.json"))
    (tmp_path / "y.json").write_text(json.dumps({"type": "Scheduler", "services": {}}))
    with pytest.raises(ConfigError, match=r"y.json: not a Dask scheduler file .*no 'address'"):
        R.scheduler_address(str(tmp_path / "y.json"))


def test_cli_refuses_a_file_that_is_not_a_scheduler_file(tmp_path, capsys):
    (tmp_path / "x.json").write_text("{}")
    with pytest.raises(SystemExit) as exc:
        main(["study", str(_spec(tmp_path)), "--out", str(tmp_path / "o"), "--scheduler", str(tmp_path / "x.json")])
    assert exc.value.code == 2 and "x.json: not a Dask scheduler file" in capsys.readouterr().err


@pytest.mark.parametrize("via_file", [False, True])
def test_a_scheduler_without_workers_is_named_within_seconds(idle_scheduler, tmp_path, monkeypatch, via_file):
    addr, f = idle_scheduler
    monkeypatch.setattr(R, "WORKER_WAIT_S", 1.0)
    t = time.perf_counter()
    with pytest.raises(ConfigError, match=rf"Dask scheduler {addr}" + (r" \(from .*scheduler.json\)" if via_file else "")
                       + r": no worker connected within 1 s: start workers \(`dask worker tcp://127.0.0.1"):
        run_study(_spec(tmp_path), tmp_path / "out", scheduler=str(f) if via_file else addr, plots=False)
    assert time.perf_counter() - t < 8
    assert not (tmp_path / "out" / "runs").exists()  # nothing started


def test_an_unreachable_scheduler_is_named(tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr(R, "CONNECT_TIMEOUT_S", 1.0)
    (tmp_path / "dead.json").write_text(json.dumps({"address": "tcp://127.0.0.1:9"}))
    with pytest.raises(ConfigError, match=r"Dask scheduler tcp://127.0.0.1:9 \(from .*dead.json\): cannot connect "
                                          r"within 1 s"):
        run_study(_spec(tmp_path), tmp_path / "out", scheduler=str(tmp_path / "dead.json"), plots=False)


def test_a_study_beyond_the_machine_stops_with_its_estimate(tmp_path, monkeypatch):
    monkeypatch.setattr(B, "CONFIRM_HOURS", 0.01)  # 36 s: 1000 runs of ~0.16 s on 2 workers exceed it
    p = _spec(tmp_path, reps=1000)
    with pytest.raises(ConfigError, match=r"s.yaml: 1000 runs: estimated 0.0\d+ h on 2 workers .*of run files .*"
                                          r"more than 0.01 h: give --yes"):
        run_study(p, tmp_path / "out", workers=2, plots=False)
    assert not (tmp_path / "out" / "runs").exists()
    est = B.check_study(load_study(p), 1000, 2, tmp_path / "out", yes=True)
    assert est["seconds"] == pytest.approx(1000 * (B.STUDY_RUN_S + 12 * B.STUDY_S_PER_POSE) / 2)
    assert est["disk_bytes"] == 1000 * B.RUN_FILE_BYTES
    # the study file's bound: a longer one lets it run, a shorter one names it
    B.check_study(load_study(_spec(tmp_path, reps=1000, max_hours=1)), 1000, 2, tmp_path / "out")
    with pytest.raises(ConfigError, match=r"more than the study file's max_hours: 0.001"):
        B.check_study(load_study(_spec(tmp_path, reps=1000, max_hours=0.001)), 1000, 2, tmp_path / "out")
    with pytest.raises(ConfigError, match=r"max_hours: expected a value > 0.0 h"):
        load_study(_spec(tmp_path, max_hours=0))


def test_memory_and_disk_beyond_the_machine(tmp_path, monkeypatch):
    from vision_calib import config

    monkeypatch.setattr(config, "machine_memory_bytes", lambda: 8 * 10**9)
    spec = load_study(_spec(tmp_path, max_hours=1e9))
    with pytest.raises(ConfigError, match=r"more than 50% of this machine's 8 GB of memory"):
        B.check_study(spec, 10**6, 1, tmp_path)
    monkeypatch.setattr(B, "RUN_FILE_BYTES", 1e15)
    with pytest.raises(ConfigError, match=r"more than the .* free on the disk of"):
        B.check_study(spec, 10, 1, tmp_path)


def test_pose_counts_beyond_the_machine(capsys):
    with pytest.raises(ConfigError, match=r"identify-synthetic --poses 100000000: estimated 2.8e\+03 GB of memory "
                                          r"and 97.2 h \(28 kB and 3.5 ms per pose"):
        B.check_pose_count("identify-synthetic", 10**8)
    assert B.check_pose_count("identify-synthetic", 10**8, yes=True)["bytes"] > 1e12
    assert B.check_pose_count("identifiability", 1000)["seconds"] < 2
    assert B.check_pose_count("identify-synthetic", None) == {}
    with pytest.raises(ConfigError, match=r"simulate --poses 1000000: .* \(28 kB and 34 ms per pose of 2 frames on 2 "
                                          r"workers"):
        B.check_pose_count("simulate", 10**6, frames=2, workers=2)
    assert main(["identifiability", str(ROOT / "scenes" / "rx90_eye_in_hand.yaml"), "--poses", "100000000"]) == 2
    assert "give --yes to run it anyway, or fewer poses" in capsys.readouterr().err
