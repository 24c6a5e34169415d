"""Saddle-point corner estimator (targets/kinds/saddle.py) on analytic X-corner images."""

import numpy as np
import pytest
from scipy.special import erf

from vision_calib.targets.kinds.saddle import read_mask, refine_detected, refine_saddles, window_radii


def x_corner(shape, c, theta, skew, s=0.7, lo=30.0, hi=220.0):
    """(H, W) float image of an X-corner at c (x, y) px (pixel centres at integer coordinates): two straight
    edges through c at angles theta and theta + skew [rad], each blurred by a Gaussian of std s px:
    mid + (hi - lo) / 2 erf(n1.d / (sqrt2 s)) erf(n2.d / (sqrt2 s)), point-symmetric about c."""
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(float)
    d = np.stack([x - c[0], y - c[1]], axis=-1)
    n1 = np.array([-np.sin(theta), np.cos(theta)])
    n2 = np.array([-np.sin(theta + skew), np.cos(theta + skew)])
    e1 = erf(d @ n1 / (np.sqrt(2) * s))
    e2 = erf(d @ n2 / (np.sqrt(2) * s))
    return (lo + hi) / 2 + (hi - lo) / 2 * e1 * e2


CASES = [(th, sk, s) for th in (0.0, 0.4, 1.1) for sk in (np.pi / 2, 1.1, 0.75) for s in (0.5, 1.5)]


@pytest.mark.parametrize("theta, skew, s", CASES)
def test_recovers_subpixel_position(theta, skew, s):
    """Noise-free corners at 16 sub-pixel offsets, started up to 0.6 px off: error < 0.005 px for edges
    blurred by 0.5 px, < 0.002 px by 1.5 px (measured 0.0027, 0.0013; the fit is exact up to the pixel-phase
    sampling of the point-sampled edges and window: the image is point-symmetric about the corner)."""
    rng = np.random.default_rng(1)
    err = []
    for fx in (0.0, 0.25, 0.5, 0.75):
        for fy in (0.1, 0.35, 0.6, 0.85):
            c = np.array([30 + fx, 31 + fy])
            img = x_corner((64, 64), c, theta, skew, s)
            start = c + rng.uniform(-0.6, 0.6, 2) * [1, 0.7]
            uv, ok = refine_saddles(img, start[None], max_move=1.0, rho=10.0)
            assert ok[0]
            err.append(np.abs(uv[0] - c).max())
    assert max(err) < (5e-3 if s < 1 else 2e-3), max(err)


def test_uint8_noise_scatter_and_bias():
    """8-bit image with read noise 4 grey: mean error over 200 draws < 3 standard errors + 0.003 px and a
    scatter that shrinks with a larger window (more pixels)."""
    rng = np.random.default_rng(2)
    c = np.array([30.3, 29.7])
    base = x_corner((64, 64), c, 0.3, 1.2, 0.8)
    std = {}
    for rho in (5.0, 10.0):
        e = []
        for _ in range(200):
            img = np.clip(np.rint(base + rng.normal(0, 4.0, base.shape)), 0, 255).astype(np.uint8)
            uv, ok = refine_saddles(img, (c + 0.3)[None], 1.0, rho)
            assert ok[0]
            e.append(uv[0] - c)
        e = np.array(e)
        std[rho] = e.std(0, ddof=1)
        assert np.all(np.abs(e.mean(0)) < 3 * std[rho] / np.sqrt(len(e)) + 3e-3), (rho, e.mean(0), std[rho])
    assert np.all(std[10.0] < std[5.0]), std


def test_rejections():
    """Not a saddle (a dark blob: Hessian determinant > 0), a flat patch, a start more than max_move away
    from the saddle, a window that cannot fit in the image: ok False and the start returned."""
    y, x = np.mgrid[0:64, 0:64].astype(float)
    blob = 200 - 150 * np.exp(-((x - 30.2) ** 2 + (y - 31.6) ** 2) / (2 * 3.0**2))
    flat = np.full((64, 64), 100.0)
    xc = x_corner((64, 64), (30.4, 31.2), 0.2, 1.4)
    starts = np.array([[30.0, 31.0]])
    for img, st in ((blob, starts), (flat, starts), (xc, starts + [1.4, 0.0]), (xc, np.array([[1.5, 31.0]]))):
        uv, ok = refine_saddles(img, st, max_move=1.0, rho=6.0)
        assert not ok[0] and np.array_equal(uv, st)
    uv, ok = refine_saddles(xc, starts, max_move=1.0, rho=6.0)
    assert ok[0] and np.abs(uv[0] - [30.4, 31.2]).max() < 2e-3


def test_window_radii_and_read_mask():
    """Windows: half the nearest-neighbour distance, within [RHO_MIN, RHO_MAX]; the read mask holds the disc of
    radius rho + max_move around each start and nothing else; refinement with everything outside it zeroed
    gives bit-identical corners (also when the corner moves)."""
    uv = np.array([[20.0, 20.0], [40.0, 20.0], [20.0, 27.0], [60.0, 60.0]])
    np.testing.assert_array_equal(window_radii(uv), [3.5, 10.0, 3.5, 12.0])
    m = read_mask(uv[:1], (64, 80), 1.0, 5.0)
    y, x = np.nonzero(m)
    r = np.hypot(x - 20, y - 20)
    assert r.max() <= 6.0 and m.sum() == np.sum(np.hypot(*np.mgrid[-6:7, -6:7]) <= 6.0)
    img = np.clip(np.rint(x_corner((64, 80), (40.6, 30.3), 0.5, 1.3) + np.random.default_rng(3).normal(0, 3, (64, 80))),
                  0, 255)
    st = np.array([[40.0, 30.9]])
    mask = read_mask(st, img.shape, 1.0, 8.0)
    a = refine_saddles(img, st, 1.0, 8.0)
    b = refine_saddles(np.where(mask, img, 0.0), st, 1.0, 8.0)
    assert a[1][0] and np.array_equal(a[0], b[0])


def _wave(x, edges, s):
    """Square wave -1 / +1 switching sign at each edge, blurred by a Gaussian of std s."""
    return -1.0 + sum((-1) ** k * (1.0 + erf((x - e) / (np.sqrt(2) * s))) for k, e in enumerate(edges))


def test_refine_detected_on_a_chessboard():
    """Blurred axis-aligned chessboard (separable: the product of two blurred square waves), squares of
    22.37 x 19.6 px at sub-pixel phases: the interior corners from 0.4 px off to < 0.002 px; the windows are
    half the smaller spacing; a restart from the result (the seeded batch mode) stays put."""
    ex, ey = 20.3 + 22.37 * np.arange(6), 15.8 + 19.6 * np.arange(6)
    y, x = np.mgrid[0:130, 0:150].astype(float)
    img = 128 + 100 * _wave(x, ex, 0.8) * _wave(y, ey, 0.8)
    cs = np.array([[u, v] for v in ey[1:-1] for u in ex[1:-1]])
    start = cs + np.random.default_rng(4).uniform(-0.4, 0.4, cs.shape)
    uv, ok = refine_detected(img, start)
    assert ok.all() and np.abs(uv - cs).max() < 2e-3, np.abs(uv - cs).max()
    np.testing.assert_array_equal(window_radii(uv), 9.5)
    uv2, ok2 = refine_saddles(img, uv)
    assert ok2.all() and np.abs(uv2 - uv).max() < 1e-3
