"""FCL is an optional extra ([plan]): without it the package imports and plans the H4 (no collision model), and an
arm's plan stops with a one-line error naming the extra (exit 2)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from blocked_imports import run_blocked  # noqa: E402


def test_plan_without_fcl(tmp_path):
    r = run_blocked(tmp_path, """
        import sys
        from vision_calib.cli import main
        import vision_calib.planning.plan, vision_calib.planning.collision  # import without fcl
        assert main(["plan", "scenes/h4_vision.yaml", "--poses", "6", "--out", "h4", "--candidates", "300",
                     "--draws", "1", "--no-plots"]) == 0
        sys.exit(main(["plan", "scenes/ur5e_cell.yaml", "--poses", "6", "--out", "ur", "--candidates", "300"]))
    """, blocked=("fcl",))
    assert r.returncode == 2, r.stderr
    assert "vision_calib[plan]" in r.stderr and "Traceback" not in r.stderr
