"""Image chain plumbing: the worker pool is reused, workers die with the main process (kill -9), and the
main process of a simulation never imports torch."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

_CHILD = r"""
import sys, time
from vision_calib.experiment.image_chain import ImageChain, ImagePool, worker_pid
from vision_calib.rig import load_scene
from vision_calib.experiment.simulate import image_chain_of
scene = load_scene("scenes/h4_vision.yaml")
chain = image_chain_of(scene)
pool = ImagePool(chain, workers=2)
pids = set(pool.map(worker_pid, range(8)))
print(" ".join(map(str, sorted(pids))), flush=True)
print("torch" in sys.modules, flush=True)
time.sleep(600)
"""


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie (exited, not yet reaped by its parent) counts as dead
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux-only")
def test_workers_die_with_killed_parent_and_no_torch_in_main():
    p = subprocess.Popen([sys.executable, "-c", _CHILD], cwd=ROOT, stdout=subprocess.PIPE, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        pids = [int(x) for x in p.stdout.readline().split()]
        torch_in_main = p.stdout.readline().strip()
        assert len(pids) >= 1 and all(_alive(q) for q in pids)
        assert torch_in_main == "False"
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait()
    deadline = time.time() + 20
    while time.time() < deadline and any(_alive(q) for q in pids):
        time.sleep(0.2)
    assert not any(_alive(q) for q in pids), [q for q in pids if _alive(q)]
