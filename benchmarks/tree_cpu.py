"""Wall time and CPU seconds of a command's whole process tree (the CLI's fork server and image workers
are not reaped by the CLI, so ``time`` misses them): polls /proc every 20 ms (Linux).

    .venv/bin/python benchmarks/tree_cpu.py .venv/bin/vision-calib demo --out /tmp/demo
"""

from __future__ import annotations

import os
import subprocess
import sys
import time


def _snapshot() -> dict:
    """{pid: (parent pid, CPU seconds)} of every process now."""
    tck = os.sysconf("SC_CLK_TCK")
    out = {}
    for p in os.listdir("/proc"):
        if p.isdigit():
            try:
                with open(f"/proc/{p}/stat") as f:
                    s = f.read().rsplit(")", 1)[1].split()
                out[int(p)] = (int(s[1]), (int(s[11]) + int(s[12])) / tck)
            except OSError:
                pass
    return out


def main(cmd: list[str]) -> None:
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    tree, cpu = {proc.pid}, {}
    while proc.poll() is None:
        snap = _snapshot()
        grown = True
        while grown:
            grown = False
            for pid, (parent, _) in snap.items():
                if pid not in tree and parent in tree:
                    tree.add(pid)
                    grown = True
        cpu.update({pid: snap[pid][1] for pid in tree if pid in snap})
        time.sleep(0.02)
    wall = time.perf_counter() - t0
    print(f"rc {proc.returncode}; wall {wall:.2f} s; CPU {sum(cpu.values()):.2f} s over {len(cpu)} processes "
          f"(largest: {', '.join(f'{c:.2f}' for c in sorted(cpu.values(), reverse=True)[:4])} s); "
          f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main(sys.argv[1:])
