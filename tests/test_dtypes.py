"""The kernel comparisons in float32 and in float64, with per-dtype tolerances (as jax-md does).

Each test runs twice, through the ``precision`` fixture: with ``jax_enable_x64`` off (float32,
how a GPU user runs) and on (float64), under strict dtype promotion both times (an implicit
float32/float64 or real/complex mix inside the library raises). Every result must come out in
the requested dtype and within the tolerance of its precision of an independent float64
reference (``tests/reference.py``: tmm, scipy quadrature, closed forms, or a numpy formula
written here).

Measured worst errors (this machine, 2026-11-25), from which the float32 tolerances are set with
a margin of ~8-18x; float64 is held to the suite's usual bounds:

================================  ==========  ==========
comparison                        float32     float64
================================  ==========  ==========
coherent stacks vs tmm            5.5e-7      1.9e-15
thick slab vs incoherent formula  1.2e-7      4.4e-16
diffuse interface vs closed form  1.3e-7      4.2e-15
lossless energy (R + T - 1)       7.2e-7      4.2e-15
================================  ==========  ==========

``tests/test_precision.py`` compares float32 with float64 on the README's benchmark-like cases
in a subprocess; this file holds the kernels themselves to their references in both precisions.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
import reference as ref

#: max |error| per comparison and precision
TOL = {
    "coherent": {"float32": 1e-5, "float64": 1e-12},
    "slab": {"float32": 1e-6, "float64": 1e-13},
    "diffuse_interface": {"float32": 1e-6, "float64": 1e-12},
    "energy": {"float32": 1e-5, "float64": 1e-13},
}


@pytest.fixture(params=["float32", "float64"])
def precision(request):
    """x64 off (float32) or on (float64), strict promotion; both restored afterwards."""
    before = jax.config.read("jax_enable_x64")
    jax.config.update("jax_enable_x64", request.param == "float64")
    try:
        with jax.numpy_dtype_promotion("strict"):
            yield request.param
    finally:
        jax.config.update("jax_enable_x64", before)


def _assert_dtype(x, precision):
    assert jnp.asarray(x).dtype == np.dtype(precision), (jnp.asarray(x).dtype, precision)


def _random_coherent(rng, k):
    n = [1.0] + [complex(rng.uniform(1.3, 2.5), rng.choice([0.0, rng.uniform(0.0, 0.5)])) for _ in range(k)]
    n.append(complex(rng.uniform(1.4, 1.8), 0.0))
    d = [float(x) for x in rng.uniform(10.0, 300.0, k)]
    return n, d


def test_coherent_stacks_against_tmm(precision):
    """20 random coherent stacks (1–6 films, absorbing ones included) on glass, angles 0–80°,
    s and p, 3 wavelengths: R and T against ``tmm.coh_tmm``."""
    rng = np.random.default_rng(17)
    wl = np.array([420.0, 560.0, 730.0])
    angles = np.array([0.0, 35.0, 80.0])
    worst = 0.0
    for _ in range(20):
        n, d = _random_coherent(rng, int(rng.integers(1, 7)))
        stack = ls.Stack(n[0], [ls.Layer(ni, di) for ni, di in zip(n[1:-1], d)], ls.Substrate(n[-1]))
        out = ls.specular(stack, jnp.asarray(wl), jnp.asarray(angles))  # (angle, pol, wl)
        _assert_dtype(out.R_front, precision)
        R_ls, T_ls = np.asarray(out.R_front, dtype=float), np.asarray(out.T_front, dtype=float)  # one transfer
        for ia, a in enumerate(angles):
            for ip, pol in enumerate("sp"):
                for iw, lam in enumerate(wl):
                    R, T = ref.coh_stack_R_T(pol, n, [math.inf, *d, math.inf], math.radians(a), lam)
                    worst = max(worst, abs(R_ls[ia, ip, iw] - R), abs(T_ls[ia, ip, iw] - T))
    print(f"\ncoherent vs tmm, {precision}: max error {worst:.2e}")
    assert worst <= TOL["coherent"][precision]


def test_thick_slab_against_closed_form(precision):
    """A thick absorbing slab (incoherent, α given) on a substrate at normal incidence: the
    incoherent sum :math:`R = R_{01} + T_{01}^2 R_{12} t^2 / (1 - R_{10} R_{12} t^2)`,
    :math:`t = e^{-\\alpha h}`, with Fresnel intensities written out here in numpy."""
    wl = np.array([450.0, 600.0, 750.0])
    worst = 0.0
    for n1, n2, h, alpha in ((1.5, 1.52, 2e4, 1e-5), (1.33, 2.0, 5e4, 3e-5), (2.1, 1.0, 1e5, 1e-6)):
        stack = ls.Stack(1.0, [ls.Layer(n1, h, coherent=False, alpha=alpha)], ls.Substrate(n2))
        out = ls.specular(stack, jnp.asarray(wl), 0.0)  # (pol, wl)
        _assert_dtype(out.R_front, precision)
        r01, r12 = ((1.0 - n1) / (1.0 + n1)) ** 2, ((n1 - n2) / (n1 + n2)) ** 2
        t = math.exp(-alpha * h)
        R = r01 + (1 - r01) ** 2 * r12 * t**2 / (1 - r01 * r12 * t**2)
        T = (1 - r01) * (1 - r12) * t / (1 - r01 * r12 * t**2)
        worst = max(worst, float(jnp.max(jnp.abs(out.R_front - R))), float(jnp.max(jnp.abs(out.T_front - T))))
    print(f"\nthick slab vs closed form, {precision}: max error {worst:.2e}")
    assert worst <= TOL["slab"][precision]


@pytest.mark.parametrize("n", [1.33, 1.5, 2.0])
def test_diffuse_interface_against_closed_form(precision, n):
    """Hemispherical (quadrature) reflectance of one interface, from outside and inside, against
    the closed forms (reference.diffuse_reflectance_interface_closed_form)."""
    r_out, r_in = ref.diffuse_reflectance_interface_closed_form(n)
    wl = jnp.asarray(np.array([550.0]))
    worst = 0.0
    for stack, expected in ((ls.Stack(1.0, [], ls.Substrate(n)), r_out), (ls.Stack(n, [], ls.Substrate(1.0)), r_in)):
        d = ls.diffuse(stack, wl)
        _assert_dtype(d.r, precision)
        worst = max(worst, abs(float(d.r[0]) - expected), abs(float(d.t[0]) - (1.0 - expected)))
    print(f"\ndiffuse interface n={n}, {precision}: max error {worst:.2e}")
    assert worst <= TOL["diffuse_interface"][precision]


def test_lossless_energy_conservation(precision):
    """Lossless coherent, incoherent and mixed stacks: R + T = 1, specular (s, p, 0–85°) and
    hemispherical (both sides)."""
    wl = jnp.asarray(np.array([450.0, 550.0, 650.0]))
    layers = [ls.Layer(1.38, 100.0), ls.Layer(1.5, 2e4, coherent=False), ls.Layer(2.1, 60.0),
              ls.Layer(1.6, 3e4, coherent=False)]
    stack = ls.Stack(1.0, layers, ls.Substrate(1.33))
    out = ls.specular(stack, wl, jnp.asarray(np.array([0.0, 40.0, 85.0])))
    _assert_dtype(out.R_front, precision)
    worst = float(jnp.max(jnp.abs(out.R_front + out.T_front - 1.0)))
    for side in ("front", "back"):
        d = ls.diffuse(stack, wl, side)
        _assert_dtype(d.r, precision)
        worst = max(worst, float(jnp.max(jnp.abs(d.r + d.t - 1.0))))
    print(f"\nenergy conservation, {precision}: max |R + T - 1| {worst:.2e}")
    assert worst <= TOL["energy"][precision]


def test_complex_helpers_match_standard_promotion(precision):
    """``complex_from``/``as_complex`` give the dtype and the values of the implicit promotions
    they replace (``re + 1j * im``, ``real * complex``), computed here under standard promotion."""
    from layerstack_jax._base.numerics import as_complex, complex_dtype, complex_from

    rng = np.random.default_rng(3)
    re, im = jnp.asarray(rng.normal(size=5)), jnp.asarray(np.abs(rng.normal(size=(2, 1))))
    z = jnp.asarray(rng.normal(size=5) + 1j * rng.normal(size=5))  # complex of the precision
    with jax.numpy_dtype_promotion("standard"):
        implicit = re + 1j * im
        mixed = re * z
    got = complex_from(re, im)
    assert got.dtype == implicit.dtype == complex_dtype(re, im)
    assert got.shape == (2, 5) and np.array_equal(np.asarray(got), np.asarray(implicit))
    assert np.array_equal(np.asarray(as_complex(re, z) * z), np.asarray(mixed))
    assert complex_dtype(np.float32(1.0)) == np.complex64
    assert complex_dtype(re) == (np.complex128 if precision == "float64" else np.complex64)
