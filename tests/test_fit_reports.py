"""Fit reports that tell the truth, one solver layer (issues 15, 17, 18): the users' cases.

Every "measurement" is made by the public forward model ``layerstack_jax.reflectance`` on a stack
built with the true values (no fitting code involved). The references: the true values (exact
data), the analytic optimum on a bound (α = 0 when the data are brighter than any α ≥ 0 allows),
the exact degeneracy of two identical absorbing layers (only h₁ + h₂ enters Beer's law:
correlation −1), the noise level that made the data (σ estimated from residuals), and the
batch's own rows fitted alone.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls
from fitting._status import CONVERGED, INVALID_DATA

WL = np.linspace(400.0, 700.0, 41)
T0 = ls.Specular(0.0, "T")
SIGMA = 0.002


def _slab(h, a):
    """An absorbing incoherent slab on glass, measured in specular transmission at 0°."""
    return ls.Stack(1.0, [ls.Layer(1.5, h, coherent=False, alpha=a, name="slab")], ls.Substrate(1.5))


def _T(h, a):
    return np.asarray(ls.reflectance(_slab(h, a), WL, T0))


@pytest.fixture(scope="module")
def alpha_objective():
    """α of the slab (h known), σ given: the objective of the bound and quality cases."""
    y = _T(10_000.0, 2e-5)
    return ft.Objective(_slab(10_000.0, 5e-6), WL, ft.Dataset(T0, y, sigma=SIGMA), [ft.alpha("slab")]), y


# ------------------------------------------------------------------ issue 18, row 9: no σ
def test_fit_without_sigma_says_chi2_is_not_meaningful():
    """The README's fit line without --sigma: no 'reduced χ² 2.4e-06' but 'not meaningful' and
    the σ estimated from the residuals, close to the noise that made the data."""
    rng = np.random.default_rng(3)
    y = _T(10_000.0, 2e-5) + SIGMA * rng.standard_normal(WL.size)
    obj = ft.Objective(_slab(8_000.0, 2e-5), WL, ft.Dataset(T0, y), [ft.thickness("slab")])
    r = ft.fit(obj)
    assert r.converged, r.reason
    assert r.sigma_origin == "estimated from residuals" and not r.sigma_given
    assert r.sigma_estimate == pytest.approx(SIGMA, rel=0.3)
    text = r.report()
    assert "not meaningful" in text and "reduced chi2" not in text
    assert f"s = {r.sigma_estimate:.3g}" in text
    d = r.to_dict()
    assert d["sigma"]["origin"] == "estimated from residuals" and d["chi2_meaningful"] is False
    title = r.plot()._suptitle.get_text()
    assert "reduced" not in title and "σ from residuals" in title


# ------------------------------------------------------------------ fit quality verdicts
def test_percent_file_is_flagged(alpha_objective):
    obj, y = alpha_objective
    r = ft.fit(obj, data=[100.0 * y[None]])
    assert any("percent" in w for w in r.warnings)
    assert "percent" in r.report() and "WARNING" in r.report()


def test_converged_fit_with_implausible_chi2_carries_the_warning(alpha_objective):
    """Data with a ripple of 0.02 (10 σ) that no α can follow: the solver meets its tolerance,
    the verdict says the model does not describe the data; 'converged' is never alone."""
    obj, y = alpha_objective
    r = ft.fit(obj, data=[(y + 0.02 * np.sin(WL / 15.0))[None]])
    assert r.converged
    assert r.reduced_chi2 > 10 and "implausibly large" in r.quality
    text = r.report()
    assert "converged         yes" in text and "WARNING" in text and "does not describe the data" in text
    assert r.to_dict()["quality"]["warnings"]


def test_exact_model_within_noise_is_consistent(alpha_objective):
    obj, y = alpha_objective
    rng = np.random.default_rng(0)
    r = ft.fit(obj, data=[(y + SIGMA * rng.standard_normal(y.size))[None]])
    assert r.converged and "consistent with the noise" in r.quality and not r.warnings
    assert r.sigma_origin == "given" and r.dof == WL.size - 1


# ------------------------------------------------------------------ issue 18, row 8: bounds
def test_optimum_on_bound_with_default_lm_is_converged_and_named(alpha_objective):
    """Data 2 % brighter than the transparent slab allows: the least-squares α is 0. The
    default LM holds α on the bound once it gets there and ends by its own step test within a
    few steps (not max_steps = 256); the bound is optimal (KKT), so the fit is converged there,
    says so, and reports α exactly at its bound — no 'max steps' flag, no solver internals."""
    obj, _ = alpha_objective
    y = 1.02 * _T(10_000.0, 0.0)
    r = ft.fit(obj, data=[y[None]])
    assert r.converged, r.reason
    assert r.num_steps <= 20
    assert float(r.values["alpha[slab]"]) == 0.0
    assert r.at_bound == [{"parameter": "alpha[slab]", "value": 0.0, "bound": 0.0, "side": "lower"}]
    assert "converged on the bound" in r.note
    text = r.report()
    assert "AT LOWER BOUND 0" in text and "alpha[slab] = 0 (lower bound 0)" in text and "converged on the bound" in text
    assert "root-find" not in text and "max_steps" not in text


def test_gauss_newton_failing_on_a_bound_is_converged_there(alpha_objective):
    """Gauss–Newton's step on the transformed α fails at the bound (optimistix reports a
    failure); the bound is optimal, so the fit is converged on it."""
    obj, _ = alpha_objective
    r = ft.fit(obj, "gauss-newton", data=[(1.02 * _T(10_000.0, 0.0))[None]])
    assert r.converged and float(r.values["alpha[slab]"]) == 0.0 and "converged on the bound" in r.note


def test_unconverged_fit_away_from_the_optimum_is_not_settled(alpha_objective):
    """A bound in contact is not enough: two steps from a far start, not on the bound, stay
    'not converged'."""
    obj, y = alpha_objective
    r = ft.fit(obj, data=[y[None]], max_steps=2)
    assert not r.converged and r.note == "" and not r.at_bound


def test_batch_of_20_with_8_optima_on_the_bound(alpha_objective):
    """The user's batch: 20 fits, 8 of them with the optimum at α = 0 — all converged, the 8 on
    the bound named, the others at their true α."""
    obj, _ = alpha_objective
    alphas = np.linspace(5e-6, 4e-5, 12)
    data = np.stack([_T(10_000.0, a) for a in alphas] + [f * _T(10_000.0, 0.0) for f in np.linspace(1.01, 1.03, 8)])
    b = ft.fit_batch(obj, data)
    assert b.converged.all(), b.summary()
    np.testing.assert_allclose(b.values["alpha[slab]"][:12], alphas, rtol=1e-6)
    assert (b.values["alpha[slab]"][12:] == 0.0).all()  # held exactly on the bound
    assert b.num_steps.max() <= 40, b.num_steps  # was 256 (max_steps) for 4 of the 8 before the bound was held
    assert b.at_bound[:, 0].tolist() == [False] * 12 + [True] * 8
    assert not b.finished_on_bound[:12].any()
    assert "alpha[slab] in 8 fit(s)" in b.summary() and "root-find" not in b.summary()


@pytest.mark.parametrize("method", ["lm", "gauss-newton", "dogleg", "bfgs"])
def test_bound_reached_but_not_optimal_is_finished_by_lbfgsb(alpha_objective, method):
    """The optimum α = 2e-10 /nm lies inside the bound but closer to it (4e-5 of the scale) than
    the 1e-4 within which the unconstrained solvers hold a parameter on its bound: the bound
    fails the optimality check (the gradient pulls away from it), so the fit is finished by
    L-BFGS-B from there, finds the true α and says what happened."""
    obj, _ = alpha_objective
    r = ft.fit(obj, method, data=[_T(10_000.0, 2e-10)[None]])
    assert r.converged, r.reason
    assert float(r.values["alpha[slab]"]) == pytest.approx(2e-10, rel=1e-3)
    assert "finished from that point with L-BFGS-B" in r.note and not r.at_bound
    b = ft.fit_batch(obj, np.stack([_T(10_000.0, 2e-10), 1.02 * _T(10_000.0, 0.0)]), method=method)
    assert b.finished_with_lbfgsb.tolist() == [True, False] and b.finished_on_bound.tolist() == [False, True]
    assert "1 fit(s) finished with L-BFGS-B" in b.summary()


# ------------------------------------------------------------------ inseparable parameters
def _twin():
    """Two identical absorbing layers (same index: no interface between them): T depends on
    h₁ + h₂ only, so h₁ and h₂ have correlation −1."""
    def stack(h1, h2):
        return ls.Stack(1.0, [ls.Layer(1.5, h1, coherent=False, alpha=2e-5, name="a"),
                              ls.Layer(1.5, h2, coherent=False, alpha=2e-5, name="b")], ls.Substrate(1.5))

    y = np.asarray(ls.reflectance(stack(6_000.0, 4_000.0), WL, T0))
    return ft.Objective(stack(5_000.0, 3_000.0), WL, ft.Dataset(T0, y, sigma=SIGMA),
                        [ft.thickness("a"), ft.thickness("b")])


def test_correlation_minus_one_pair_is_named():
    r = ft.fit(_twin())
    assert r.converged
    assert r.values["thickness[a]"] + r.values["thickness[b]"] == pytest.approx(10_000.0, rel=1e-8)
    assert r.not_separated == [{"parameters": ["thickness[b]", "thickness[a]"], "correlation": -1.0}]
    text = r.report()
    assert "NOT SEPARATED by the data: thickness[b] / thickness[a] (correlation -1.0000" in text
    assert np.isnan(r.x_stderr).all()


# ------------------------------------------------------------------ fit and fit_batch agree
def _bare_background_case():
    """Varnish over a Lambertian background with its bare-background spectrum: α·h is
    degenerate (rank deficient), ρg is pinned by the bare spectrum (finite σ)."""
    g = ls.Directional(45.0, 0.0)

    def stack(h, a, rho):
        return ls.Stack(1.0, [ls.Layer(1.5, h, coherent=False, alpha=a, name="varnish")],
                        ls.LambertianBackground(1.5, rho))

    coated = np.asarray(ls.reflectance(stack(20_000.0, 1e-5, 0.6), WL, g))
    bare = np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.LambertianBackground(1.5, 0.6)), WL, g))
    rng = np.random.default_rng(5)
    coated = coated + SIGMA * rng.standard_normal(WL.size)
    bare = bare + SIGMA * rng.standard_normal(WL.size)
    return ft.Objective(stack(15_000.0, 1e-5, 0.5), WL,
                        [ft.Dataset(g, coated, sigma=SIGMA), ft.Dataset(g, bare, sigma=SIGMA, bare=True)],
                        [ft.thickness("varnish"), ft.alpha("varnish"), ft.rho_g()])


def _noisy_slab_without_sigma():
    rng = np.random.default_rng(1)
    y = _T(10_000.0, 2e-5) + SIGMA * rng.standard_normal(WL.size)
    return ft.Objective(_slab(8_000.0, 1e-5), WL, ft.Dataset(T0, y), [ft.thickness("slab")])


@pytest.mark.parametrize("case", [_noisy_slab_without_sigma, _bare_background_case, _twin])
def test_fit_and_fit_batch_give_the_same_standard_errors(case):
    obj = case()
    r = ft.fit(obj)
    data = [np.asarray(d)[None] for d in obj.args()[0]]
    b = ft.fit_batch(obj, data, full_results=True)
    np.testing.assert_array_equal(np.isnan(b.stderr[0]), np.isnan(r.x_stderr))
    np.testing.assert_allclose(b.stderr[0], r.x_stderr, rtol=1e-6)
    np.testing.assert_array_equal(b.results[0].x_stderr, b.stderr[0])  # one computation
    assert b.rank[0] == r.rank and b.sigma_origin == r.sigma_origin
    if case is _bare_background_case:
        assert r.rank == 2 and np.isfinite(r.stderr["rho_g"])  # the reported discrepancy: ρg is determined
        assert np.isnan(r.stderr["alpha[varnish]"]) and np.isnan(r.stderr["thickness[varnish]"])


# ------------------------------------------------------------------ issue 18, row 7
def test_batch_pixel_that_cannot_be_fitted_is_flagged_alone():
    """Noisy readings of a dark pixel dip below 0 (within 5 σ: data, fitted); a pixel whose
    reading is far below 0 or NaN cannot be fitted: flagged in its own row, while the others
    are fitted as without it."""
    y = _T(10_000.0, 2e-5)
    obj = ft.Objective(_slab(8_000.0, 2e-5), WL, ft.Dataset(T0, y, sigma=SIGMA), [ft.thickness("slab")])
    data = np.stack([_T(h, 2e-5) for h in (9_000.0, 10_000.0, 11_000.0, 12_000.0)])
    data[0, 3] = -0.001  # dark reading within noise
    data[1, 7] = -0.5  # wrong baseline
    data[2, 9] = np.nan  # dead pixel, not masked
    b = ft.fit_batch(obj, data)
    assert b.result_code.tolist() == [CONVERGED, INVALID_DATA, INVALID_DATA, CONVERGED]
    assert "below -5 sigma" in b.invalid_data[1] and "NaN" in b.invalid_data[2]
    assert np.isnan(b.x[1:3]).all() and "not fitted" in b.reasons[1] and "2 × not fitted" in b.summary()
    assert b.values["thickness[slab]"][3] == pytest.approx(12_000.0, rel=1e-8)
    alone = ft.fit(obj, data=[data[0][None]])
    assert b.values["thickness[slab]"][0] == pytest.approx(float(alone.values["thickness[slab]"]), rel=1e-9)


# ------------------------------------------------------------------ one solver layer
def test_import_fitting_is_silent_and_does_not_import_jaxopt():
    """A fresh interpreter: ``import fitting`` raises no runtime warning (jaxopt's "no longer
    maintained" was one) and does not import jaxopt. (Compile-time warnings on escape sequences
    in source files depend on the byte-code cache and are left out.)"""
    code = ("import sys, warnings\n"
            "with warnings.catch_warnings(record=True) as w:\n"
            "    warnings.simplefilter('always')\n"
            "    import fitting\n"
            "found = [f'{x.category.__name__}: {x.message}' for x in w\n"
            "         if not str(x.message).startswith('invalid escape sequence')]\n"
            "assert not found, found\n"
            "assert 'jaxopt' not in sys.modules, 'jaxopt imported'\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_reasons_are_in_the_librarys_words(alpha_objective):
    obj, y = alpha_objective
    r = ft.fit(obj, data=[y[None]], max_steps=1, method="gauss-newton")
    assert not r.converged and r.reason.startswith("not converged: the step limit (max_steps)")
    assert "NO — not converged" in r.report() and "did not converge" in r.report()


def test_lookup_start_picks_the_nearest_tabulated_spectrum_and_fits_the_same(alpha_objective):
    """fit_batch(start="lookup"): each fit starts from the tabulated point whose spectrum is
    nearest its data (checked against a direct search over the table) and finds the true α.
    From the objective's single start (α = 5e-6) the densest slab (α = 9e-5) is lost: LM's first
    step lowers the cost by jumping to the opaque plateau (α ≈ 0.47, T ≈ 0, no gradient), and the
    fit, 'converged' there, carries an implausible χ² (≫ 1 with σ given) that says so."""
    from fitting._batch import LookupTable

    obj, _ = alpha_objective
    alphas = np.array([1e-6, 8e-6, 3e-5, 9e-5])
    data = np.stack([_T(10_000.0, a) for a in alphas])
    table = LookupTable(obj, 32)
    starts = table.nearest((data[:, None, :],), (np.full((4, 1, WL.size), 1 / SIGMA),))
    direct = [table.points[np.argmin([np.sum((_T(10_000.0, p[0]) - y) ** 2) for p in table.points])] for y in data]
    np.testing.assert_array_equal(starts, np.array(direct))
    a = ft.fit_batch(obj, data, start="lookup", lookup_size=32)
    b = ft.fit_batch(obj, data)
    assert a.converged.all() and b.converged.all()
    np.testing.assert_allclose(a.values["alpha[slab]"], alphas, rtol=1e-7)
    np.testing.assert_allclose(b.values["alpha[slab]"][:3], alphas[:3], rtol=1e-7)
    assert a.reduced_chi2[3] < 1e-6 and b.reduced_chi2[3] > 1e3
    with pytest.raises(ls.LayerstackError, match="start must be"):
        ft.fit_batch(obj, data, start="table")
