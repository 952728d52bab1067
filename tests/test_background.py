"""Stacks over a Lambertian background (Simonot et al. §4): instrument geometries, special cases
and the ρg inversion, against the independent formulas of tests/reference.py (Williams–Clapper
eq. 82, Shore–Spoonhower eq. 83, Saunderson eqs. 84–87, tmm-based eqs. 78–79).

Several parameter sets are evaluated in one library call: α, ρg and the indices are arrays along
the wavelength axis and geometry angles are arrays (leading axes of the result).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
import reference as ref
from _helpers import INF, build_stack, max_abs

TOL = 1e-10
#: quadrature nodes for the stacks with a thick absorbing layer: converged (see test_quadrature:
#: the default node count is ~1e-9 accurate near grazing Beer factors)
NODES = 64

INC = np.array([0.0, 8.0, 30.0, 45.0, 60.0, 80.0])
VIEW = np.array([0.0, 45.0, 10.0, 0.0, 20.0, 0.0])


def _wc_stack(n0, n1, ah, rho, h=2e4):
    """ambient n0 | one thick α layer of index n1 | background of the same index n1 (n1 = n2)."""
    layer = ls.Layer(n1, h, coherent=False, alpha=jnp.asarray(np.asarray(ah) / h))
    return ls.Stack(n0, [layer], ls.LambertianBackground(n1, jnp.asarray(rho)))


AH = np.array([0.0, 0.05, 0.3, 1.0, 2.5])
RHO = np.array([0.9, 0.2, 0.5, 0.8, 1.0])
WL = jnp.linspace(400.0, 700.0, AH.size)  # one (αh, ρg) pair per "wavelength"


@pytest.mark.parametrize("n0,n1", [(1.0, 1.5), (1.0, 1.33), (1.2, 1.6)])
def test_williams_clapper_radiance_factor_and_brdf(n0, n1):
    """Directional(θ0, θ0') with n1 = n_g is eq. 82; BRDF = that / π (eq. 76)."""
    st = _wc_stack(n0, n1, AH, RHO)
    got = np.asarray(ls.reflectance(st, WL, ls.Directional(jnp.asarray(INC), jnp.asarray(VIEW)), nodes=NODES))
    brdf = np.asarray(ls.reflectance(st, WL, ls.BRDF(jnp.asarray(INC), jnp.asarray(VIEW)), nodes=NODES))
    assert got.shape == (INC.size, AH.size)
    exp = np.array(
        [
            [ref.williams_clapper_factor(n0, n1, ah, rho, math.radians(a), math.radians(b)) for ah, rho in zip(AH, RHO)]
            for a, b in zip(INC, VIEW)
        ]
    )
    assert max_abs(got, exp) <= TOL
    assert max_abs(brdf, exp / math.pi) <= TOL


@pytest.mark.parametrize("n0,n1", [(1.0, 1.5), (1.2, 1.6)])
def test_shore_spoonhower_sphere(n0, n1):
    """Sphere, specular excluded, n1 = n_g: eq. 83; SCI adds the front Fresnel reflectance."""
    st = _wc_stack(n0, n1, AH, RHO)
    for a in (0.0, 8.0, 45.0, 75.0):
        sce = np.asarray(ls.reflectance(st, WL, ls.Sphere(a), nodes=NODES))
        sci = np.asarray(ls.reflectance(st, WL, ls.Sphere(a, "included"), nodes=NODES))
        exp = np.array([ref.shore_spoonhower(n0, n1, ah, rho, math.radians(a)) for ah, rho in zip(AH, RHO)])
        R01 = ref.fresnel_natural_R(n0, n1, math.radians(a))[2]
        assert max_abs(sce, exp) <= TOL, a
        assert max_abs(sci, exp + R01) <= TOL, a


@pytest.mark.parametrize("n", [1.33, 1.5, 2.0])
def test_saunderson_bare_background(n):
    """No layer (air | paint): sphere eq. 84 and radiance detector eq. 85, default node count."""
    rho = jnp.asarray(RHO)
    st = ls.Stack(1.0, [], ls.LambertianBackground(n, rho))
    for a, b in zip(INC, VIEW):
        sce = np.asarray(ls.reflectance(st, WL, ls.Sphere(a)))
        rad = np.asarray(ls.reflectance(st, WL, ls.Directional(a, b)))
        assert max_abs(sce, ref.saunderson_sphere(n, RHO, math.radians(a))) <= TOL
        assert max_abs(rad, ref.saunderson_radiance(n, RHO, math.radians(a), math.radians(b))) <= TOL


def test_invert_background_round_trip_bare_eqs_86_87():
    """ρg from a bare-background measurement (eq. 86: sphere; eq. 87: radiance detector, BRDF):
    measured values synthesised by the reference, inverted by the library, compared both with
    the true ρg and with the reference inversion."""
    n = 1.5
    st = ls.Stack(1.0, [], ls.LambertianBackground(n, 0.0))
    for a, b in ((8.0, 0.0), (45.0, 0.0), (0.0, 45.0)):
        th, thp = math.radians(a), math.radians(b)
        meas = ref.saunderson_sphere(n, RHO, th)
        got = np.asarray(ls.invert_background(st, WL, jnp.asarray(meas), ls.Sphere(a)))
        assert max_abs(got, RHO) <= TOL
        assert max_abs(got, ref.saunderson_invert(n, meas, th)) <= TOL
        meas = ref.saunderson_radiance(n, RHO, th, thp)
        got = np.asarray(ls.invert_background(st, WL, jnp.asarray(meas), ls.Directional(a, b)))
        assert max_abs(got, RHO) <= TOL
        assert max_abs(got, ref.saunderson_radiance_invert(n, meas, th, thp)) <= TOL
        got = np.asarray(ls.invert_background(st, WL, jnp.asarray(meas / math.pi), ls.BRDF(a, b)))
        assert max_abs(got, RHO) <= TOL
        # SCI: the specular part (front Fresnel R) is removed before inverting
        meas = ref.saunderson_sphere(n, RHO, th) + ref.fresnel_natural_R(1.0, n, th)[2]
        got = np.asarray(ls.invert_background(st, WL, jnp.asarray(meas), ls.Sphere(a, "included")))
        assert max_abs(got, RHO) <= TOL


#: thin film on a varnish on paint (coherent film, thick absorbing varnish, background)
_GEN_N = [1.0, 1.9 + 0.05j, 1.52 + 2e-6j, 1.45]
_GEN_D = [INF, 80.0, 2e4, INF]
_GEN_C = ["i", "c", "i", "i"]


def _general_stack(rho):
    return build_stack(_GEN_N, _GEN_D, [True, False], background=rho)


def test_general_stack_sphere_radiance_sci_against_tmm_reference():
    """Air | 80 nm absorbing film | 20 µm absorbing varnish | paint (n_g = 1.45): eq. 78 (sphere
    SCE), SCI = SCE + specular R (eqs. 69, 78), eq. 79 (radiance factor), BRDF = factor/π, with the
    reference's tmm + adaptive quad."""
    lam = 550.0
    rho = np.array([0.1, 0.5, 0.95])
    st = _general_stack(jnp.asarray(rho))
    wl = jnp.full(3, lam)
    for a, b in ((8.0, 0.0), (60.0, 15.0)):
        th, thp = math.radians(a), math.radians(b)
        sce = np.asarray(ls.reflectance(st, wl, ls.Sphere(a), nodes=NODES))
        sci = np.asarray(ls.reflectance(st, wl, ls.Sphere(a, "included"), nodes=NODES))
        rad = np.asarray(ls.reflectance(st, wl, ls.Directional(a, b), nodes=NODES))
        brdf = np.asarray(ls.reflectance(st, wl, ls.BRDF(a, b), nodes=NODES))
        # the reference formulas broadcast over an array of ρg
        exp_sce, exp_spec = ref.background_sphere(_GEN_N, _GEN_D, _GEN_C, lam, rho, th)
        exp_rad = ref.background_radiance_factor(_GEN_N, _GEN_D, _GEN_C, lam, rho, th, thp)
        assert max_abs(sce, exp_sce) <= TOL
        assert max_abs(sci, exp_sce + exp_spec) <= TOL
        assert max_abs(rad, exp_rad) <= TOL
        assert max_abs(brdf, exp_rad / math.pi) <= TOL
        spec = np.asarray(ls.reflectance(st, wl, ls.Specular(a)))
        assert max_abs(spec, exp_spec) <= TOL
        # Specular T (into the background's binder) and A = 1 - R - T
        _, T_ref = ref.inc_stack_R_T("u", _GEN_N, _GEN_D, _GEN_C, th, lam)
        assert max_abs(ls.reflectance(st, wl, ls.Specular(a, "T")), T_ref) <= TOL
        assert max_abs(ls.reflectance(st, wl, ls.Specular(a, "A")), 1.0 - exp_spec - T_ref) <= TOL


def test_invert_background_round_trip_general_stack():
    """Eq. 86 generalised: measurement synthesised with the tmm reference for the film / varnish /
    paint stack, inverted by the library (sphere SCE and SCI, radiance, BRDF)."""
    lam = 550.0
    rho = np.array([0.05, 0.4, 0.9])
    st = _general_stack(0.0)
    wl = jnp.full(3, lam)
    th, thp = math.radians(45.0), 0.0
    sce, spec = ref.background_sphere(_GEN_N, _GEN_D, _GEN_C, lam, rho, th)
    rad = ref.background_radiance_factor(_GEN_N, _GEN_D, _GEN_C, lam, rho, th, thp)
    for geom, meas in (
        (ls.Sphere(45.0), sce),
        (ls.Sphere(45.0, "included"), sce + spec),
        (ls.Directional(45.0, 0.0), rad),
        (ls.BRDF(45.0, 0.0), rad / math.pi),
    ):
        got = np.asarray(ls.invert_background(st, wl, jnp.asarray(meas), geom, nodes=NODES))
        assert max_abs(got, rho) <= 1e-9, geom


def test_opaque_layer_leaves_only_the_front_reflection():
    """α → ∞: the background disappears; SCE = 0, radiance factor = 0, SCI = Fresnel R(θ0) of the
    top interface (no NaN from exp(−∞) or 0·∞)."""
    st = ls.Stack(1.0, [ls.Layer(1.5, 1e5, coherent=False, alpha=10.0)], ls.LambertianBackground(1.6, 0.8))
    wl = jnp.array([450.0, 550.0])
    for a in (0.0, 8.0, 45.0, 85.0):
        sce = np.asarray(ls.reflectance(st, wl, ls.Sphere(a)))
        sci = np.asarray(ls.reflectance(st, wl, ls.Sphere(a, "included")))
        rad = np.asarray(ls.reflectance(st, wl, ls.Directional(a, 0.0)))
        assert np.all(np.isfinite(sce)) and np.all(np.isfinite(sci)) and np.all(np.isfinite(rad))
        assert np.all(sce == 0.0) and np.all(rad == 0.0)
        assert max_abs(sci, ref.fresnel_natural_R(1.0, 1.5, math.radians(a))[2]) <= 1e-15


def test_transparent_index_matched_stack_reads_rho_g():
    """α = 0 and all indices equal: every geometry reads ρg (sphere SCE at any angle, radiance
    detector at any pair of angles); also with a spectrum ρg(λ) given as TabulatedSpectrum."""
    rho_tab = ls.TabulatedSpectrum([380.0, 780.0], jnp.array([0.2, 0.9]))
    wl = jnp.array([380.0, 480.0, 580.0, 780.0])
    rho = 0.2 + 0.7 * (np.asarray(wl) - 380.0) / 400.0
    for n in (1.0, 1.5):
        st = ls.Stack(
            n,
            [ls.Layer(n, 3e4, coherent=False, alpha=0.0), ls.Layer(n, 100.0)],
            ls.LambertianBackground(n, rho_tab),
        )
        inc, view = jnp.array([0.0, 8.0, 45.0, 70.0, 89.0]), jnp.array([0.0, 0.0, 0.0, 30.0, 0.0])
        sce = ls.reflectance(st, wl, ls.Sphere(inc))
        rad = ls.reflectance(st, wl, ls.Directional(inc, view))
        assert sce.shape == rad.shape == (5, 4)
        assert max_abs(sce, rho[None, :]) <= 1e-13
        assert max_abs(rad, rho[None, :]) <= 1e-13


def test_substrate_exit_geometries():
    """Over a specular substrate there is no diffuse light: SCE = 0, SCI = R; directional raises."""
    st = build_stack([1.0, 1.38, 1.52], [INF, 100.0, INF])
    wl = jnp.array([550.0])
    R, _ = ref.coh_stack_R_T("u", [1.0, 1.38, 1.52], [INF, 100.0, INF], math.radians(8.0), 550.0)
    assert max_abs(ls.reflectance(st, wl, ls.Sphere(8.0)), 0.0) == 0.0
    assert abs(float(ls.reflectance(st, wl, ls.Sphere(8.0, "included"))[0]) - R) <= 1e-12
    with pytest.raises(ls.LayerstackError):
        ls.reflectance(st, wl, ls.Directional(45.0, 0.0))
    with pytest.raises(ls.LayerstackError):
        ls.invert_background(st, wl, jnp.array([0.5]), ls.Sphere(8.0))


def test_default_nodes_background_accuracy():
    """Williams–Clapper with the default node count: within 1e-7 (the quadrature's documented
    accuracy with a grazing Beer factor), and ≤ 1e-10 when the layer is clear (α = 0)."""
    st = _wc_stack(1.0, 1.5, AH, RHO)
    got = np.asarray(ls.reflectance(st, WL, ls.Directional(45.0, 0.0)))
    exp = np.array([ref.williams_clapper_factor(1.0, 1.5, ah, r, math.radians(45.0), 0.0) for ah, r in zip(AH, RHO)])
    assert max_abs(got, exp) <= 1e-7
    assert abs(got[0] - exp[0]) <= TOL  # αh = 0
