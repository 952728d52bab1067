"""Parameters the data cannot separate, in plain words and grouped (issues 27 and 31).

References: the combination a fit reports as determined is checked against a NumPy
re-derivation from the fit's own covariance written here (the exponent p that makes
ln b + p ln a least variable, :math:`p^* = -\\mathrm{cov}(\\ln a, \\ln b)/\\mathrm{var}(\\ln a)`,
and its relative error against the parts'); the grouping against covariances built in the test
from Jacobians of known structure; the pair count against the binomial coefficient. The data are
made by the public forward model with the true values.
"""

from __future__ import annotations

import json
from math import comb

import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls
from fitting._statistics import correlated_groups, separability_findings


# ----------------------------------------------------------------------------- a 2 nm oxide
@pytest.fixture(scope="module")
def oxide():
    """ψ/Δ at 70° of 2 nm of oxide (n = 1.46) on Si, σ = 0.02°; n and d free."""
    wl = np.linspace(300.0, 800.0, 101)
    si = ls.material("Si", "Aspnes")

    def st(n, d):
        return ls.Stack(1.0, [ls.Layer(n, d, name="oxide")], ls.Substrate(si))

    rng = np.random.default_rng(0)
    ds, clean = [], []
    for q in ("psi", "delta"):
        g = ls.Ellipsometric(70.0, quantity=q)
        y = np.asarray(ls.reflectance(st(1.46, 2.0), wl, g))
        clean.append(y)
        ds.append(ft.Dataset(g, y + 0.02 * rng.standard_normal(y.shape), sigma=0.02))
    return ft.Objective(st(1.5, 3.0), wl, ds, [ft.index_n("oxide"), ft.thickness("oxide")]), clean


def test_thin_oxide_n_and_d_flagged_with_the_combination_they_determine(oxide):
    """Correlation ≈ −1 at full rank: flagged as poorly separable, with the product the data
    determine."""
    r = ft.fit(oxide[0])
    assert r.converged and r.rank == 2
    rho = r.correlation[0, 1]
    assert rho < -0.99
    assert not r.identifiable
    (f,) = r.separability
    assert f["kind"] == "poorly separable" and set(f["parameters"]) == {"n[oxide]", "thickness[oxide]"}
    assert f["pairs"] == 1 and f["max_abs_correlation"] == pytest.approx(abs(rho))
    text = f["combination"]
    assert text.startswith("thickness[oxide]·n[oxide]^") and "is determined, not" in text
    p = float(text.split("^")[1].split()[0])
    # NumPy: the exponent p* minimising var(ln d + p ln n), from the covariance in relative units
    C = r.covariance / np.outer(r.x, r.x)
    p_star = -C[0, 1] / C[0, 0]
    assert p == pytest.approx(p_star, rel=0.1)
    # the combination is determined far better than either part
    a = np.array([p, 1.0])
    assert np.sqrt(a @ C @ a) < 0.2 * np.sqrt(C[1, 1])
    report = r.report()
    assert "POORLY SEPARABLE" in report and text in report
    assert "the data cannot separate 1 group(s)" in " ".join(r.warnings)
    d = json.loads(r.to_json())
    assert d["identifiability"]["findings"][0]["combination"] == text
    assert d["identifiability"]["correlation_limit"] == 0.99


def test_fit_batch_reports_the_same_finding_for_every_fit(oxide):
    obj, clean = oxide
    rng = np.random.default_rng(1)
    data = [y + 0.02 * rng.standard_normal((3,) + y.shape) for y in clean]
    b = ft.fit_batch(obj, data, chunk_size=3, progress=False)
    assert b.converged.all()
    for k in range(3):
        (f,) = b.separability[k]
        assert f["kind"] == "poorly separable" and f["combination"].startswith("thickness[oxide]·n[oxide]^")
    assert "3 fit(s): poorly separable (|ρ| > 0.99): n[oxide], thickness[oxide]" in b.summary()


def test_a_looser_limit_is_stated_and_used():
    cov = np.array([[1.0, 0.95], [0.95, 1.0]])
    assert correlated_groups(cov, 0.99) == [] and len(correlated_groups(cov, 0.9)) == 1


def test_groups_follow_the_links_of_known_jacobians():
    """J of two independent pairs, each a product a·b (columns ∝ 1/a, 1/b in relative units),
    and a fifth parameter on its own: two groups, each naming the product."""

    class _P:
        def __init__(self, name):
            self.name = name

    class _Layout:
        params = [_P("a"), _P("b"), _P("c"), _P("d"), _P("e")]
        names = ["a", "b", "c", "d", "e"]
        owner = np.arange(5)
        scale = np.ones(5)

    rng = np.random.default_rng(2)
    t = rng.standard_normal((40, 3))
    # relative derivatives: a and b enter only through a·b (plus a little of a alone), c and d
    # through c/d, e alone
    Jrel = np.column_stack([t[:, 0] + 1e-3 * t[:, 2], t[:, 0], t[:, 1], -t[:, 1] + 1e-3 * t[:, 2], t[:, 2]])
    x = np.array([2.0, 3.0, 4.0, 5.0, 6.0])
    J = Jrel / x  # d r / d x
    cov = np.linalg.inv(J.T @ J)
    d = np.sqrt(np.diag(cov))
    corr = cov / np.outer(d, d)
    found = separability_findings(_Layout(), x, cov, corr)
    assert [f["components"] for f in found] == [["a", "b"], ["c", "d"]]
    assert found[0]["combination"].startswith("a·b ") or found[0]["combination"].startswith("b·a ")
    assert found[1]["combination"].split()[0] in ("c·d^-1", "d·c^-1")


# ----------------------------------------------------------------------------- 54 parameters
WL = np.linspace(400.0, 700.0, 21)


def _series(n_samples=45):
    """45 varnish thicknesses, all free, α on 8 B-splines, a scalar ρg: 54 parameters; α and
    the thicknesses enter only as α·h (53 components on one null direction: 1,378 pairs)."""
    g = ls.Directional(45.0, 0.0)
    h = np.linspace(10_000.0, 40_000.0, n_samples)
    basis = ft.bspline_basis(WL, 8)
    a_true = 2e-5 * (1 + 0.3 * np.cos(np.linspace(0, 3, 8)))

    def st(hh, a):
        return ls.Stack(1.0, [ls.Layer(1.5, hh, coherent=False, alpha=a, name="varnish")],
                        ls.LambertianBackground(1.5, 0.6))

    y = np.stack([np.asarray(ls.reflectance(st(x, basis @ a_true), WL, g)) for x in h])
    rng = np.random.default_rng(4)
    y = y + 0.002 * rng.standard_normal(y.shape)
    params = [ft.thickness("varnish", value=h * 0.9, per_sample=True),
              ft.alpha("varnish", basis=basis, value=np.full(8, 1.5e-5)), ft.rho_g(value=0.5)]
    return ft.Objective(st(h[0], 1.5e-5), WL, ft.Dataset(g, y, sigma=0.002), params, n_samples=n_samples)


def test_54_parameters_report_fits_a_screen_and_the_json_has_every_pair(tmp_path):
    obj = _series()
    assert obj.n_parameters == 54
    r = ft.fit(obj)
    assert r.rank < 54 and not r.identifiable
    assert len(r.not_separated) >= comb(53, 2)  # every α–h, α–α and h–h pair of the null direction
    text = r.report()
    ident = text.split("identifiability\n---------------\n")[1].split("\n\nresiduals")[0].splitlines()
    assert len(ident) <= 12, ident
    assert max(len(line) for line in ident) < 400
    warn = [line for line in text.splitlines() if line.startswith("WARNING")]
    assert sum(len(w) for w in warn) < 1500, warn
    assert len(text) < 12_000  # the parameter table is most of it (54 values)
    # the grouped finding names the product, and the advice of fit-cube is given
    (f,) = [f for f in r.separability if f["kind"] == "not identifiable"]
    assert len(f["components"]) == 53 and "rho_g" not in f["parameters"]
    assert "alpha[varnish]·thickness[varnish]" in f["combination"] or \
        "thickness[varnish]·alpha[varnish]" in f["combination"]
    assert any("thickness and alpha are both free" in w and "fix one of them" in w for w in r.warnings)
    assert "thickness and alpha are both free" in text
    d = json.loads(r.to_json(tmp_path / "fit.json"))
    assert len(d["identifiability"]["not_separated"]) == len(r.not_separated)
    assert d["identifiability"]["findings"][0]["components"] == f["components"]


def test_cli_fit_gives_the_alpha_h_advice_and_the_combination(tmp_path, capsys):
    """`layerstack fit` of an absorbing slab with its thickness and α both free: the report names
    α·h as what the data determine and gives fit-cube's advice (one helper)."""
    from layerstack_cli import main
    from layerstack_jax.io import save_spectra_csv

    from fitting._fit_findings import structural_degeneracy

    wl = np.arange(400.0, 701.0, 10.0)
    stack = tmp_path / "s.toml"
    stack.write_text("""
[[layers]]
name = "slab"
n = 1.5
thickness_nm = { value = 8000, free = true, min = 0, max = 1e5 }
coherent = false
alpha_per_nm = { value = 3e-5, free = true }

[substrate]
n = 1.5
""")
    st = ls.Stack(1.0, [ls.Layer(1.5, 10_000.0, coherent=False, alpha=2e-5, name="slab")], ls.Substrate(1.5))
    data = tmp_path / "d.csv"
    save_spectra_csv(data, wl, {"a": np.asarray(ls.reflectance(st, wl, ls.Specular(0.0, "T")))})
    code = main(["fit", str(stack), str(data), "-g", "specular:0:T", "-o", str(tmp_path / "r.json")])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "NOT IDENTIFIABLE" in text and "·" in text
    advice = structural_degeneracy(ft.Objective(st, wl, ft.Dataset(ls.Specular(0.0, "T"), np.ones(wl.size) * 0.5),
                                                [ft.thickness("slab"), ft.alpha("slab")]))
    assert advice and advice[0] in text
