"""Report plots drawn in two processes (report.plots.draw_all): every file written, a failure surfaces."""

import numpy as np
import pytest

from vision_calib.report.plots import draw_all, plot_error_map, plot_parameters, plot_residuals


def test_draw_all_writes_every_plot(tmp_path):
    rng = np.random.default_rng(0)
    jobs = [(plot_residuals, (tmp_path / "r.png", rng.normal(size=(30, 4)), rng.normal(size=(30, 4)) * 0.01,
                              "joint")),
            (plot_parameters, (tmp_path / "p.png", ["a", "b"], np.zeros(2), np.ones(2) * 1e-3, np.ones(2) * 1e-4)),
            (plot_error_map, (tmp_path / "e.png", rng.normal(size=(20, 3)), rng.random(20), rng.random(20)))]
    draw_all(jobs)
    for name in ("r.png", "p.png", "e.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*tmp*"))  # atomic writes left no temporaries


def test_a_failing_plot_raises_in_the_caller(tmp_path):
    """The first job runs in the forked child: its failure is not lost, it is drawn again (and raises) here."""
    def bad(path):
        raise ValueError(f"cannot draw {path}")

    ok = []
    with pytest.raises(ValueError, match="cannot draw"):
        draw_all([(bad, (tmp_path / "x.png",)), (lambda: ok.append(1), ())])
    assert ok == [1]
