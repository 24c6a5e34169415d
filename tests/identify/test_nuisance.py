"""Nuisance coefficients for a shared measurement error: the augmented least squares is the GLS fit with
C = blockdiag(obs_cov) + U U^T (values, covariance, chi-square and its dof), and on data drawn with C its
chi2/dof and parameter z-scores follow their laws, where the fit that ignores U does not."""

import numpy as np

from toy_models import linear_problem
from vision_calib.identify import model_adequacy, solve_lse
from vision_calib.identify.nuisance import split_nuisance, with_nuisance

K, M, N_PAR, D = 20, 3, 4, 5
X_TRUE = np.array([0.3, -0.1, 0.05, 0.2])


def _setup(seed=0):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((K, M, N_PAR))
    B = rng.standard_normal((K, M, M))
    cov = 1e-4 * (B @ np.swapaxes(B, 1, 2) + 0.2 * np.eye(M))
    U = 2e-2 * rng.standard_normal((K, M, D))  # shared error: ~2x the per-pose noise
    C = np.zeros((K * M, K * M))
    for k in range(K):
        C[k * M:(k + 1) * M, k * M:(k + 1) * M] = cov[k]
    Uf = U.reshape(K * M, D)
    return rng, A, cov, U, C + Uf @ Uf.T, Uf


def _draw(rng, A, cov, Uf):
    noise = np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng.standard_normal((K, M))).ravel()
    noise += Uf @ rng.standard_normal(D)
    return np.einsum("kmn,n->km", A, X_TRUE) + noise.reshape(K, M)


def test_augmented_fit_is_the_gls_fit_with_the_full_covariance():
    rng, A, cov, U, C, Uf = _setup()
    y = _draw(rng, A, cov, Uf)
    prob = linear_problem(A, y, cov, ["a", "b", "c", "d"], [0.1] * N_PAR)
    res, nz = split_nuisance(solve_lse(with_nuisance(prob, U, "cam")), N_PAR)
    Af, Ci = A.reshape(K * M, N_PAR), np.linalg.inv(C)
    cov_gls = np.linalg.inv(Af.T @ Ci @ Af)
    x_gls = cov_gls @ Af.T @ Ci @ y.ravel()
    r = y.ravel() - Af @ x_gls
    assert res.names == ("a", "b", "c", "d") and nz["names"] == [f"cam.c{i}" for i in range(D)]
    np.testing.assert_allclose(res.identified, x_gls, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.covariance, cov_gls, rtol=1e-8, atol=0)
    assert res.dof == K * M - N_PAR  # d prior rows and d coefficients: same dof as the plain fit
    np.testing.assert_allclose(2 * res.cost_final, r @ Ci @ r, rtol=1e-8)
    # the coefficients are the posterior mean of the shared error given the residuals
    c_post = Uf.T @ Ci @ r
    np.testing.assert_allclose(nz["values"], c_post, rtol=0, atol=1e-7)
    # ignoring U: a different (less precise) fit with smaller reported std
    plain = solve_lse(prob)
    assert np.all(plain.std < res.std)


def test_chi2_and_z_follow_their_laws_only_with_the_shared_error_in_the_fit():
    rng, A, cov, U, C, Uf = _setup(1)
    chi2_aug, chi2_plain, z = [], [], []
    n_rep = 300
    for _ in range(n_rep):
        prob = linear_problem(A, _draw(rng, A, cov, Uf), cov, ["a", "b", "c", "d"], [0.1] * N_PAR)
        res, _ = split_nuisance(solve_lse(with_nuisance(prob, U)), N_PAR)
        chi2_aug.append(res.chi2_dof)
        z.append((res.identified - X_TRUE) / res.std)
        chi2_plain.append(solve_lse(prob).chi2_dof)
        assert model_adequacy(res)["dof"] == K * M - N_PAR
    dof = K * M - N_PAR
    sd_mean = np.sqrt(2.0 / dof / n_rep)  # std of the mean of chi2(dof)/dof over n_rep draws
    assert abs(np.mean(chi2_aug) - 1) < 4 * sd_mean, np.mean(chi2_aug)
    assert np.mean(chi2_plain) > 1 + 20 * sd_mean, np.mean(chi2_plain)  # the shared error seen as misfit
    z = np.array(z)
    # RMS z of each parameter ~ 1 (chi-square with n_rep dof: relative std of the RMS ~ 1/sqrt(2 n_rep))
    rms = np.sqrt(np.mean(z**2, axis=0))
    assert np.all(np.abs(rms - 1) < 4 / np.sqrt(2 * n_rep)), rms
