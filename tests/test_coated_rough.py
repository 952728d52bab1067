"""Smooth films on a rough object (Hirayama §4.2, layerstack_jax/_appearance/coated_rough.py) and the
renderer tables (layerstack_jax/_appearance/render_tables.py).

References, none computed with the code under test:
* ``ls.specular`` (the smooth stack) for the σ0 → 0 limit;
* explicit sums of Hirayama's geometric series (eq. 11 for the diffuse amplitude, eq. 18 for the
  specular one), m up to convergence, with Fresnel amplitudes from ``tmm.interface_r/t`` and the
  rough boundary from the independent He–Torrance implementation of tests/test_he_torrance.py;
* reciprocity; direct evaluation of the model for the tables (layout and interpolation error).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tmm
from test_he_torrance import ref_D, ref_shadow, ref_sigma

import layerstack_jax as ls
from layerstack_jax._appearance.coated_rough import coated_rough
from layerstack_jax._appearance.he_torrance import he_torrance_brdf
from layerstack_jax._appearance.render_tables import (CoatingTables, angle_grid, coating_tables, interpolate_k_d, interpolate_k_r,
                                           interpolate_k_t)

SILVER = complex(0.05, 4.0)  # ~ Ag at 550 nm (fixed: the tests need no dispersion)
ALUMINIUM = complex(0.96, 6.69)  # ~ Al at 550 nm
WL = np.array([500.0, 515.0, 530.0, 545.0])  # steps resolve the 2 µm fringes (no aliasing warning)


def hirayama_stack(metal_film=SILVER, obj=ALUMINIUM):
    """Fig. 8 / Table 1 (teapot): air · dielectric 1.4 (1000 nm) · metal (5 nm) · 1.4 (1000 nm) · object."""
    return ls.Stack(ambient=1.0, layers=[ls.Layer(1.4, 1000.0), ls.Layer(ls.Index(metal_film.real, metal_film.imag), 5.0),
                                         ls.Layer(1.4, 1000.0)],
                    exit=ls.Substrate(ls.Index(obj.real, obj.imag)))


def single_film(n1=1.4, d=300.0, obj=ALUMINIUM):
    return ls.Stack(ambient=1.0, layers=[ls.Layer(n1, d)], exit=ls.Substrate(ls.Index(obj.real, obj.imag)))


# ----------------------------------------------------------------------------- smooth limit


@pytest.mark.parametrize("sigma0", [0.0, 1e-6])
def test_smooth_limit_equals_the_smooth_stack(sigma0):
    th = np.array([0.0, 20.0, 45.0, 70.0, 89.0])
    for stack in (hirayama_stack(), ls.Stack(ambient=1.0, layers=[ls.Layer(2.0, 120.0), ls.Layer(1.38, 90.0)],
                                             exit=ls.Substrate(1.52))):
        out = coated_rough(stack, WL, th, th[::-1], 30.0, sigma_nm=sigma0, tau_nm=300.0)
        ref = ls.specular(stack, WL, th).natural()
        np.testing.assert_allclose(np.asarray(out.k_r), np.asarray(ref.R_front), rtol=0, atol=1e-10)
        np.testing.assert_allclose(np.asarray(out.k_t), np.asarray(ref.T_front) * (stack.exit.index.k == 0),
                                   rtol=0, atol=1e-10)
        assert np.max(np.abs(np.asarray(out.k_d))) <= 1e-12


# ----------------------------------------------------------------------------- explicit series


def _fresnel(pol, n_i, n_f, th_i):
    th_f = tmm.snell(n_i, n_f, th_i)
    return tmm.interface_r(pol, n_i, n_f, th_i, th_f), tmm.interface_t(pol, n_i, n_f, th_i, th_f), th_f


def _rho_pol(pol, n1, n_obj, wl, t1_in, t1_out, phi, sigma0, tau):
    """He–Torrance directional diffuse in the film (independent implementation), one polarization."""
    lam = wl / n1
    k = 2 * math.pi / lam
    ki = np.array([math.sin(t1_in), 0.0, -math.cos(t1_in)])
    kr = np.array([math.sin(t1_out) * math.cos(phi), math.sin(t1_out) * math.sin(phi), math.cos(t1_out)])
    v = kr - ki
    th_loc = math.acos(min(np.linalg.norm(v) / 2, 1.0))
    F2 = abs(_fresnel(pol, n1, n_obj, th_loc)[0]) ** 2
    G = (v @ v / v[2]) ** 2
    sig = ref_sigma(t1_in, t1_out, sigma0, tau)
    g = (k * sig * (math.cos(t1_in) + math.cos(t1_out))) ** 2
    D = ref_D(g, k * math.hypot(v[0], v[1]), tau, lam)
    S = ref_shadow(t1_in, sigma0, tau, "corrected") * ref_shadow(t1_out, sigma0, tau, "corrected")
    return F2 * G * S * D / (math.pi * math.cos(t1_in) * math.cos(t1_out))


def _eta_s(pol, n1, n_obj, wl, t1, sigma0, tau):
    r = _fresnel(pol, n1, n_obj, t1)[0]
    k = 2 * math.pi * n1 / wl
    sig = ref_sigma(t1, t1, sigma0, tau)
    return r * math.exp(-0.5 * (2 * k * sig * math.cos(t1)) ** 2) * ref_shadow(t1, sigma0, tau, "corrected")


def _geometric_sum(first, ratio):
    """Σ_{m≥1} first · ratio^{m−1}, summed term by term until the terms vanish."""
    total, term = 0.0, first
    for _ in range(100000):
        total += term
        if abs(term) < 1e-19 * max(abs(total), 1e-300):
            return total
        term *= ratio
    raise AssertionError("series did not converge")


def explicit_single_film(n1, d, n_obj, wl, th_in, th_out, phi, sigma0, tau):
    """(k_r at th_in, literal k_d, radiometric k_d) of air · film · rough object by explicit sums."""
    k_r, lit, rad = 0.0, 0.0, 0.0
    for pol in "sp":
        r_l, t_l, t1_l = _fresnel(pol, 1.0, n1, th_in)  # light (Hirayama's ω_l)
        _, t_v, t1_v = _fresnel(pol, 1.0, n1, th_out)  # viewing ray (Hirayama's ω_i)
        t1_l, t1_v = t1_l.real, t1_v.real
        ph_l = 2 * math.pi * n1 * d * math.cos(t1_l) / wl
        ph_v = 2 * math.pi * n1 * d * math.cos(t1_v) / wl
        eta_l = _eta_s(pol, n1, n_obj, wl, t1_l, sigma0, tau)
        rho = _rho_pol(pol, n1, n_obj, wl, t1_l, t1_v, phi, sigma0, tau)
        # eq. 18 with the rough seed: γ = r1 + Σ t1 η (r1' η)^{m−1} t1' e^{2iφ m}
        t_back = _fresnel(pol, n1, 1.0, t1_l)[1]
        gamma = r_l + _geometric_sum(t_l * eta_l * t_back * np.exp(2j * ph_l), -r_l * eta_l * np.exp(2j * ph_l))
        k_r += 0.5 * abs(gamma) ** 2
        # eq. 11–14: E = Σ Γ Λ^{m−1}, Λ = −r η_s e^{2iφ_l}, Γ = (n1 s_z1/n0 s_z0) t(θ_i) t(θ_l) η_d Φ
        lam_ = -r_l * eta_l * np.exp(2j * ph_l)
        pref = n1 * math.cos(t1_v) / math.cos(th_out)  # read at the viewing direction
        Gam = pref * t_v * t_l * math.sqrt(rho) * np.exp(1j * (ph_l + ph_v))
        lit += 0.5 * abs(_geometric_sum(Gam, lam_)) ** 2
        # radiometric: T↓ = (n1 cos θ1 / cos θ0)|t e^{iφ} Σ Λ^m|² each way, (n0/n1)² ρ
        def t_down(t, ph, eta, r, t1, th0):
            amp = _geometric_sum(t * np.exp(1j * ph), -r * eta * np.exp(2j * ph))
            return n1 * math.cos(t1) / math.cos(th0) * abs(amp) ** 2

        r_v = _fresnel(pol, 1.0, n1, th_out)[0]
        eta_v = _eta_s(pol, n1, n_obj, wl, t1_v, sigma0, tau)
        T_l = t_down(t_l, ph_l, eta_l, r_l, t1_l, th_in)
        T_v = t_down(t_v, ph_v, eta_v, r_v, t1_v, th_out)
        rad += 0.5 * T_l * rho * T_v / n1 ** 2
    return k_r, lit, rad


@pytest.mark.parametrize("case", [
    (1.4, 300.0, ALUMINIUM, 550.0, 20.0, 50.0, 30.0, 25.0, 300.0),
    (2.0, 1000.0, complex(3.9, 0.02), 480.0, 60.0, 10.0, 150.0, 50.0, 300.0),
    (1.4, 1000.0, SILVER, 650.0, 75.0, 40.0, 0.0, 10.0, 200.0),
])
def test_single_film_against_explicit_geometric_series(case):
    n1, d, n_obj, wl, th_in, th_out, phi, sigma0, tau = case
    stack = single_film(n1, d, n_obj)
    ref_r, ref_lit, ref_rad = explicit_single_film(n1, d, n_obj, wl, math.radians(th_in), math.radians(th_out),
                                                   math.radians(phi), sigma0, tau)
    kw = dict(sigma_nm=sigma0, tau_nm=tau)
    lit = coated_rough(stack, np.array([wl]), th_in, th_out, phi, form="literal", **kw)
    rad = coated_rough(stack, np.array([wl]), th_in, th_out, phi, **kw)
    assert float(rad.k_r[0]) == pytest.approx(ref_r, rel=1e-10)
    assert float(lit.k_d[0]) == pytest.approx(ref_lit, rel=1e-10)
    assert float(rad.k_d[0]) == pytest.approx(ref_rad, rel=1e-10)


# ----------------------------------------------------------------------------- properties


def test_radiometric_form_is_reciprocal_and_the_literal_one_is_not():
    rng = np.random.default_rng(5)
    ti, to, ph = rng.uniform(0, 89, 30), rng.uniform(0, 89, 30), rng.uniform(0, 360, 30)
    stack = hirayama_stack()
    kw = dict(sigma_nm=25.0, tau_nm=300.0, uniform_albedo=0.1)
    a = np.asarray(coated_rough(stack, WL, ti, to, ph, **kw).k_d)
    b = np.asarray(coated_rough(stack, WL, to, ti, ph, **kw).k_d)
    assert np.all(a > 0)
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=0)
    la = np.asarray(coated_rough(stack, WL, ti, to, ph, form="literal", **kw).k_d)
    lb = np.asarray(coated_rough(stack, WL, to, ti, ph, form="literal", **kw).k_d)
    assert np.max(np.abs(la - lb) / lb) > 0.1


def test_grazing_viewing_radiometric_vanishes_literal_does_not():
    """Literal eqs. 15–17 (prefactor read at the viewing direction): |t(θ_v)|²/cos²θ_v stays
    finite as θ_v → 90°, so k_d does not fall to zero at grazing viewing (at exactly 90° it is
    0/0, returned as 0); the radiometric form falls like cos θ_v."""
    stack = single_film(obj=complex(3.9, 0.02))
    kw = dict(sigma_nm=25.0, tau_nm=300.0)
    views = np.array([30.0, 89.99, 90.0])
    rad = np.asarray(coated_rough(stack, WL, 30.0, views, 0.0, **kw).k_d)
    lit = np.asarray(coated_rough(stack, WL, 30.0, views, 0.0, form="literal", **kw).k_d)
    assert np.all(rad[1] / rad[0] < 1e-3) and np.all(rad[2] == 0)
    assert np.all(lit[1] / lit[0] > 0.05)


def test_bare_object_both_forms_are_he_torrance():
    stack = ls.Stack(ambient=1.0, layers=[], exit=ls.Substrate(ls.Index(ALUMINIUM.real, ALUMINIUM.imag)))
    kw = dict(sigma_nm=30.0, tau_nm=300.0)
    ht = he_torrance_brdf(WL, 35.0, 50.0, 20.0, n_substrate=ALUMINIUM, **kw)
    for form in ("radiometric", "literal"):
        out = coated_rough(stack, WL, 35.0, 50.0, 20.0, form=form, **kw)
        np.testing.assert_allclose(np.asarray(out.k_d), np.asarray(ht.directional_diffuse), rtol=1e-12)
        np.testing.assert_allclose(np.asarray(out.k_r), np.asarray(ht.specular), rtol=1e-12)


def test_roughness_lowers_the_specular_reflectance_of_the_coating():
    """Hirayama's mechanism (§6): the specular reflectance of the coated aluminium (Fig. 8 stack,
    fixed indices) drops several-fold at σ0 = 25–50 nm (τ = 300 nm). Measured at normal
    incidence, mean over 420–700 nm: smooth 0.877, σ0 = 25 nm 0.530 (÷1.65), σ0 = 50 nm 0.223
    (÷3.9); bare aluminium 0.921 -> 0.661 (÷1.39) -> 0.259 (÷3.6): inside the n = 1.4 film the
    wavenumber, hence g, is larger. At σ0 = 25 nm k_r runs from 0.18 (420 nm) to 0.75 (700 nm):
    the specular/diffuse split follows σ0/λ."""
    wl = np.linspace(420.0, 700.0, 57)
    stack = hirayama_stack()
    k_r = [np.asarray(coated_rough(stack, wl, 0.0, 0.0, sigma_nm=s, tau_nm=300.0).k_r) for s in (0.0, 25.0, 50.0)]
    means = [float(np.mean(x)) for x in k_r]
    np.testing.assert_allclose(means, [0.8769, 0.5301, 0.2226], atol=2e-4)
    assert k_r[1][0] < 0.2 and k_r[1][-1] > 0.7
    kd = np.asarray(coated_rough(stack, wl, 0.0, 0.0, sigma_nm=25.0, tau_nm=300.0).k_d)
    assert kd.max() / kd.min() > 10  # wavelength-dependent lobe


def test_gradients_finite_and_match_finite_differences():
    stack = hirayama_stack()
    th = jnp.array([0.0, 45.0, 89.9999, 90.0])

    @jax.jit
    def total(sigma0, tau, d):
        st = ls.Stack(ambient=1.0, layers=[ls.Layer(1.4, d), *stack.layers[1:]], exit=stack.exit)
        out = coated_rough(st, WL, th, th[::-1], 30.0, sigma_nm=sigma0, tau_nm=tau, n_terms=48)
        return jnp.sum(out.k_d) + jnp.sum(out.k_r)

    for s in (0.0, 25.0):
        g = jax.grad(total, argnums=(0, 1, 2))(s, 300.0, 1000.0)
        assert all(np.isfinite(float(x)) for x in g), g
    g = jax.grad(total, argnums=(0, 1, 2))(25.0, 300.0, 1000.0)
    h = 1e-3
    fd = [(total(25.0 + h, 300.0, 1000.0) - total(25.0 - h, 300.0, 1000.0)) / (2 * h),
          (total(25.0, 300.0 + h, 1000.0) - total(25.0, 300.0 - h, 1000.0)) / (2 * h),
          (total(25.0, 300.0, 1000.0 + h) - total(25.0, 300.0, 1000.0 - h)) / (2 * h)]
    for a, b in zip(g, fd):
        assert float(a) == pytest.approx(float(b), rel=1e-6, abs=1e-9)


def test_bad_input_is_rejected():
    bg = ls.Stack(ambient=1.0, layers=[ls.Layer(1.4, 100.0)], exit=ls.LambertianBackground(1.5, 0.8))
    with pytest.raises(ls.LayerstackError, match="Substrate"):
        coated_rough(bg, WL, 0.0, 0.0, sigma_nm=10.0, tau_nm=300.0)
    thick = ls.Stack(ambient=1.0, layers=[ls.Layer(1.5, 1e5, coherent=False)], exit=ls.Substrate(ALUMINIUM))
    with pytest.raises(ls.LayerstackError, match="coherent"):
        coated_rough(thick, WL, 0.0, 0.0, sigma_nm=10.0, tau_nm=300.0)
    with pytest.raises(ls.LayerstackError, match="form"):
        coated_rough(single_film(), WL, 0.0, 0.0, sigma_nm=10.0, tau_nm=300.0, form="x")
    with pytest.raises(ls.LayerstackError, match="sigma_nm"):
        coated_rough(single_film(), WL, 0.0, 0.0, sigma_nm=-1.0, tau_nm=300.0)
    with pytest.warns(ls.LayerstackWarning, match="absorbs"):
        coated_rough(ls.Stack(ambient=1.0, layers=[ls.Layer(ls.Index(1.4, 0.1), 50.0)], exit=ls.Substrate(ALUMINIUM)),
                     WL, 0.0, 0.0, sigma_nm=10.0, tau_nm=300.0)


# ----------------------------------------------------------------------------- tables


@pytest.fixture(scope="module")
def small_tables():
    wl = np.linspace(400.0, 700.0, 13)
    return coating_tables(hirayama_stack(), wl, n_angles=10, n_angles_out=8, n_phi=7, sigma_nm=25.0, tau_nm=300.0,
                          uniform_albedo=0.05, block=4, error_stride=2)


def test_tables_layout(small_tables):
    t = small_tables
    assert isinstance(t, CoatingTables)
    A, B, P, L = 10, 8, 7, 13
    assert t.k_r.shape == t.k_t.shape == (A, L) and t.k_d.shape == (A, B, P, L)
    assert t.cos_theta.shape == (A,) and t.cos_theta_out.shape == (B,) and t.phi_out.shape == (P,)
    for x in (t.wavelength_nm, t.cos_theta, t.cos_theta_out, t.phi_out, t.k_r, t.k_t, t.k_d):
        assert isinstance(x, np.ndarray) and x.dtype == np.float64
    assert np.all(np.diff(t.cos_theta) > 0) and 0 < t.cos_theta[0] and t.cos_theta[-1] == 1.0
    assert t.phi_out[0] == 0.0 and t.phi_out[-1] == pytest.approx(math.pi)
    assert np.all(t.k_t == 0)  # opaque object
    assert np.all(t.k_d >= 0) and np.all((t.k_r >= 0) & (t.k_r <= 1))
    assert np.isfinite(t.interpolation_error) and t.interpolation_error == max(t.interpolation_error_k_r,
                                                                                t.interpolation_error_k_d)


def test_tables_at_nodes_are_direct_evaluations(small_tables):
    """Axis order of the contract: k_d[a, b, p, l] = k_d(cos_theta[a], cos_theta_out[b], phi_out[p], λ[l])."""
    t = small_tables
    th_i = np.degrees(np.arccos(t.cos_theta))[:, None, None]
    th_o = np.degrees(np.arccos(t.cos_theta_out))[None, :, None]
    ph = np.degrees(t.phi_out)[None, None, :]
    out = coated_rough(hirayama_stack(), t.wavelength_nm, th_i, th_o, ph, sigma_nm=25.0, tau_nm=300.0,
                       uniform_albedo=0.05)
    np.testing.assert_allclose(t.k_d, np.asarray(out.k_d), rtol=1e-12, atol=0)
    np.testing.assert_allclose(t.k_r, np.asarray(out.k_r)[:, 0, 0, :], rtol=1e-12, atol=0)
    # and the interpolation helpers reproduce the nodes
    np.testing.assert_allclose(interpolate_k_r(t, t.cos_theta[:, None], t.wavelength_nm[None]), t.k_r, rtol=1e-14)
    np.testing.assert_allclose(interpolate_k_t(t, t.cos_theta[:, None], t.wavelength_nm[None]), t.k_t, atol=0)


def test_tables_interpolation_within_the_stated_error(small_tables):
    t = small_tables
    rng = np.random.default_rng(11)
    n = 40
    ci = rng.uniform(t.cos_theta[0], 1.0, n)
    co = rng.uniform(t.cos_theta_out[0], 1.0, n)
    ph = rng.uniform(-math.pi, math.pi, n)  # negative azimuths fold onto [0, π]
    wl = rng.uniform(400.0, 700.0, n)
    direct = np.array([float(coated_rough(hirayama_stack(), np.array([w]), math.degrees(math.acos(a)),
                                          math.degrees(math.acos(b)), math.degrees(p), sigma_nm=25.0, tau_nm=300.0,
                                          uniform_albedo=0.05).k_d[0]) for a, b, p, w in zip(ci, co, ph, wl)])
    interp = interpolate_k_d(t, ci, co, ph, wl)
    floor = 1e-3 * t.k_d.max()
    rel = np.abs(interp - direct) / np.maximum(np.abs(direct), floor)
    assert np.max(rel) <= 1.5 * t.interpolation_error_k_d, (np.max(rel), t.interpolation_error_k_d)
    direct_r = np.array([float(coated_rough(hirayama_stack(), np.array([w]), math.degrees(math.acos(a)), 0.0,
                                            sigma_nm=25.0, tau_nm=300.0).k_r[0]) for a, w in zip(ci, wl)])
    rel_r = np.abs(interpolate_k_r(t, ci, wl) - direct_r) / np.maximum(direct_r, 1e-3 * t.k_r.max())
    assert np.max(rel_r) <= 1.5 * t.interpolation_error_k_r


def test_smooth_tables_match_the_smooth_stack():
    wl = np.linspace(400.0, 700.0, 7)
    stack = ls.Stack(ambient=1.0, layers=[ls.Layer(2.0, 120.0)], exit=ls.Substrate(1.52))
    t = coating_tables(stack, wl, n_angles=6, include_diffuse=False, estimate_error=False)
    ref = ls.specular(stack, wl, np.degrees(np.arccos(t.cos_theta))).natural()
    np.testing.assert_allclose(t.k_r, np.asarray(ref.R_front), atol=1e-12)
    np.testing.assert_allclose(t.k_t, np.asarray(ref.T_front), atol=1e-12)
    assert t.k_d.shape == (6, 0, 0, 7)


def test_angle_grids():
    g = angle_grid(90)
    assert g[-1] == 1.0 and g[0] == pytest.approx(math.cos(math.radians(89.0)))
    np.testing.assert_allclose(angle_grid(4, "cos"), [0.25, 0.5, 0.75, 1.0])
    with pytest.raises(ls.LayerstackError):
        angle_grid(1)


def test_polarized_outputs_average_to_natural_light():
    stack = hirayama_stack()
    th = np.array([10.0, 50.0, 80.0])
    kw = dict(sigma_nm=25.0, tau_nm=300.0)
    nat = coated_rough(stack, WL, th, th[::-1], 40.0, **kw)
    pol = coated_rough(stack, WL, th, th[::-1], 40.0, polarized=True, **kw)
    for a, b in zip(nat, pol):
        assert b.shape == (3, 2, 4)
        np.testing.assert_allclose(0.5 * (np.asarray(b)[:, 0] + np.asarray(b)[:, 1]), np.asarray(a), rtol=1e-14)
    assert np.max(np.abs(np.asarray(pol.k_d)[:, 0] - np.asarray(pol.k_d)[:, 1])) > 1e-3  # s and p differ
