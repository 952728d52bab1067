"""fitting/_statistics.py: the one computation of χ², covariance, standard errors, correlation
and identifiability, against independent references.

References: ``numpy.polyfit`` (its own least-squares solve and covariance, ``cov="unscaled"``
for given σ, ``cov=True`` for σ estimated from the residuals, χ²/(N − P)) on a straight-line
model; the exact degeneracy r = f(a + b) whose covariance limit is known in closed form
(correlation −1); batched rows against the same fits one at a time.
"""

from __future__ import annotations

import numpy as np
import pytest

from fitting import _statistics as S


class _Layout:
    """The parts of a fitting layout the statistics read: scale, bounds, owner, names."""

    def __init__(self, P, owner=None, lower=None, upper=None):
        self.size = P
        self.scale = np.ones(P)
        self.owner = np.arange(P) if owner is None else np.asarray(owner)
        self.lower = np.full(P, -np.inf) if lower is None else np.asarray(lower, float)
        self.upper = np.full(P, np.inf) if upper is None else np.asarray(upper, float)
        self.names = [f"p{i}" for i in range(P)]


def _line(seed=0, n=30, sigma=0.1):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 3.0, n)
    y = 0.7 + 1.9 * t + sigma * rng.standard_normal(n)
    return t, y, sigma


def _line_fit(t, y, sigma):
    """Weighted least squares of y = a + b t by lstsq; J = ∂r/∂(a, b) of r = (f − y)/σ."""
    J = np.column_stack([np.ones_like(t), t]) / sigma
    ab = np.linalg.lstsq(J, y / sigma, rcond=None)[0]
    r = (ab[0] + ab[1] * t - y) / sigma
    return ab, J, r


@pytest.mark.parametrize("given", [True, False])
def test_line_covariance_matches_numpy_polyfit(given):
    t, y, sigma = _line()
    ab, J, r = _line_fit(t, y, sigma)
    st = S.fit_statistics(J, ab, [r[None]], _Layout(2), t.size, sigma_given=given)
    # polyfit orders coefficients (b, a); its weights are 1/σ
    _, cov_ref = np.polyfit(t, y, 1, w=np.full(t.size, 1 / sigma), cov="unscaled" if given else True)
    cov_ref = cov_ref[::-1, ::-1]
    np.testing.assert_allclose(st.covariance, cov_ref, rtol=1e-10)
    np.testing.assert_allclose(st.stderr, np.sqrt(np.diag(cov_ref)), rtol=1e-10)
    assert st.dof == t.size - 2 and st.chi2 == pytest.approx(np.sum(r ** 2), rel=1e-12)
    rho = cov_ref[0, 1] / np.sqrt(cov_ref[0, 0] * cov_ref[1, 1])
    assert st.correlation[0, 1] == pytest.approx(rho, rel=1e-10)
    assert st.sigma_origin == (S.SIGMA_GIVEN if given else S.SIGMA_ESTIMATED)
    assert int(st.rank) == 2 and not st.unresolved.any()


def test_sigma_origin_default_when_no_sigma_and_no_rescaling():
    t, y, sigma = _line()
    ab, J, r = _line_fit(t, y, sigma)
    st = S.fit_statistics(J, ab, [r[None]], _Layout(2), t.size, sigma_given=False, scale_covariance=False)
    assert st.sigma_origin == S.SIGMA_DEFAULT and not st.chi2_meaningful


def test_exact_degeneracy_is_unresolved_with_correlation_minus_one():
    """r depends on a + b only: J has two equal columns; a and b are unresolved (NaN errors)
    and their correlation is the limit −1 (covariance ∝ v vᵀ, v = (1, −1)/√2); c is resolved."""
    t = np.linspace(0, 1, 20)
    J = np.column_stack([np.ones_like(t), np.ones_like(t), t])
    x = np.array([1.0, 2.0, 0.5])
    r = 0.01 * np.sin(7 * t)
    st = S.fit_statistics(J, x, [r[None]], _Layout(3), t.size, sigma_given=True)
    assert int(st.rank) == 2
    assert st.unresolved.tolist() == [True, True, False]
    assert np.isnan(st.stderr[:2]).all() and np.isfinite(st.stderr[2])
    assert st.correlation[0, 1] == -1.0
    assert S.strong_correlations(st.correlation) == [(1, 0, -1.0)]


def test_nearly_degenerate_pair_is_found_by_its_correlation_whatever_the_rank():
    """Columns that differ by 1e-6: full rank at rank_rtol = 1e-8, but |ρ| > 0.99."""
    t = np.linspace(0, 1, 20)
    J = np.column_stack([np.ones_like(t), np.ones_like(t) + 1e-6 * t])
    st = S.fit_statistics(J, np.array([1.0, 2.0]), [np.zeros((1, 20))], _Layout(2), 20, sigma_given=True)
    assert int(st.rank) == 2 and not st.unresolved.any()
    [(i, j, rho)] = S.strong_correlations(st.correlation)
    assert (i, j) == (1, 0) and rho < -0.99


def test_zero_column_is_unresolved():
    J = np.column_stack([np.linspace(1, 2, 10), np.zeros(10)])
    st = S.fit_statistics(J, np.array([1.0, 1.0]), [np.zeros((1, 10))], _Layout(2), 10, sigma_given=True)
    assert st.unresolved.tolist() == [False, True] and np.isnan(st.stderr[1])


def test_batch_rows_equal_single_fits():
    """A stack of fits (one deficient) gives, row by row, the numbers of each fit alone."""
    rows = []
    for seed in range(3):
        t, y, s = _line(seed)
        ab, J, r = _line_fit(t, y, s)
        rows.append((J, ab, r[None]))
    t = np.linspace(0, 3, 30)
    rows.append((np.column_stack([np.ones_like(t), np.zeros_like(t)]), np.array([1.0, 0.0]), np.zeros((1, 30))))
    J = np.stack([a for a, _, _ in rows])
    x = np.stack([b for _, b, _ in rows])
    r = np.stack([c for _, _, c in rows])
    batch = S.fit_statistics(J, x, [r], _Layout(2), 30, sigma_given=False)
    for k, (Jk, xk, rk) in enumerate(rows):
        one = S.fit_statistics(Jk, xk, [rk], _Layout(2), 30, sigma_given=False)
        for field in ("chi2", "reduced_chi2", "covariance", "stderr", "correlation", "singular_values", "rank",
                      "unresolved"):
            np.testing.assert_array_equal(np.asarray(getattr(batch, field))[k], getattr(one, field), err_msg=field)


def test_nonfinite_jacobian_makes_no_claim():
    J = np.full((1, 10, 2), np.nan)
    st = S.fit_statistics(J, np.ones((1, 2)), [np.zeros((1, 1, 10))], _Layout(2), 10, sigma_given=True)
    assert np.isnan(st.stderr).all() and int(st.rank[0]) == 2 and not st.unresolved.any()


def test_bound_contacts():
    lo, hi = S.bound_contacts(np.array([0.0, 1e-9, 5.0, 2.0, 1.0]), np.array([0.0, 0.0, 0.0, -np.inf, 0.0]),
                              np.array([1.0, 1.0, 5.0, np.inf, 1.0]), np.ones(5))
    assert lo.tolist() == [True, True, False, False, False]
    assert hi.tolist() == [False, False, True, False, True]
