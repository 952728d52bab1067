"""Ellipsometry (rho = r_p / r_s, psi, Delta) against tmm.ellips, Fresnel closed forms and a
measured Woollam file.

Expected values come from ``tmm``, from Fresnel's formulas written here in numpy, or from a
measurement; nothing is computed with layerstack_jax except the quantity under test.

Δ is reported as ellipsometers report it: Δ = −arg(r_p/r_s) with the package's e^{−iωt},
n + ik amplitudes, i.e. Δ = 180° − Δ_tmm. ``test_delta_sign_of_a_measured_woollam_file`` shows
why: a J. A. Woollam RC2 file of oxidized silicon reads Δ ≈ 110°–174°, in (0°, 180°), where
arg(r_p/r_s) is negative.
"""

from __future__ import annotations

import cmath
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tmm

import layerstack_jax as ls
from _helpers import INF, build_stack, tree_stack

ell_jit = jax.jit(ls.ellipsometry)


def _wrap(x):
    """Wrap angles (radians) into (-pi, pi]."""
    return np.angle(np.exp(1j * np.asarray(x)))


def _random_index(rng):
    u = rng.random()
    if u < 0.4:
        return complex(rng.uniform(1.0, 3.5), 0.0)
    if u < 0.6:
        return complex(rng.uniform(1.3, 4.5), rng.uniform(0.0, 0.6))
    return complex(rng.uniform(0.05, 3.0), rng.uniform(0.5, 5.0))  # metal, k up to 5


def _random_stack(rng, K):
    n0 = float(rng.uniform(1.0, 1.6))
    n = [complex(n0)] + [_random_index(rng) for _ in range(K)]
    n.append(complex(rng.uniform(1.3, 4.0), 0.0) if rng.random() < 0.5 else _random_index(rng))
    d = [INF] + [float(rng.uniform(1.0, 200.0)) for _ in range(K)] + [INF]
    return n, d


ANGLES = np.array([0.0, 5.0, 20.0, 35.0, 45.0, 55.0, 60.0, 65.0, 70.0, 75.0, 80.0, 89.5])
WL = np.array([310.0, 633.0, 1100.0])


@pytest.mark.parametrize("K", [0, 1, 2, 3, 5])
def test_psi_delta_match_tmm_ellips_random_stacks(K):
    """psi identical to tmm.ellips; Delta = 180 deg - Delta_tmm (tmm reports arg(-r_p/r_s), the
    instruments -arg(r_p/r_s));
    random stacks with dielectrics, semiconductors and metals (k <= 5), 12 angles to 89.5 deg."""
    rng = np.random.default_rng(100 + K)
    stacks, refs = [], []
    for _ in range(8):
        n, d = _random_stack(rng, K)
        stacks.append(build_stack(n, d, leaves=True))
        psi = np.empty((ANGLES.size, WL.size))
        dl = np.empty_like(psi)
        rho = np.empty_like(psi, dtype=complex)
        for i, a in enumerate(ANGLES):
            for j, w in enumerate(WL):
                e = tmm.ellips(n, d, math.radians(a), w)
                psi[i, j], dl[i, j] = e["psi"], e["Delta"]
                rho[i, j] = tmm.coh_tmm("p", n, d, math.radians(a), w)["r"] / tmm.coh_tmm("s", n, d, math.radians(a), w)["r"]
        refs.append((psi, dl, rho))
    batch = tree_stack(stacks)
    out = jax.vmap(ell_jit, in_axes=(0, None, None))(batch, WL, ANGLES)
    for b, (psi, dl, rho) in enumerate(refs):
        got_psi = np.deg2rad(np.asarray(out.psi_deg[b]))
        got_dl = np.deg2rad(np.asarray(out.delta_deg[b]))
        assert np.max(np.abs(got_psi - psi)) <= 1e-9
        # Delta is ill-conditioned only where |rho| ~ 0 (psi ~ 0, Brewster-like): weight by sin 2psi
        err = np.abs(_wrap(got_dl - (np.pi - dl))) * np.sin(2 * psi)
        assert np.max(err) <= 1e-9
        assert np.max(np.abs(np.asarray(out.rho[b]) - rho) / (1 + np.abs(rho))) <= 1e-9
        assert np.all((got_dl > -np.pi) & (got_dl <= np.pi))
        assert np.all((got_psi >= 0) & (got_psi <= np.pi / 2))


def _fresnel_rs_rp(n0, n1, theta):
    """Born & Wolf / tmm amplitudes of one interface (complex n1 allowed), numpy."""
    c0 = cmath.cos(theta)
    s1 = n0 * cmath.sin(theta) / n1
    c1 = cmath.sqrt(1 - s1 * s1)
    if (n1 * c1).imag < 0:
        c1 = -c1
    rs = (n0 * c0 - n1 * c1) / (n0 * c0 + n1 * c1)
    rp = (n1 * c0 - n0 * c1) / (n1 * c0 + n0 * c1)
    return rs, rp


@pytest.mark.parametrize("n1", [1.5, 3.88 + 0.02j, 0.13 + 3.4j, 1.2 + 5.0j])
def test_bare_substrate_closed_form(n1):
    """tan psi e^{-i Delta} = r_p / r_s from Fresnel's formulas (no layer): Delta = -arg(r_p/r_s)."""
    angles = np.linspace(0.0, 89.0, 37)
    wl = np.array([500.0, 700.0])
    st = ls.Stack(1.0, [], ls.Substrate(ls.Index(n1.real, n1.imag) if isinstance(n1, complex) else n1))
    e = ell_jit(st, wl, angles)
    for i, a in enumerate(angles):
        rs, rp = _fresnel_rs_rp(1.0, complex(n1), math.radians(a))
        rho = rp / rs
        np.testing.assert_allclose(np.asarray(e.rho[i]), rho, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(np.asarray(e.psi_deg[i]), math.degrees(math.atan(abs(rho))), atol=1e-10)
        if abs(rho) > 1e-6:
            d = -math.degrees(cmath.phase(rho))
            assert abs(_wrap(np.deg2rad(np.asarray(e.delta_deg[i]) - d))).max() <= 1e-10


def test_glass_textbook_values():
    """Lossless glass: psi = 45, Delta = 180 at normal incidence (exactly +180, not -180);
    Delta = 180 below Brewster, 0 above; psi = 0 at Brewster; N, C, S consistent."""
    n = 1.5
    brewster = math.degrees(math.atan(n))
    angles = np.array([0.0, 30.0, brewster - 1.0, brewster + 1.0, 80.0])
    e = ell_jit(ls.Stack(1.0, [], ls.Substrate(n)), np.array([550.0]), angles)
    assert float(e.psi_deg[0, 0]) == pytest.approx(45.0, abs=1e-12)
    np.testing.assert_array_equal(np.asarray(e.delta_deg[:3, 0]), 180.0)
    np.testing.assert_array_equal(np.asarray(e.delta_deg[3:, 0]), 0.0)
    eb = ell_jit(ls.Stack(1.0, [], ls.Substrate(n)), np.array([550.0]), brewster)
    assert float(eb.psi_deg[0]) < 1e-6
    psi, dl = np.deg2rad(np.asarray(e.psi_deg)), np.deg2rad(np.asarray(e.delta_deg))
    np.testing.assert_allclose(np.asarray(e.N), np.cos(2 * psi), atol=1e-15)
    np.testing.assert_allclose(np.asarray(e.C), np.sin(2 * psi) * np.cos(dl), atol=1e-15)
    np.testing.assert_allclose(np.asarray(e.S), np.sin(2 * psi) * np.sin(dl), atol=1e-15)


def _film_stack(d, n_film=ls.Index(1.46, 0.0), ambient=1.0, substrate=ls.Index(3.88, 0.02)):
    return ls.Stack(ambient, [ls.Layer(n_film, d)], ls.Substrate(substrate))


def test_gradient_wrt_thickness_matches_central_differences():
    """d(psi, Delta, N, C, S)/d(thickness) of SiO2 on Si vs central finite differences."""
    wl = np.array([400.0, 633.0, 900.0])
    angles = np.array([55.0, 70.0, 75.0])

    def f(d):
        e = ls.ellipsometry(_film_stack(d), wl, angles)
        return jnp.stack([e.psi_deg, e.delta_deg, e.N, e.C, e.S])

    d0 = 123.4
    jac = np.asarray(jax.jit(jax.jacfwd(f))(jnp.asarray(d0)))
    h = 1e-4
    fj = jax.jit(f)
    fd = (np.asarray(fj(d0 + h)) - np.asarray(fj(d0 - h))) / (2 * h)
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-8)
    jrev = np.asarray(jax.jit(jax.jacrev(f))(jnp.asarray(d0)))
    np.testing.assert_allclose(jrev, jac, rtol=1e-12, atol=1e-12)


def test_gradients_finite_at_brewster_critical_and_grazing():
    """No NaN in values or gradients at Brewster's angle (r_p = 0), at the critical angle of
    total internal reflection and near grazing incidence."""
    n = 1.5
    brewster = math.degrees(math.atan(n))
    critical = math.degrees(math.asin(1.0 / 1.5))

    def bare(nsub, angle, ambient=1.0):
        e = ls.ellipsometry(ls.Stack(ambient, [], ls.Substrate(nsub)), np.array([550.0]), angle)
        return jnp.sum(e.psi_deg + e.delta_deg + e.N + e.C + e.S)

    vg = jax.jit(jax.value_and_grad(bare), static_argnums=2)
    for args in [(n, brewster, 1.0), (1.0, critical, 1.5), (n, 89.999, 1.0)]:
        v, g = vg(*args)
        assert np.isfinite(float(v)) and np.isfinite(float(g))

    def film(d, angle):
        e = ls.ellipsometry(_film_stack(d, ambient=1.5, substrate=1.0), np.array([550.0]), angle)
        return jnp.sum(e.psi_deg + e.delta_deg)

    gf = jax.jit(jax.grad(film))
    for angle in [critical, 89.9]:
        g = gf(50.0, angle)
        assert np.isfinite(float(g))


def test_shapes_and_jit_one_compile():
    st = _film_stack(100.0)
    e = ell_jit(st, np.linspace(400, 800, 7), np.zeros((2, 3)) + 60.0)
    assert e.psi_deg.shape == e.delta_deg.shape == e.rho.shape == (2, 3, 7)
    f = jax.jit(lambda d: ls.ellipsometry(_film_stack(d), np.linspace(400, 800, 7), 70.0).psi_deg)
    a, b = f(100.0), f(150.0)
    assert f._cache_size() == 1 and not np.allclose(a, b)


def test_bad_input_raises():
    inc = ls.Stack(1.0, [ls.Layer(1.5, 1e5, coherent=False)], ls.Substrate(1.5))
    with pytest.raises(ls.LayerstackError, match="coherent"):
        ls.ellipsometry(inc, np.array([500.0]), 60.0)
    with pytest.raises(ls.LayerstackError, match="angle_deg"):
        ls.ellipsometry(_film_stack(10.0), np.array([500.0]), 90.0)
    with pytest.raises(ls.LayerstackError, match="angle_deg"):
        ls.ellipsometry(_film_stack(10.0), np.array([500.0]), -1.0)


# J. A. Woollam RC2 measurement (CompleteEASE 6.37) of ~2 nm native SiO2 on Si, 70°, as shipped
# by pyElli (github.com/PyEllips/pyElli, examples/gallery/SiO2onSi.ellips.nxs at commit aa49502,
# GPL-3.0 repository; measured values quoted for a test): (wavelength nm, psi deg, Delta deg).
WOOLLAM_SIO2_SI_70 = np.array([
    (250.0, 35.11196, 110.37192), (300.0, 29.85667, 141.44139), (350.0, 26.16517, 147.30881),
    (400.0, 20.38003, 169.13811), (450.0, 15.80446, 171.10200), (500.0, 13.45709, 171.97935),
    (550.0, 12.01816, 172.61429), (600.0, 11.03281, 173.02867), (650.0, 10.32219, 173.40695),
    (700.0, 9.77915, 173.77614), (750.0, 9.36196, 174.15385), (800.0, 9.02136, 174.41823),
])


def test_delta_sign_of_a_measured_woollam_file():
    """The reported Delta is the instrument's: a Woollam file of native oxide on silicon (Si from
    Aspnes & Studna, SiO2 Cauchy 1.452 + 0.0036/lambda^2) is matched to <= 1 deg rms in psi and
    Delta at the best thickness of a 0–10 nm scan (about 2 nm); the opposite sign of Delta (the
    former convention, arg(r_p/r_s)) misses it by more than 40 deg rms at every thickness."""
    wl, psi_m, delta_m = WOOLLAM_SIO2_SI_70.T
    si = ls.material("Si", "Aspnes")

    def psi_delta(d):
        st = ls.Stack(1.0, [ls.Layer(ls.Cauchy(1.452, 0.0036), d)], ls.Substrate(si))
        e = ls.ellipsometry(st, wl, 70.0)
        return e.psi_deg, e.delta_deg

    thickness = np.linspace(0.0, 10.0, 201)
    psi, delta = (np.asarray(x) for x in jax.jit(jax.vmap(psi_delta))(thickness))

    def rms(sign):
        dd = np.rad2deg(_wrap(np.deg2rad(sign * delta - delta_m)))
        return np.sqrt(np.mean((psi - psi_m) ** 2 + dd**2, axis=-1))

    best = int(np.argmin(rms(1.0)))
    assert rms(1.0)[best] <= 1.0
    assert 1.0 <= thickness[best] <= 3.0
    assert np.all(delta[best] > 0) and np.all(delta[best] < 180)
    assert np.min(rms(-1.0)) > 40.0
