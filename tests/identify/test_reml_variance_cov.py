"""The REML variances' covariance 2 (tr(P V_i P V_j))^-1 of identify.handeye_fit computed in O(N) (sums over the
poses) equals the dense formula with the (N m)^2 projector P built explicitly."""

import numpy as np
import pytest
from scipy.linalg import block_diag

from vision_calib.identify.handeye_fit import reml_variance_cov


def _dense(J, known, blocks, theta):
    n, m, _ = J.shape
    C = known + np.einsum("i,inab->nab", theta, blocks)
    W = block_diag(*np.linalg.inv(C))
    Jf = J.reshape(n * m, -1)
    P = W - W @ Jf @ np.linalg.pinv(Jf.T @ W @ Jf) @ Jf.T @ W
    V = [block_diag(*b) for b in blocks]
    T = np.array([[np.trace(P @ Vi @ P @ Vj) for Vj in V] for Vi in V])
    return 2.0 * np.linalg.pinv(T)


@pytest.mark.parametrize("n, k", [(12, 2), (40, 7)])
def test_variance_cov_equals_the_dense_formula(n, k):
    rng = np.random.default_rng(n + k)
    J = rng.normal(size=(n, 6, 12))
    A = rng.normal(size=(n, 6, 6))
    known = 0.1 * A @ np.swapaxes(A, 1, 2)
    B = rng.normal(size=(k, n, 6, 3))
    blocks = B @ np.swapaxes(B, 2, 3)
    theta = rng.uniform(0.1, 1.0, k)
    ref = _dense(J, known, blocks, theta)
    np.testing.assert_allclose(reml_variance_cov(J, known, blocks, theta), ref, rtol=1e-9,
                               atol=1e-12 * np.abs(ref).max())
