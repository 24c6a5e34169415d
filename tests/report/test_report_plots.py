"""What the report plots draw (report/plots.py), read back from the matplotlib figures: each error-map panel on its
own labelled colour scale spanning its own errors, one parameter axis per unit (and z-scores against the truth),
residual histograms with labelled axes and a rotation row."""

import numpy as np
import pytest

from vision_calib.report import plots


@pytest.fixture
def figures(monkeypatch):
    """The figures the plot functions would save, kept open for inspection."""
    kept = []

    def keep(fig, path):
        kept.append(fig)
        return path

    monkeypatch.setattr(plots, "_save", keep)
    yield kept
    import matplotlib.pyplot as plt

    plt.close("all")


def test_error_map_panels_each_span_their_own_errors(figures, tmp_path):
    rng = np.random.default_rng(1)
    before, after = 1.0 + rng.random(25), 0.08 + 0.01 * rng.random(25)  # after: 100x smaller, 1 % spread
    plots.plot_error_map(tmp_path / "e.png", rng.normal(size=(25, 3)) * 0.1, before, after)
    fig = figures[0]
    panels = [a for a in fig.axes if a.collections and a.get_xlabel() == "x [mm]"]
    bars = [a for a in fig.axes if a not in panels]
    assert len(panels) == 2 and len(bars) == 2
    for a, e, name in zip(panels, (before, after), ("nominal", "identified")):
        sc = a.collections[0]
        assert sc.get_clim() == pytest.approx((e.min(), e.max()))
        colours = sc.to_rgba(e)  # the identified panel is not one flat colour: its colours span the colour map
        assert np.ptp(colours[:, :3], axis=0).max() > 0.5
    assert [b.get_ylabel() for b in bars] == ["position error, nominal [mm]", "position error, identified [mm]"]


def test_parameters_one_axis_per_unit_and_z_scores(figures, tmp_path):
    names = ["a1", "d2", "alpha1", "theta2", "c"]
    kinds = ["length", "length", "angle", "angle", "coefficient"]
    nominal = np.array([0.1, 0.2, 0.0, 1.0, 0.0])
    ident = nominal + [1e-3, -2e-3, 5e-4, -1e-3, 0.3]
    std = np.array([1e-4, 2e-4, 1e-4, 2e-4, 0.1])
    true = nominal + [1.1e-3, -2.1e-3, 4e-4, -1.2e-3, 0.1]
    plots.plot_parameters(tmp_path / "p.png", names, nominal, ident, std, true, kinds)
    top = [a for a in figures[0].axes if "deviation" in a.get_ylabel()]
    z = [a for a in figures[0].axes if a.get_ylabel().startswith("z =")]
    assert [a.get_ylabel() for a in top] == ["length deviation [mm]", "angle deviation [deg]",
                                             "coefficient deviation [1]"]
    for a, sl, f in zip(top, (slice(0, 2), slice(2, 4), slice(4, 5)), (1e3, np.degrees(1.0), 1.0)):
        y = a.lines[0].get_ydata()  # the error-bar markers
        assert y == pytest.approx((ident - nominal)[sl] * f)
        truth = [ln for ln in a.lines if ln.get_marker() == "x"]  # the truth markers
        assert truth[0].get_ydata() == pytest.approx((true - nominal)[sl] * f)
    zs = np.concatenate([a.lines[0].get_ydata() for a in z])
    assert zs == pytest.approx((ident - true) / std)
    # without a truth: one row, no z axes
    plots.plot_parameters(tmp_path / "p2.png", names, nominal, ident, std, None, kinds)
    assert not [a for a in figures[1].axes if a.get_ylabel().startswith("z =")]


def test_residuals_translation_and_rotation_rows_with_labelled_histograms(figures, tmp_path):
    rng = np.random.default_rng(2)
    rb, ra = rng.normal(size=(12, 6)) * 1e-3, rng.normal(size=(12, 6)) * 1e-5
    plots.plot_residuals(tmp_path / "r.png", rb, ra, "pose", [f"p{i}" for i in range(12)])
    ax = figures[0].axes
    assert len(ax) == 4
    assert [a.get_ylabel() for a in ax] == ["translation residual [mm]", "number of poses",
                                           "rotation residual [deg]", "number of poses"]
    assert ax[1].get_xlabel() == "translation residual norm per pose [mm]"
    assert ax[3].get_xlabel() == "rotation residual norm per pose [deg]"
    # the rotation row's bars are the rotation norms in deg (after: the second series)
    segs = ax[2].collections[1].get_segments()
    assert [s[1][1] for s in segs] == pytest.approx(np.degrees(np.linalg.norm(ra[:, 3:], axis=1)))
    assert [t.get_text() for t in ax[0].get_xticklabels()] == [f"p{i}" for i in range(12)]
    plots.plot_residuals(tmp_path / "j.png", rb[:, :4], ra[:, :4], "joint")
    assert [a.get_ylabel() for a in figures[1].axes] == ["joint residual [deg]", "number of poses"]
