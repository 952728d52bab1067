"""Oscillator dispersions (Lorentz, Drude, Tauc–Lorentz, Cody–Lorentz, Cauchy–Urbach) against
closed forms written here in numpy, against pyElli on the same parameters, and ε1 against a
scipy Kramers–Kronig integration of ε2 (written here in numpy, independently of the library).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad

import layerstack_jax as ls
from layerstack_jax._media.oscillators import HC_EV_NM, CauchyUrbach, CodyLorentz, Drude, Lorentz, TaucLorentz

WL = np.linspace(190.0, 1700.0, 41)
E = HC_EV_NM / WL

LORENTZ = dict(A=[20.0, 5.0], E0=[4.0, 6.5], gamma=[0.5, 1.0], eps_inf=1.7)
DRUDE = dict(Ep=9.0, gamma=0.07, eps_inf=1.3)
TL = dict(Eg=1.5, A=[100.0, 30.0], E0=[3.5, 5.0], C=[2.0, 1.0], eps_inf=1.2)
CL = dict(Eg=1.6, A=100.0, E0=3.6, gamma=2.4, Ep=0.8, Et=1.8, Eu=0.05, eps_inf=1.0)
CU = dict(A=1.5, B=0.01, C=0.001, k0=0.01, Eb=3.0, Eu=0.3)


# ------------------------------------------------------------------ independent numpy references
def tl_eps2_np(E, Eg, A, E0, C):
    """Jellison & Modine (1996) eq. 4, one oscillator."""
    E = np.asarray(E, float)
    above = E > Eg
    Es = np.where(above, E, 1.0)
    out = A * E0 * C * (Es - Eg) ** 2 / (((Es**2 - E0**2) ** 2 + C**2 * Es**2) * Es)
    return np.where(above, out, 0.0)


def cl_eps2_np(x, Eg, A, E0, gamma, Ep, Et, Eu):
    """Ferlauto et al. (2002) eqs. 3–4 (scalar x)."""
    if x <= 0:
        return 0.0

    def G(y):
        return (y - Eg) ** 2 / ((y - Eg) ** 2 + Ep**2)

    def L(y):
        return A * E0 * gamma * y / ((y * y - E0 * E0) ** 2 + gamma**2 * y * y)

    return G(x) * L(x) if x > Et else Et * G(Et) * L(Et) / x * math.exp((x - Et) / Eu)


def kk_eps1(eps2, e, breaks, top=80.0):
    """(2/π) P∫_0^∞ ξ ε2(ξ)/(ξ² − e²) dξ by scipy: QAWC (Cauchy weight) on the segment holding e,
    plain adaptive quadrature elsewhere, and the tail beyond ``top``."""
    pts = sorted({0.0, *[b for b in breaks if 0 < b < top and abs(b - e) > 1e-6 * e], top})
    total = 0.0
    for a, b in zip(pts[:-1], pts[1:]):
        if a < e < b:
            total += quad(lambda x: x * eps2(x) / (x + e), a, b, weight="cauchy", wvar=e, limit=500,
                          epsabs=1e-14, epsrel=1e-13)[0]
        else:
            total += quad(lambda x: x * eps2(x) / (x * x - e * e), a, b, limit=500, epsabs=1e-14, epsrel=1e-13)[0]
    total += quad(lambda x: x * eps2(x) / (x * x - e * e), top, np.inf, limit=500, epsabs=1e-14)[0]
    return 2 / math.pi * total


# ------------------------------------------------------------------ closed forms
def test_lorentz_and_drude_closed_forms():
    eps = np.asarray(Lorentz(**LORENTZ).permittivity(WL))
    ref = LORENTZ["eps_inf"] + sum(
        a / (e0**2 - E**2 - 1j * g * E) for a, e0, g in zip(LORENTZ["A"], LORENTZ["E0"], LORENTZ["gamma"])
    )
    np.testing.assert_allclose(eps, ref, rtol=1e-13)
    assert np.all(eps.imag > 0)
    eps_d = np.asarray(Drude(**DRUDE).permittivity(WL))
    np.testing.assert_allclose(eps_d, DRUDE["eps_inf"] - DRUDE["Ep"] ** 2 / (E**2 + 1j * DRUDE["gamma"] * E), rtol=1e-13)
    # lossless Drude metal below the screened plasma energy: purely imaginary index, +ik (k > 0)
    n = np.asarray(Drude(Ep=9.0, gamma=0.0, eps_inf=1.0)(WL))
    below = E < 9.0
    np.testing.assert_allclose(n[below].real, 0.0, atol=1e-15)
    np.testing.assert_allclose(n[below].imag, np.sqrt(81.0 / E[below] ** 2 - 1), rtol=1e-13)
    # index = sqrt(eps), k >= 0
    nl = np.asarray(Lorentz(**LORENTZ)(WL))
    np.testing.assert_allclose(nl**2, eps, rtol=1e-13)
    assert np.all(nl.imag >= 0)


def test_tauc_lorentz_eps2_closed_form_and_gap():
    eps = np.asarray(TaucLorentz(**TL).permittivity(WL))
    ref = sum(tl_eps2_np(E, TL["Eg"], a, e0, c) for a, e0, c in zip(TL["A"], TL["E0"], TL["C"]))
    np.testing.assert_allclose(eps.imag, ref, rtol=1e-13, atol=1e-15)
    assert np.all(eps.imag[E <= TL["Eg"]] == 0)


def test_cauchy_urbach_closed_form():
    n = np.asarray(CauchyUrbach(**CU)(WL))
    lam = WL * 1e-3
    np.testing.assert_allclose(n.real, CU["A"] + CU["B"] / lam**2 + CU["C"] / lam**4, rtol=1e-14)
    np.testing.assert_allclose(n.imag, CU["k0"] * np.exp((E - CU["Eb"]) / CU["Eu"]), rtol=1e-13)


# ------------------------------------------------------------------ Kramers–Kronig
@pytest.mark.parametrize(
    "pars",
    [dict(Eg=1.5, A=100.0, E0=3.5, C=2.0), dict(Eg=3.2, A=250.0, E0=5.5, C=1.2), dict(Eg=0.8, A=40.0, E0=2.0, C=3.5)],
)
def test_tauc_lorentz_eps1_is_kramers_kronig_of_eps2(pars):
    """Closed-form ε1 − ε∞ equals (2/π) P∫ ξ ε2/(ξ² − E²) dξ (scipy) to 1e-9, also at E = Eg."""
    es = np.array([0.3, 0.9 * pars["Eg"], pars["Eg"], 1.1 * pars["Eg"], pars["E0"], 2.0 * pars["E0"], 9.0])
    model = TaucLorentz(eps_inf=0.0, **{k: [v] if k != "Eg" else v for k, v in pars.items()})
    got = np.asarray(jax.jit(lambda m, w: m.permittivity(w))(model, HC_EV_NM / es)).real

    def eps2(x):
        return float(tl_eps2_np(x, **pars))

    ref = np.array([kk_eps1(eps2, e, [pars["Eg"], pars["E0"]], top=200.0) for e in es])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9 * np.max(np.abs(ref)))


@pytest.mark.parametrize(
    "pars",
    [CL, dict(Eg=1.2, A=50.0, E0=4.5, gamma=1.0, Ep=1.5, Et=1.3, Eu=0.1, eps_inf=1.0),
     dict(Eg=3.0, A=200.0, E0=8.0, gamma=3.0, Ep=1.0, Et=3.5, Eu=0.02, eps_inf=1.0)],
)
def test_cody_lorentz_eps1_is_kramers_kronig_of_eps2(pars):
    """ε1 − ε∞ by the library's jnp quadrature vs scipy's principal-value integral of ε2, ≤ 1e-7
    relative to max |ε1|."""
    p = {k: v for k, v in pars.items() if k != "eps_inf"}
    es = np.array([0.5, 1.0, 0.99 * p["Et"], 1.01 * p["Et"], 2.5, p["E0"], 5.0, 7.0])
    got = np.asarray(jax.jit(lambda m, w: m.permittivity(w))(CodyLorentz(eps_inf=0.0, **p), HC_EV_NM / es)).real

    def eps2(x):
        return cl_eps2_np(x, **p)

    ref = np.array([kk_eps1(eps2, e, [p["Et"], p["E0"]]) for e in es])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-7 * np.max(np.abs(ref)))
    # ε2 against the formula written here
    eps = np.asarray(CodyLorentz(**pars).permittivity(WL))
    np.testing.assert_allclose(eps.imag, [eps2(x) for x in E], rtol=1e-12, atol=1e-300)


# ------------------------------------------------------------------ pyElli, same parameters
def test_against_pyelli_same_parameters():
    """Each model equals pyElli's (0.23) on the same parameters to <= 1e-9 relative (ε or n);
    Cody–Lorentz: ε2 only (pyElli computes its ε1 by an approximate numerical transform on a
    1000-point grid, 0.03 away; ours is checked against scipy above)."""
    elli = pytest.importorskip("elli")

    def close(ours, theirs, tol=1e-9):
        ours, theirs = np.asarray(ours), np.asarray(theirs)
        assert np.max(np.abs(ours - theirs) / np.abs(theirs)) <= tol

    p = elli.LorentzEnergy()
    for a, e0, g in zip(LORENTZ["A"], LORENTZ["E0"], LORENTZ["gamma"]):
        p = p.add(A=a, E=e0, gamma=g)
    # pyElli's LorentzEnergy is 1 + Σ: add ε∞ − 1
    close(Lorentz(**LORENTZ).permittivity(WL), (p + (LORENTZ["eps_inf"] - 1)).get_dielectric(WL))
    p = elli.DrudeEnergy(A=-DRUDE["Ep"] ** 2, gamma=-DRUDE["gamma"]) + DRUDE["eps_inf"]
    close(Drude(**DRUDE).permittivity(WL), p.get_dielectric(WL))
    p = elli.TaucLorentz(Eg=TL["Eg"])
    for a, e0, c in zip(TL["A"], TL["E0"], TL["C"]):
        p = p.add(A=a, E=e0, C=c)
    close(TaucLorentz(**TL).permittivity(WL), (p + TL["eps_inf"]).get_dielectric(WL))
    p = elli.CodyLorentz(**{k: v for k, v in CL.items() if k != "eps_inf"})
    above = E > 1.0  # where ε2 is not vanishingly small
    close(np.asarray(CodyLorentz(**CL).permittivity(WL)).imag[above], p.get_dielectric(WL).imag[above])
    hc_um = HC_EV_NM * 1e-3
    p = elli.CauchyUrbach(n0=CU["A"], B=CU["B"] / hc_um**2, C=CU["C"] / hc_um**4, D=CU["k0"], Eg=CU["Eb"], Eu=CU["Eu"])
    close(CauchyUrbach(**CU)(WL), p.get_refractive_index(WL))
    p = elli.Sellmeier().add(A=0.6961663, B=0.0684043**2).add(A=0.4079426, B=0.1162414**2).add(A=0.8974794, B=9.896161**2)
    sell = ls.Sellmeier([0.6961663, 0.4079426, 0.8974794], [0.0684043**2, 0.1162414**2, 9.896161**2])
    close(sell(WL), p.get_refractive_index(WL))


# ------------------------------------------------------------------ differentiable and fittable
MODELS = {
    "lorentz": (Lorentz, dict(A=20.0, E0=4.5, gamma=0.8, eps_inf=2.0)),
    "drude": (Drude, dict(Ep=3.0, gamma=0.3, eps_inf=2.0)),
    "tauc_lorentz": (TaucLorentz, dict(Eg=2.0, A=80.0, E0=4.0, C=1.5, eps_inf=1.5)),
    "cody_lorentz": (CodyLorentz, dict(Eg=1.6, A=60.0, E0=3.6, gamma=2.4, Ep=0.8, Et=1.8, Eu=0.05, eps_inf=1.2)),
    "cauchy_urbach": (CauchyUrbach, dict(A=1.6, B=0.01, C=0.0005, k0=0.02, Eb=3.5, Eu=0.3)),
}


@pytest.mark.parametrize("name", sorted(MODELS))
def test_index_gradients_wrt_every_parameter_match_central_differences(name):
    """n and k of each model differentiated w.r.t. every parameter (jacfwd) vs central
    differences; all finite, also at the band gap (TL/CL: a wavelength exactly at Eg)."""
    cls, pars = MODELS[name]
    keys = sorted(pars)
    wl = np.array([300.0, 450.0, HC_EV_NM / pars.get("Eg", 2.0), 800.0])

    def f(x):
        n = cls(**{k: x[i] for i, k in enumerate(keys)})(wl)
        return jnp.concatenate([jnp.real(n), jnp.imag(n)])

    x0 = jnp.asarray([float(pars[k]) for k in keys])
    jac = np.asarray(jax.jit(jax.jacfwd(f))(x0))
    assert np.all(np.isfinite(jac))
    fj = jax.jit(f)
    h = 1e-6 * np.maximum(np.abs(np.asarray(x0)), 1.0)
    fd = np.stack([(np.asarray(fj(x0.at[i].add(h[i]))) - np.asarray(fj(x0.at[i].add(-h[i])))) / (2 * h[i])
                   for i in range(x0.size)], axis=-1)
    # atol: at E = Eg, dk/dEg = 0 exactly while the central difference is O(h) (ε2 ∝ (E − Eg)²)
    np.testing.assert_allclose(jac, fd, rtol=1e-5, atol=1e-6 * np.max(np.abs(fd)))


@pytest.mark.slow  # ~50 s: compiles the reverse pass of a five-model stack
def test_ellipsometry_gradient_through_a_stack_of_every_model():
    """ψ, C, S of a stack of five 12 nm films, one of each model, on silicon: reverse-mode
    gradients w.r.t. every model parameter and the common thickness are finite; the thickness
    derivative matches a central difference."""

    def loss(models, d):
        st = ls.Stack(1.0, [ls.Layer(m, d) for m in models], ls.Substrate(ls.Index(3.9, 0.02)))
        e = ls.ellipsometry(st, np.array([300.0, 500.0, 800.0]), 65.0)
        return jnp.sum(e.psi_deg + e.C + e.S)

    models = [cls(**{k: jnp.asarray(float(v)) for k, v in pars.items()}) for cls, pars in MODELS.values()]
    g_rev = jax.jit(jax.grad(loss, argnums=(0, 1)))(models, 12.0)
    leaves = jax.tree_util.tree_leaves(g_rev)
    assert len(leaves) == sum(len(p) for _, p in MODELS.values()) + 1
    assert all(np.isfinite(float(x)) for x in leaves)
    # directional derivative along the thickness: reverse == central difference
    lj = jax.jit(loss)
    fd = (float(lj(models, 12.0 + 1e-4)) - float(lj(models, 12.0 - 1e-4))) / 2e-4
    assert float(g_rev[1]) == pytest.approx(fd, rel=1e-6)


def test_one_compilation_for_new_parameter_values():
    f = jax.jit(lambda m: ls.ellipsometry(ls.Stack(1.0, [ls.Layer(m, 50.0)], ls.Substrate(3.9)), WL, 70.0).psi_deg)
    a = f(TaucLorentz(**TL))
    b = f(TaucLorentz(**{**TL, "Eg": 1.7}))
    assert f._cache_size() == 1 and not np.allclose(a, b)


def test_bad_parameters_raise():
    with pytest.raises(ls.LayerstackError, match="gamma"):
        Lorentz(A=1.0, E0=2.0, gamma=-0.1)
    with pytest.raises(ls.LayerstackError, match="Lorentz"):
        Lorentz(A=[1.0, 2.0], E0=[2.0], gamma=[0.1, 0.1])
    with pytest.raises(ls.LayerstackError, match="TaucLorentz.C"):
        TaucLorentz(Eg=1.0, A=10.0, E0=2.0, C=4.5)
    with pytest.raises(ls.LayerstackError, match="Eu"):
        CodyLorentz(Eg=1.6, A=60.0, E0=3.6, gamma=2.4, Ep=0.8, Et=1.8, Eu=0.0)
    with pytest.raises(ls.LayerstackError, match="CauchyUrbach.k0"):
        CauchyUrbach(A=1.5, k0=-0.1)
    with pytest.raises(ls.LayerstackError, match="Drude.gamma"):
        Drude(Ep=9.0, gamma=-1.0)
    with pytest.warns(ls.LayerstackWarning, match="TaucLorentz.E0"):
        TaucLorentz(Eg=3.0, A=10.0, E0=2.5, C=1.0)
    with pytest.warns(ls.LayerstackWarning, match="CodyLorentz.Et"):
        CodyLorentz(Eg=1.6, A=60.0, E0=3.6, gamma=2.4, Ep=0.8, Et=1.0, Eu=0.05)
