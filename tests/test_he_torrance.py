"""He–Torrance rough boundary (layerstack_jax/_appearance/he_torrance.py).

References, none computed with the code under test:
* an independent implementation of He et al. (1991) written here with numpy/scipy: the
  effective roughness by root-finding (scipy.optimize.brentq) on He's implicit equation for z0,
  Smith's Λ as printed, Fresnel factors from ``tmm.interface_r``, the geometrical factor G from
  explicit s/p polarization vectors, and the D series summed until its terms vanish;
* scipy.special.lambertw; Gauss–Legendre quadrature of the directional albedo;
* energy: near-specular lobe of a slightly rough perfect mirror integrates to 1 − e^{−g};
* central finite differences for the gradients.
"""

from __future__ import annotations

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tmm
from scipy import optimize, special

import layerstack_jax as ls
from layerstack_jax._appearance.he_torrance import he_torrance_brdf, lambert_w0, series_terms

# ----------------------------------------------------------------------------- reference


def ref_shadow(theta, sigma0, tau, form):
    """Smith's S(θ) as printed (He et al.; form 'smith') or 1/(1 + Λ) ('corrected')."""
    if sigma0 == 0 or theta == 0:
        return 1.0
    a = tau / (2 * sigma0 * math.tan(theta))
    lam = 0.5 * (math.exp(-a * a) / (a * math.sqrt(math.pi)) - special.erfc(a))
    s = 1.0 / (1.0 + lam)
    return s * (1 - 0.5 * special.erfc(a)) if form == "smith" else s


def ref_sigma(theta_i, theta_r, sigma0, tau):
    """Effective roughness from He's implicit equation, solved with brentq."""
    if sigma0 == 0:
        return 0.0

    def K(t):
        return 0.0 if t == 0 else math.tan(t) * special.erfc(tau / (2 * sigma0 * math.tan(t)))

    Ks = K(theta_i) + K(theta_r)
    if Ks == 0:
        return sigma0
    f = lambda z0: math.sqrt(math.pi / 2) * z0 - sigma0 / 4 * Ks * math.exp(-z0 * z0 / (2 * sigma0 * sigma0))
    z0 = optimize.brentq(f, 0.0, sigma0 * Ks, xtol=1e-300, rtol=1e-15, maxiter=500)
    return sigma0 / math.sqrt(1 + (z0 / sigma0) ** 2)


def ref_D(g, vxy, tau, lam_medium):
    """D with the series summed until the terms are negligible (no fixed truncation)."""
    total, m, term_g = 0.0, 1, math.exp(-g)
    while True:
        term_g *= g / m  # g^m e^-g / m!
        term = term_g / m * math.exp(-(vxy * tau) ** 2 / (4 * m))
        total += term
        if m > g and term_g < 1e-22:
            break
        m += 1
    return math.pi ** 2 * tau ** 2 / (4 * lam_medium ** 2) * total


def ref_brdf(n_a, n_b, wl, ti, tr, phi, sigma0, tau, form="corrected"):
    """(specular reflectance, directional-diffuse BRDF) of He et al., natural light."""
    lam = wl / n_a  # wavelength in the medium of incidence
    k = 2 * math.pi / lam
    ki = np.array([math.sin(ti), 0.0, -math.cos(ti)])
    kr = np.array([math.sin(tr) * math.cos(phi), math.sin(tr) * math.sin(phi), math.cos(tr)])
    z = np.array([0.0, 0.0, 1.0])
    # specular
    F2_spec = np.mean([abs(tmm.interface_r(p, n_a, n_b, ti, tmm.snell(n_a, n_b, ti))) ** 2 for p in "sp"])
    sig_s = ref_sigma(ti, ti, sigma0, tau)
    g_s = (k * sig_s * 2 * math.cos(ti)) ** 2
    spec = F2_spec * math.exp(-g_s) * ref_shadow(ti, sigma0, tau, form) ** 2
    # directional diffuse
    v = kr - ki
    cos_loc = np.linalg.norm(v) / 2
    th_loc = math.acos(min(cos_loc, 1.0))
    F2 = np.mean([abs(tmm.interface_r(p, n_a, n_b, th_loc, tmm.snell(n_a, n_b, th_loc))) ** 2 for p in "sp"])
    s_i = np.cross(ki, z)
    s_i /= np.linalg.norm(s_i)
    p_i = np.cross(s_i, ki)
    s_r = np.cross(kr, z)
    s_r /= np.linalg.norm(s_r)
    p_r = np.cross(s_r, kr)
    cr = np.linalg.norm(np.cross(kr, ki))
    G = (v @ v / v[2]) ** 2 / cr ** 4 * ((s_r @ ki) ** 2 + (p_r @ ki) ** 2) * ((s_i @ kr) ** 2 + (p_i @ kr) ** 2)
    sig = ref_sigma(ti, tr, sigma0, tau)
    g = (k * sig * (math.cos(ti) + math.cos(tr))) ** 2
    D = ref_D(g, k * math.hypot(v[0], v[1]), tau, lam)
    S = ref_shadow(ti, sigma0, tau, form) * ref_shadow(tr, sigma0, tau, form)
    dd = F2 * G * S * D / (math.pi * math.cos(ti) * math.cos(tr))
    return spec, dd


# ----------------------------------------------------------------------------- tests


def test_lambert_w0_against_scipy_and_its_derivative():
    z = np.array([0.0, 1e-12, 1e-3, 0.3, 1.0, 2.718, 10.0, 1e3, 1e8, 1e30, 1e200])
    w = np.asarray(lambert_w0(jnp.asarray(z)))
    ref = special.lambertw(z).real
    np.testing.assert_allclose(w, ref, rtol=2e-15, atol=1e-300)
    zz = np.array([1e-3, 0.5, 3.0, 100.0])
    dw = np.asarray(jax.vmap(jax.grad(lambert_w0))(jnp.asarray(zz)))
    h = 1e-6 * zz
    fd = (special.lambertw(zz + h).real - special.lambertw(zz - h).real) / (2 * h)
    np.testing.assert_allclose(dw, fd, rtol=1e-8)


CASES = [  # n_b, wavelength, sigma0, tau
    (complex(1.2, 7.0), 550.0, 25.0, 300.0),  # silver-like
    (complex(3.9, 0.02), 450.0, 50.0, 300.0),  # silicon-like
    (1.5, 700.0, 10.0, 150.0),  # glass
    (complex(0.2, 3.5), 400.0, 80.0, 400.0),  # larger g
]


@pytest.mark.parametrize("form", ["corrected", "smith"])
@pytest.mark.parametrize("case", CASES)
def test_against_independent_implementation(case, form):
    n_b, wl, sigma0, tau = case
    rng = np.random.default_rng(7)
    ti = rng.uniform(3, 87, 12)
    tr = rng.uniform(3, 87, 12)
    ph = rng.uniform(0, 360, 12)
    out = he_torrance_brdf(np.array([wl]), ti, tr, ph, n_substrate=n_b, sigma_nm=sigma0, tau_nm=tau,
                           shadowing_form=form)
    for j in range(12):
        spec, dd = ref_brdf(1.0, n_b, wl, math.radians(ti[j]), math.radians(tr[j]), math.radians(ph[j]), sigma0, tau,
                            form)
        assert float(out.specular[j, 0]) == pytest.approx(spec, rel=1e-8, abs=1e-300)
        assert float(out.directional_diffuse[j, 0]) == pytest.approx(dd, rel=1e-8, abs=1e-300)


def test_against_reference_in_a_denser_ambient():
    """The boundary seen from a film (n_a = 1.4): k = 2π n_a/λ and Fresnel from n_a."""
    ti, tr, ph = 25.0, 50.0, 120.0
    out = he_torrance_brdf(np.array([500.0]), ti, tr, ph, n_substrate=complex(1.2, 7.0), n_ambient=1.4,
                           sigma_nm=30.0, tau_nm=300.0)
    spec, dd = ref_brdf(1.4, complex(1.2, 7.0), 500.0, *np.radians([ti, tr, ph]), 30.0, 300.0)
    assert float(out.specular[0]) == pytest.approx(spec, rel=1e-8)
    assert float(out.directional_diffuse[0]) == pytest.approx(dd, rel=1e-8)


@pytest.mark.parametrize("form", ["corrected", "smith"])
def test_reciprocity(form):
    rng = np.random.default_rng(3)
    ti, to, ph = rng.uniform(0, 89.9, 50), rng.uniform(0, 89.9, 50), rng.uniform(0, 360, 50)
    wl = np.array([400.0, 550.0, 700.0])
    kw = dict(n_substrate=complex(0.3, 3.0), sigma_nm=40.0, tau_nm=300.0, shadowing_form=form)
    a = np.asarray(he_torrance_brdf(wl, ti, to, ph, **kw).directional_diffuse)
    b = np.asarray(he_torrance_brdf(wl, to, ti, ph, **kw).directional_diffuse)
    assert np.all(a > 0)
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=0)


def _albedo(n_b, sigma0, wl=500.0, tau=300.0, nodes=(96, 48)):
    """Directional albedo (specular + ∫ ρ_dd cos θ dω) at the incidence angles ANGLES, by
    Gauss–Legendre in cos θ and φ (96 × 48 nodes agree with 400 × 160 to 1e-8 on these lobes).
    One compiled shape for every call (fixed node counts, angles and series length)."""
    x, wx = np.polynomial.legendre.leggauss(nodes[0])
    mu, wmu = 0.5 * (x + 1), 0.5 * wx
    p, wp = np.polynomial.legendre.leggauss(nodes[1])
    phi, wphi = 0.5 * np.pi * (p + 1), np.pi * wp  # φ ∈ [0, π], doubled (even in φ)
    out = he_torrance_brdf(np.array([wl]), ANGLES[:, None, None], np.degrees(np.arccos(mu))[None, :, None],
                           np.degrees(phi)[None, None, :], n_substrate=n_b, sigma_nm=sigma0, tau_nm=tau, n_terms=96)
    dd = np.asarray(out.directional_diffuse)[..., 0]
    return np.asarray(out.specular)[:, 0, 0, 0] + np.einsum("abc,b,c->a", dd, mu * wmu, wphi)


ANGLES = np.array([0.0, 15.0, 30.0, 45.0, 60.0, 70.0, 75.0, 80.0, 85.0, 89.0])


@pytest.mark.parametrize("n_b", [1.33, 1.5, 2.4])
def test_albedo_of_lossless_dielectric_below_one(n_b):
    for ratio in (0.01, 0.05, 0.1, 0.2, 0.3):
        a = _albedo(n_b, ratio * 500.0)
        assert np.all(a <= 1.0), (ratio, a)
        assert np.all(a > 0)


def test_albedo_of_perfect_mirror_is_not_bounded_by_one():
    """The model is a single-scattering Kirchhoff approximation: for |F| = 1 the directional
    albedo exceeds 1. Measured (corrected shadowing, τ = 300 nm, λ = 500 nm): at σ0/λ = 0.01
    4.9e-4 at 60°, rising to 5.4e-3 at 85°; at σ0/λ = 0.1 up to 10.0% at 70° (9.4% at 75°, the
    node checked below). At normal incidence it stays below 1 (1 − 2.4e-5 at σ0/λ = 0.01).
    Recorded here so that a change shows."""
    mirror = complex(1.0, 1e6)  # |r| = 1 to 1e-6
    small = _albedo(mirror, 5.0)
    np.testing.assert_allclose(small[[0, 4, 8]], [0.99997612, 1.00048787, 1.0054382], atol=2e-6)
    large = _albedo(mirror, 50.0)
    assert large[6] == pytest.approx(1.09355532, abs=2e-6)
    assert large[0] < 1.0


def test_near_specular_lobe_carries_what_the_specular_term_loses():
    """Slightly rough mirror at normal incidence: specular e^{-g} plus the lobe = 1 − O(g²)
    (fixes the normalisation (kτ)²/16 of D: G ρ cos θ_r integrates exactly over the
    transverse wavevector there)."""
    mirror = complex(1.0, 1e6)
    for sigma0 in (1.0, 3.0):
        a = _albedo(mirror, sigma0, tau=600.0)
        g = (4 * math.pi * sigma0 / 500.0) ** 2
        assert abs(a[0] - 1.0) < 2 * g * g, (sigma0, a[0], g)


def test_smooth_limit_is_fresnel():
    wl = np.array([400.0, 600.0])
    th = np.array([0.0, 30.0, 60.0, 89.0, 90.0])
    out = he_torrance_brdf(wl, th, th, 0.0, n_substrate=complex(0.2, 3.5), sigma_nm=0.0, tau_nm=300.0)
    ref = [[np.mean([abs(tmm.interface_r(p, 1.0, complex(0.2, 3.5), t, tmm.snell(1.0, complex(0.2, 3.5), t))) ** 2
                     for p in "sp"]) for _ in wl] for t in np.radians(th)]
    np.testing.assert_allclose(np.asarray(out.specular), ref, rtol=1e-12, atol=1e-15)
    assert np.all(np.asarray(out.directional_diffuse) == 0)


def test_gradients_against_finite_differences_and_nan_free():
    wl = jnp.array([450.0, 620.0])

    def total(sigma0, tau, wl, ti=35.0, to=55.0, ph=20.0):
        out = he_torrance_brdf(wl, ti, to, ph, n_substrate=complex(1.2, 7.0), sigma_nm=sigma0, tau_nm=tau, n_terms=48)
        return jnp.sum(out.directional_diffuse) + jnp.sum(out.specular)

    total = jax.jit(total)
    grads = jax.grad(total, argnums=(0, 1, 2))(30.0, 300.0, wl)
    h = 1e-3
    fd_s = (total(30.0 + h, 300.0, wl) - total(30.0 - h, 300.0, wl)) / (2 * h)
    fd_t = (total(30.0, 300.0 + h, wl) - total(30.0, 300.0 - h, wl)) / (2 * h)
    e = jnp.array([1.0, 0.0])
    fd_w = (total(30.0, 300.0, wl + h * e) - total(30.0, 300.0, wl - h * e)) / (2 * h)
    assert float(grads[0]) == pytest.approx(float(fd_s), rel=1e-6)
    assert float(grads[1]) == pytest.approx(float(fd_t), rel=1e-6)
    assert float(grads[2][0]) == pytest.approx(float(fd_w), rel=1e-6)
    # σ0 = 0, normal and grazing directions: finite values and gradients
    for ti, to in ((0.0, 0.0), (90.0, 30.0), (89.9999, 90.0), (0.0, 90.0)):
        for s in (0.0, 25.0):
            g = jax.grad(total, argnums=(0, 1, 2))(s, 300.0, wl, ti, to)
            assert all(np.all(np.isfinite(np.asarray(x))) for x in g), (ti, to, s, g)


def test_series_terms_cover_the_poisson_mass():
    for g in (0.01, 1.0, 5.0, 20.0, 60.0):
        m = series_terms(g)
        tail = special.pdtrc(m, g)  # P(X > m)
        assert tail <= 1e-15 * -math.expm1(-g)


def test_bad_input_is_rejected():
    wl = np.array([500.0])
    with pytest.raises(ls.LayerstackError, match="sigma_nm"):
        he_torrance_brdf(wl, 10.0, 10.0, n_substrate=1.5, sigma_nm=-1.0, tau_nm=300.0)
    with pytest.raises(ls.LayerstackError, match="tau_nm"):
        he_torrance_brdf(wl, 10.0, 10.0, n_substrate=1.5, sigma_nm=10.0, tau_nm=0.0)
    with pytest.raises(ls.LayerstackError, match="incidence_deg"):
        he_torrance_brdf(wl, 95.0, 10.0, n_substrate=1.5, sigma_nm=10.0, tau_nm=300.0)
    with pytest.raises(ls.LayerstackError, match="shadowing_form"):
        he_torrance_brdf(wl, 10.0, 10.0, n_substrate=1.5, sigma_nm=10.0, tau_nm=300.0, shadowing_form="x")
    with pytest.raises(ls.LayerstackError, match="n_ambient"):
        he_torrance_brdf(wl, 10.0, 10.0, n_substrate=1.5, n_ambient=complex(1.0, 0.1), sigma_nm=10.0, tau_nm=300.0)
    with pytest.warns(UserWarning, match="slope"):
        he_torrance_brdf(wl, 10.0, 10.0, n_substrate=1.5, sigma_nm=200.0, tau_nm=300.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        he_torrance_brdf(wl, 10.0, 10.0, n_substrate=1.5, sigma_nm=50.0, tau_nm=300.0)


def test_polarized_outputs_against_reference():
    ti, tr, ph = 40.0, 20.0, 200.0
    out = he_torrance_brdf(np.array([500.0]), ti, tr, ph, n_substrate=complex(3.9, 0.02), sigma_nm=30.0,
                           tau_nm=300.0, polarized=True)
    assert out.specular.shape == (2, 1)
    nat = he_torrance_brdf(np.array([500.0]), ti, tr, ph, n_substrate=complex(3.9, 0.02), sigma_nm=30.0, tau_nm=300.0)
    np.testing.assert_allclose(np.mean(np.asarray(out.directional_diffuse), axis=0), np.asarray(nat.directional_diffuse),
                               rtol=1e-14)
    spec, dd = ref_brdf(1.0, complex(3.9, 0.02), 500.0, *np.radians([ti, tr, ph]), 30.0, 300.0)
    assert float(np.mean(out.specular)) == pytest.approx(spec, rel=1e-8)
    assert float(out.specular[0, 0]) > float(out.specular[1, 0])  # s above p off normal
