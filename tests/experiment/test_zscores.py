"""Reported std you can trust, on data the model does not share: image-mode runs of the H4 demo scene over
5 seeds (render -> detect -> PnP -> identify), z = (identified - true) / reported std."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from bench_zscores import zscores  # noqa: E402

pytestmark = pytest.mark.slow


def test_image_mode_z_scores_over_five_seeds():
    res = zscores("scenes/h4_vision.yaml", [1, 2, 3, 4, 5])
    Z = np.array([z for _, z, _, _ in res.values()])
    assert Z.shape == (5, 19)
    assert 0.7 < np.sqrt(np.mean(Z**2)) < 1.5 and np.max(np.abs(Z)) < 4, Z
    # the per-pose covariances now hold the systematic part: chi2/dof near 1, not ~40 as with the frame
    # scatter alone (so the variance factor no longer has to inflate the std)
    assert all(0.5 < c < 2.0 for _, _, c, _ in res.values())
    # known gap (README): h4.h stays about -3.5 std off in every seed (a depth bias common to all poses,
    # correlated across poses, is not in the per-pose covariances); this checks it does not grow past 4
    names = res[1][0]
    assert np.max(np.abs(Z[:, names.index("h4.h")])) < 4
