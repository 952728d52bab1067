"""Kubelka–Munk bodies (issue 28): the closed forms against an independent integration of the
two-flux equations (scipy ``solve_ivp``, written here), the opaque limit, Kubelka's layering,
Duncan's mixing, Saunderson's formula out of the full model, gradients against central
differences, finite values and gradients at every limit in float32 and float64.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

import fitting as ft
import layerstack_jax as ls

WL = np.linspace(400.0, 700.0, 7)


# ----------------------------------------------------------------------------- the reference
def _integrate(bodies, Rg):
    r"""``(R, I(X)/I(0))`` of bodies ``[(K, S, X), …]`` (top first, in contact) over a ground
    ``Rg``: the two-flux equations dI/dz = −(K+S) I + S J, dJ/dz = (K+S) J − S I, integrated
    upwards from the ground where (I, J) = (1, Rg), one body after the other (DOP853, rtol 1e-13).
    The growing solution dominates upwards, so the ratio J/I is well conditioned."""
    y = np.array([1.0, Rg])
    for K, S, X in reversed(bodies):
        if X == 0:
            continue
        A = np.array([[-(K + S), S], [-S, K + S]])
        sol = solve_ivp(lambda z, v: A @ v, (X, 0.0), y, method="DOP853", rtol=1e-13, atol=1e-150)
        y = sol.y[:, -1]
    I0, J0 = y
    return J0 / I0, 1.0 / I0


def _cases():
    rng = np.random.default_rng(28)
    out = [(rng.uniform(0, 2e-3), rng.uniform(0, 2e-2), rng.uniform(0, 3000.0), rng.uniform()) for _ in range(40)]
    out += [
        (1e-3, 0.0, 800.0, 0.7),        # pure absorber: R = Rg e^{-2KX}
        (0.0, 5e-3, 800.0, 0.3),        # white: no absorption
        (0.0, 0.0, 800.0, 0.45),        # neither: R = Rg, T = 1
        (2e-3, 1e-2, 0.0, 0.6),         # no body: R = Rg
        (1e-12, 1e-2, 500.0, 0.2),      # K → 0
        (1e-3, 1e-14, 500.0, 0.9),      # S → 0
        (1e-4, 0.5, 400.0, 0.1),        # SX = 200
        (0.2, 0.05, 1000.0, 0.5),       # KX = 200: opaque by absorption
        (3e-3, 2e-2, 1e-9, 0.8),        # X → 0
        (1e-3, 1e-2, 30.0, 1.0),        # white ground
        (1e-3, 1e-2, 30.0, 0.0),        # black ground
    ]
    return out


@pytest.mark.parametrize("K, S, X, Rg", _cases())
def test_reflectance_and_transmittance_against_the_two_flux_ode(K, S, X, Rg):
    R, T = _integrate([(K, S, X)], Rg)
    assert abs(float(ls.km_reflectance(K, S, X, Rg)) - R) <= 1e-10
    assert abs(float(ls.km_transmittance(K, S, X, Rg)) - T) <= 1e-10
    R0, T0 = _integrate([(K, S, X)], 0.0)  # over black: Kubelka's T
    assert abs(float(ls.km_transmittance(K, S, X)) - T0) <= 1e-10
    assert abs(float(ls.km_reflectance(K, S, X)) - R0) <= 1e-10


def test_limits_in_closed_form():
    K, X, Rg = 1.3e-3, 700.0, 0.62
    assert float(ls.km_reflectance(K, 0.0, X, Rg)) == pytest.approx(Rg * np.exp(-2 * K * X), rel=1e-14)
    assert float(ls.km_transmittance(K, 0.0, X)) == pytest.approx(np.exp(-K * X), rel=1e-14)
    S = 4e-3
    white = (Rg + S * X * (1 - Rg)) / (1 + S * X * (1 - Rg))
    assert float(ls.km_reflectance(0.0, S, X, Rg)) == pytest.approx(white, rel=1e-14)
    assert float(ls.km_reflectance(K, S, 0.0, Rg)) == Rg
    assert float(ls.km_transmittance(K, S, 0.0)) == 1.0


@pytest.mark.parametrize("K, S", [(1e-3, 1e-2), (2e-2, 1e-3), (1e-6, 1.0), (0.5, 0.5), (0.0, 1e-2)])
def test_opaque_limit_is_a_minus_b(K, S):
    a = 1.0 + K / S
    r_inf = a - np.sqrt(a * a - 1.0)
    assert float(ls.km_r_infinity(K, S)) == pytest.approx(r_inf, rel=1e-12, abs=1e-15)
    for Rg in (0.0, 0.5, 1.0):  # thick enough, the ground is unseen (a white body only as 1/(SX): not here)
        if K > 0:
            assert float(ls.km_reflectance(K, S, 1e9, Rg)) == pytest.approx(r_inf, rel=1e-12)
    if K > 0:
        assert float(ls.k_over_s(r_inf)) == pytest.approx(K / S, rel=1e-10)
    body = ls.PaintLayer(ls.Paint(K, S), thickness=None, ground=0.3)
    assert float(np.ravel(body.reflectance(WL))[0]) == pytest.approx(r_inf, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("seed", range(6))
def test_layering_against_two_bodies_integrated_as_one_system(seed):
    rng = np.random.default_rng(seed)
    (K1, K2), (S1, S2) = rng.uniform(0, 2e-3, 2), rng.uniform(0, 2e-2, 2)
    X1, X2, Rg = rng.uniform(10, 1500), rng.uniform(10, 1500), rng.uniform()
    R, _ = _integrate([(K1, S1, X1), (K2, S2, X2)], Rg)
    lower = ls.PaintLayer(ls.Paint(K2, S2), X2, ground=Rg)
    upper = ls.PaintLayer(ls.Paint(K1, S1), X1, ground=lower)
    assert abs(float(np.ravel(upper.reflectance(WL))[0]) - R) <= 1e-10
    # Kubelka's layering formula with the upper body's R and T over black
    R1, T1 = float(ls.km_reflectance(K1, S1, X1)), float(ls.km_transmittance(K1, S1, X1))
    R12, _ = ls.layered(R1, T1, float(np.ravel(lower.reflectance(WL))[0]))
    assert abs(float(R12) - R) <= 1e-10
    # and T of two bodies over black
    _, T = _integrate([(K1, S1, X1), (K2, S2, X2)], 0.0)
    _, T12 = ls.layered(R1, T1, float(ls.km_reflectance(K2, S2, X2)), float(ls.km_transmittance(K2, S2, X2)))
    assert abs(float(T12) - T) <= 1e-10


def test_duncan_mixing_is_linear_in_k_and_s():
    rng = np.random.default_rng(3)
    Ks, Ss, c = rng.uniform(0, 1e-3, (3, WL.size)), rng.uniform(0, 1e-2, (3, WL.size)), np.array([0.2, 0.5, 0.3])
    mix = ls.Mixture(c, [ls.Paint(k, s, name=f"p{i}") for i, (k, s) in enumerate(zip(Ks, Ss))])
    K, S = mix.constants(WL)
    np.testing.assert_allclose(np.asarray(K), c @ Ks, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(S), c @ Ss, rtol=1e-15)
    X, Rg = 900.0, 0.4
    R = np.asarray(ls.PaintLayer(mix, X, Rg).reflectance(WL))
    for j in range(WL.size):
        assert abs(R[j] - _integrate([(c @ Ks[:, j], c @ Ss[:, j], X)], Rg)[0]) <= 1e-10
    # not linear in K/S: mixing the ratios would give another R∞
    r_ratio = float(ls.km_r_infinity(c @ (Ks[:, 0] / Ss[:, 0]), 1.0))
    assert abs(float(ls.km_r_infinity(K[0], S[0])) - r_ratio) > 1e-3


# ----------------------------------------------------------------------------- Saunderson
def _fresnel_unpolarized(n0, n1, theta):
    """External reflectance of a bare interface for natural light (numpy, Fresnel)."""
    c0 = np.cos(theta)
    s1 = n0 * np.sin(theta) / n1
    c1 = np.sqrt(1 - s1 * s1 + 0j)
    rs = (n0 * c0 - n1 * c1) / (n0 * c0 + n1 * c1)
    rp = (n1 * c0 - n0 * c1) / (n1 * c0 + n0 * c1)
    return 0.5 * (abs(rs) ** 2 + abs(rp) ** 2)


def _k2_quad(n0, n1):
    """Hemispherical internal reflectance of the binder interface (from n1 towards n0), by scipy
    quad split at the critical angle: 2 ∫ R(θ) cos θ sin θ dθ."""
    tc = np.arcsin(n0 / n1)
    f = lambda t: 2 * _fresnel_unpolarized(n1, n0, t) * np.cos(t) * np.sin(t)  # noqa: E731
    return quad(f, 0, tc, epsabs=1e-14, epsrel=1e-13, limit=200)[0] + quad(f, tc, np.pi / 2, epsabs=1e-14, epsrel=1e-13, limit=200)[0]


def _k2_library(n_g):
    from layerstack_jax._stacks.illumination import diffuse_resolved
    from layerstack_jax._stacks.stack import resolve

    rs = resolve(ls.Stack(1.0, [], ls.LambertianBackground(n_g, 0.5)), WL)
    return float(np.asarray(diffuse_resolved(rs, "back", ls.DEFAULT_NODES).r).ravel()[0])


@pytest.mark.parametrize("n_g", [1.45, 1.52, 1.6])
def test_saunderson_comes_out_of_a_bare_body_under_its_binder(n_g):
    K, S, X, Rg = 4e-4, 6e-3, 250.0, 0.55
    rho, _ = _integrate([(K, S, X)], Rg)  # the body's internal reflectance, independently
    k2 = _k2_library(n_g)
    assert abs(k2 - _k2_quad(1.0, n_g)) < 1e-13  # the library's k2 is the hemispherical integral
    stack = ls.Stack(1.0, [], ls.KubelkaMunk(n_g, ls.Paint(K, S), X, Rg))
    body = rho / (1 - k2 * rho)
    k1 = _fresnel_unpolarized(1.0, n_g, np.deg2rad(8.0))
    sci = k1 + (1 - k1) * (1 - k2) * body  # Saunderson 1942, sphere, specular included
    sce = (1 - k1) * (1 - k2) * body
    np.testing.assert_allclose(np.asarray(ls.reflectance(stack, WL, ls.Sphere(8.0, "included"))), sci, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(ls.reflectance(stack, WL, ls.Sphere(8.0, "excluded"))), sce, rtol=0, atol=1e-12)
    # 45°/0° radiance factor: in at 45°, out at 0°, n² law of radiance across the interface
    k1_45, k1_0 = _fresnel_unpolarized(1.0, n_g, np.deg2rad(45.0)), _fresnel_unpolarized(1.0, n_g, 0.0)
    d450 = (1.0 / n_g) ** 2 * (1 - k1_45) * (1 - k1_0) * body
    np.testing.assert_allclose(np.asarray(ls.reflectance(stack, WL, ls.Directional(45.0, 0.0))), d450, rtol=0,
                               atol=1e-12)


@pytest.mark.parametrize("n_g, k2_expected, max_difference", [(1.4, 0.52899, 0.0397), (1.5, 0.59635, 0.0022),
                                                              (1.6, 0.65088, -0.0322)])
def test_customary_k2_of_0_6_differs_from_the_hemispherical_one(n_g, k2_expected, max_difference):
    """The customary constant k₂ = 0.6 against the hemispherical internal reflectance of the
    binder (the library's k₂ equals scipy's quad to 1e-14): at n = 1.5 (k₂ = 0.5963) the SCE
    reading differs by at most 0.0022 (at ρ ≈ 0.71); at n = 1.4 and 1.6 by +0.040 and −0.032."""
    k2 = _k2_library(n_g)
    assert k2 == pytest.approx(_k2_quad(1.0, n_g), abs=1e-13) and k2 == pytest.approx(k2_expected, abs=1e-5)
    rho = np.linspace(0, 1, 1001)
    k1 = _fresnel_unpolarized(1.0, n_g, np.deg2rad(8.0))
    diff = (1 - k1) * ((1 - k2) * rho / (1 - k2 * rho) - 0.4 * rho / (1 - 0.6 * rho))
    assert diff[np.argmax(np.abs(diff))] == pytest.approx(max_difference, abs=1e-4)


# ----------------------------------------------------------------------------- gradients
def _reading(c, K_scale, S_scale, X, varnish):
    """45°/0° reading of a varnished two-pigment paint over a grey ground, as a function of the
    concentrations, a scale of every K and of every S, the paint thickness and the varnish's
    thickness (all the fitted numbers)."""
    Ks = jnp.array([[2e-4, 6e-4, 1e-3], [1e-3, 3e-4, 5e-5]])
    Ss = jnp.array([[8e-3, 7e-3, 6e-3], [2e-3, 2e-3, 2e-3]])
    mix = ls.Mixture(c, [ls.Paint(K_scale * k, S_scale * s) for k, s in zip(Ks, Ss)])
    stack = ls.Stack(1.0, [ls.Layer(1.5, varnish, coherent=False, alpha=2e-6, name="varnish")],
                     ls.KubelkaMunk(1.5, mix, X, 0.4))
    return ls.reflectance(stack, WL[:3], ls.Directional(45.0, 0.0))


@pytest.mark.parametrize("point", [
    (np.array([0.3, 0.7]), 1.0, 1.0, 600.0, 2e4),
    (np.array([0.9, 0.1]), 0.5, 2.0, 1.5e3, 5e4),
])
def test_gradients_against_central_differences(point):
    c, ks, ss, X, h = point
    args = [jnp.asarray(c), ks, ss, X, h]
    f = lambda *a: jnp.sum(_reading(*a) * jnp.array([0.3, 0.5, 0.2]))  # noqa: E731
    grads = jax.grad(f, argnums=range(5))(*args)
    for i, g in enumerate(grads):
        x = np.atleast_1d(np.asarray(args[i], float))
        for j in range(x.size):
            step = 1e-5 * max(abs(x[j]), 1e-3)
            up, dn = x.copy(), x.copy()
            up[j] += step
            dn[j] -= step
            pick = (lambda v: jnp.asarray(v)) if np.ndim(args[i]) else (lambda v: float(v[0]))
            fd = (f(*args[:i], pick(up), *args[i + 1:]) - f(*args[:i], pick(dn), *args[i + 1:])) / (2 * step)
            got = np.atleast_1d(np.asarray(g))[j]
            rounding = 1e-15 * float(f(*args)) / step  # the difference quotient's own floor
            assert abs(got - float(fd)) <= 1e-6 * abs(float(fd)) + rounding, (i, j, got, fd)


LIMITS = [(1e-3, 0.0, 800.0, 0.5), (0.0, 5e-3, 800.0, 0.5), (0.0, 0.0, 800.0, 0.5), (1e-3, 5e-3, 0.0, 0.5),
          (1e-3, 5.0, 1e3, 0.5), (5.0, 1e-3, 1e3, 0.5), (1e-3, 5e-3, 1e12, 0.5)]


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("K, S, X, Rg", LIMITS)
def test_values_and_gradients_finite_at_the_limits(dtype, K, S, X, Rg):
    args = [jnp.asarray(v, dtype) for v in (K, S, X, Rg)]
    for fn in (ls.km_reflectance, ls.km_transmittance):
        v = fn(*args)
        g = jax.grad(lambda *a: fn(*a), argnums=range(4))(*args)
        assert v.dtype == dtype and np.isfinite(float(v)) and 0 <= float(v) <= 1
        assert all(np.isfinite(float(x)) for x in g), (fn.__name__, g)
    R64 = float(ls.km_reflectance(*[jnp.asarray(v, jnp.float64) for v in (K, S, X, Rg)]))
    assert abs(float(ls.km_reflectance(*args)) - R64) <= (1e-6 if dtype == jnp.float32 else 1e-15)
    g = jax.grad(lambda k, s: ls.km_r_infinity(k, s), argnums=(0, 1))(args[0], args[1])
    assert all(np.isfinite(float(x)) for x in g)


def test_gradients_at_the_limits_match_the_limit_forms():
    """At S = 0, K = 0, X = 0 the gradients are those of the limit formulas (the series branch)."""
    K, S, X, Rg = 1.1e-3, 4e-3, 700.0, 0.6
    g = jax.grad(ls.km_reflectance, argnums=(0, 2, 3))(K, 0.0, X, Rg)
    e = np.exp(-2 * K * X)
    np.testing.assert_allclose([float(x) for x in g], [-2 * X * Rg * e, -2 * K * Rg * e, e], rtol=1e-12)
    gS = float(jax.grad(ls.km_reflectance, argnums=1)(0.0, S, X, Rg))
    assert gS == pytest.approx(X * (1 - Rg) ** 2 / (1 + S * X * (1 - Rg)) ** 2, rel=1e-12)
    # at K = 0 the derivative in K by a one-sided second-order difference
    h = 1e-9
    f = lambda k: float(ls.km_reflectance(k, S, X, Rg))  # noqa: E731
    fd = (-3 * f(0.0) + 4 * f(h) - f(2 * h)) / (2 * h)
    assert float(jax.grad(ls.km_reflectance)(0.0, S, X, Rg)) == pytest.approx(fd, rel=1e-6)
    # at X = 0: dR/dX = S − Rg(S + K) − Rg(S + K − Rg S)
    gX = float(jax.grad(ls.km_reflectance, argnums=2)(K, S, 0.0, Rg))
    assert gX == pytest.approx(S - Rg * (S + K) - Rg * (S + K - Rg * S), rel=1e-12)


# ----------------------------------------------------------------------------- in the stack
def test_a_body_is_a_background_of_its_own_reflectance():
    paint = ls.Paint(np.linspace(1e-4, 1e-3, WL.size), 5e-3)
    body = ls.KubelkaMunk(1.5, paint, 400.0, 0.3)
    rho = np.asarray(body.body().reflectance(WL))
    layers = [ls.Layer(1.5, 3e4, coherent=False, alpha=1e-5, name="varnish")]
    for g in (ls.Sphere(8.0), ls.Directional(45.0, 0.0), ls.BRDF(30.0, 10.0)):
        got = ls.reflectance(ls.Stack(1.0, layers, body), WL, g)
        want = ls.reflectance(ls.Stack(1.0, layers, ls.LambertianBackground(1.5, rho)), WL, g)
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=0, atol=1e-15)


def test_every_number_of_the_body_keeps_the_optics_fixed():
    mix = ls.Mixture([0.5, 0.5], [ls.Paint(1e-3, 1e-2), ls.Paint(1e-4, 2e-3)])
    stack = ls.Stack(1.0, [], ls.KubelkaMunk(1.5, mix, 300.0, ls.PaintLayer(ls.Paint(1e-4, 1e-2), 1e3, 0.8)))
    for leaf in ls.stack_leaves(stack):
        assert leaf.fixed_optics == (leaf.path[0] == "exit" and leaf.path[1] != "index"), leaf
    batched = ls.Stack(1.0, [], ls.KubelkaMunk(1.5, ls.Mixture(np.array([[0.2, 0.8], [0.7, 0.3]]), mix.pigments),
                                               300.0, 0.5))
    got = np.asarray(ls.predict(batched, WL, ls.Sphere(8.0)))
    for i, c in enumerate([[0.2, 0.8], [0.7, 0.3]]):
        one = ls.Stack(1.0, [], ls.KubelkaMunk(1.5, ls.Mixture(c, mix.pigments), 300.0, 0.5))
        np.testing.assert_allclose(got[i], np.asarray(ls.reflectance(one, WL, ls.Sphere(8.0))), rtol=0, atol=1e-15)


def test_bad_bodies_are_refused_naming_the_field():
    with pytest.raises(ls.LayerstackError, match="absorption K"):
        ls.Paint(-1e-3, 1e-2)
    with pytest.raises(ls.LayerstackError, match="thickness"):
        ls.KubelkaMunk(1.5, ls.Paint(1e-3, 1e-2), -5.0)
    with pytest.raises(ls.LayerstackError, match="ground reflectance"):
        ls.KubelkaMunk(1.5, ls.Paint(1e-3, 1e-2), 5.0, 1.2)
    with pytest.raises(ls.LayerstackError, match="2 values"):
        ls.Mixture([1.0], [ls.Paint(1e-3, 1e-2), ls.Paint(1e-3, 1e-2)])
    with pytest.raises(ls.LayerstackError, match="must be real"):
        ls.Stack(1.0, [], ls.KubelkaMunk(1.5 + 0.1j, ls.Paint(1e-3, 1e-2), 5.0))

    @jax.jit
    def traced(k):
        return ls.reflectance(ls.Stack(1.0, [], ls.KubelkaMunk(1.5, ls.Paint(k, 1e-2), 50.0, 0.5)), WL, ls.Sphere(8.0))

    with pytest.raises(Exception, match="absorption K"):
        jax.block_until_ready(traced(-1.0))


# ----------------------------------------------------------------------------- files and fits
BODY_FILE = """
[[layers]]
name = "varnish"
n = 1.5
thickness_nm = 20000
coherent = false
alpha_per_nm = 2e-6

[kubelka_munk]
n = 1.5
thickness_nm = { value = 30000, free = true, min = 0, max = 1e5 }
ground_reflectance = 0.8

[[kubelka_munk.pigments]]
name = "white"
K_per_nm = 1e-6
S_per_nm = 5e-4
concentration = 0.6

[[kubelka_munk.pigments]]
name = "red"
K_per_nm = { wavelength_nm = [380, 550, 600, 780], values = [2e-4, 2e-4, 1e-5, 1e-5] }
S_per_nm = 1e-4
concentration = { value = 0.4, free = true, max = 2 }
"""


def _by_hand(thickness=30000.0):
    red_K = ls.TabulatedSpectrum([380, 550, 600, 780], [2e-4, 2e-4, 1e-5, 1e-5])
    mix = ls.Mixture(np.array([0.6, 0.4]), [ls.Paint(1e-6, 5e-4, name="white"), ls.Paint(red_K, 1e-4, name="red")])
    return ls.Stack(1.0, [ls.Layer(1.5, 20000.0, coherent=False, alpha=2e-6, name="varnish")],
                    ls.KubelkaMunk(1.5, mix, thickness, 0.8))


def test_a_body_in_a_stack_file(tmp_path):
    (tmp_path / "s.toml").write_text(BODY_FILE)
    stack, declared = ft.load_fit_parameters(tmp_path / "s.toml")
    assert [(d.path, d.name, d.upper) for d in declared] == [
        (("exit", "thickness"), "thickness_nm", 1e5), (("exit", "paint", "concentrations", 1), "concentration[red]", 2)]
    np.testing.assert_allclose(np.asarray(ls.reflectance(stack, WL, ls.Directional(45.0, 0.0))),
                               np.asarray(ls.reflectance(_by_hand(), WL, ls.Directional(45.0, 0.0))), rtol=0, atol=1e-15)
    with pytest.raises(ls.LayerstackError, match="not both"):
        ls.stack_from_dict({"substrate": {"n": 1.5}, "kubelka_munk": {"n": 1.5, "K_per_nm": 0, "S_per_nm": 0}})
    with pytest.raises(ls.LayerstackError, match="S_per_nm"):
        ls.stack_from_dict({"kubelka_munk": {"n": 1.5, "K_per_nm": 1e-4}})


@pytest.mark.parametrize("paint", ["mixture", "paint", "opaque"])
def test_a_body_saved_and_read_back(tmp_path, paint):
    """save_stack → load_stack keeps every leaf of a body (pigments with their names, tabulated K,
    concentrations, thickness, ground) and so its reading; the file has the tables the reader
    documents (one [[kubelka_munk.pigments]] per pigment)."""
    stack = _by_hand()
    if paint == "paint":
        stack = ls.Stack(1.0, stack.layers, ls.KubelkaMunk(1.5, stack.exit.paint.pigments[1], 30000.0, 0.8))
    elif paint == "opaque":
        stack = ls.Stack(1.0, [], ls.KubelkaMunk(1.52, ls.Paint(2e-5, 3e-3, name="white"), None, 0.0))
    path = ls.save_stack(tmp_path / "body.toml", stack)
    text = path.read_text()
    assert text.count("[[kubelka_munk.pigments]]") == (2 if paint == "mixture" else 0)
    back = ls.load_stack(path)
    numbers = lambda st: np.concatenate([np.ravel(np.asarray(x, float)) for x in jax.tree_util.tree_leaves(st)])
    np.testing.assert_array_equal(numbers(back), numbers(stack))  # every number, in the same places
    assert type(back.exit.paint) is type(stack.exit.paint)
    if paint == "mixture":
        assert [p.name for p in back.exit.paint.pigments] == ["white", "red"]
    g = ls.Directional(45.0, 0.0)
    np.testing.assert_array_equal(np.asarray(ls.reflectance(back, WL, g)), np.asarray(ls.reflectance(stack, WL, g)))


def test_a_mixture_of_a_batch_is_not_written_as_one_body(tmp_path):
    stack = _by_hand()
    batched = ls.Stack(1.0, stack.layers, ls.KubelkaMunk(1.5, ls.Mixture(np.array([[0.6, 0.4], [0.5, 0.5]]),
                                                                          stack.exit.paint.pigments), 3e4, 0.8))
    with pytest.raises(ls.LayerstackError, match="one mixture"):
        ls.save_stack(tmp_path / "b.toml", batched)


def test_a_body_predicted_and_varied_from_the_command_line(tmp_path):
    from layerstack_cli import main

    (tmp_path / "s.toml").write_text(BODY_FILE)
    out = tmp_path / "v.csv"
    assert main(["predict", str(tmp_path / "s.toml"), "-g", "45/0", "-w", "400:700:100", "-o", str(out),
                 "--vary", "kubelka_munk.thickness_nm=1e4,3e4", "--digits", "17"]) == 0
    values = np.loadtxt(out, delimiter=",", skiprows=1)
    for j, h in enumerate((1e4, 3e4)):
        want = ls.reflectance(_by_hand(h), values[:, 0], ls.Directional(45.0, 0.0))
        np.testing.assert_allclose(values[:, 1 + j], np.asarray(want), rtol=0, atol=1e-14)


def test_concentrations_fitted_under_a_varnish():
    """Three pigments in an opaque body under a varnish, 45°/0°: an opaque body fixes only the
    ratios of the concentrations (K/S is unchanged when all are scaled), so the white is held at
    its value and the two others are fitted, with the Fresnel algebra computed once."""

    wl = np.linspace(400.0, 700.0, 31)
    bell = lambda mu, w: np.exp(-0.5 * ((wl - mu) / w) ** 2)  # noqa: E731
    pigments = [ls.Paint(np.full(wl.size, 2e-7), np.full(wl.size, 6e-4), name="white"),
                ls.Paint(3e-4 * bell(480.0, 50.0) + 1e-6, np.full(wl.size, 5e-5), name="red"),
                ls.Paint(2e-4 * bell(620.0, 60.0) + 1e-6, np.full(wl.size, 3e-5), name="blue")]

    def stack(c):
        return ls.Stack(1.0, [ls.Layer(1.52, 25000.0, coherent=False, alpha=3e-6, name="varnish")],
                        ls.KubelkaMunk(1.5, ls.Mixture(np.asarray(c), pigments)))

    geometry = ls.Directional(45.0, 0.0)
    truth = np.array([0.6, 0.25, 0.15])
    data = np.asarray(ls.reflectance(stack(truth), wl, geometry))
    obj = ft.Objective(stack([0.6, 0.4, 0.4]), wl, ft.Dataset(geometry, data),
                       [ft.Parameter(("exit", "paint", "concentrations"), kind="thickness", name="c",
                                     fixed=np.array([True, False, False]))])
    assert obj._fixed_optics() is not None
    r = ft.fit(obj)
    assert r.converged, r.reason
    np.testing.assert_allclose(r.values["c"], truth, rtol=1e-7)


def test_the_paint_of_a_body_is_set_from_vary():
    from layerstack_cli._predict import _set_field

    stack = ls.Stack(1.0, [], ls.KubelkaMunk(1.5, ls.Paint(1e-4, 5e-3), 300.0, 0.5))
    batched = _set_field(stack, "kubelka_munk.K_per_nm", np.array([1e-4, 3e-4]), "s.toml")
    got = np.asarray(ls.predict(batched, WL, ls.Sphere(8.0)))
    for i, k in enumerate((1e-4, 3e-4)):
        one = ls.Stack(1.0, [], ls.KubelkaMunk(1.5, ls.Paint(k, 5e-3), 300.0, 0.5))
        np.testing.assert_allclose(got[i], np.asarray(ls.reflectance(one, WL, ls.Sphere(8.0))), rtol=0, atol=1e-15)
    with pytest.raises(ls.LayerstackError, match="fields: thickness_nm, ground_reflectance, n, k, K_per_nm, S_per_nm"):
        _set_field(stack, "kubelka_munk.X", np.array([1.0]), "s.toml")


def test_a_body_fitted_from_the_command_line(tmp_path):
    """``layerstack fit`` on a stack file with a body: the paint thickness and the red's
    concentration recovered from noise-free 45°/0° data (the white's held: were it free too, the
    products KX, SX would be all the data fix, and the report says the three cannot be separated)."""
    import json

    from layerstack_cli import main

    (tmp_path / "s.toml").write_text(BODY_FILE)
    wl = np.arange(400.0, 701.0, 10.0)
    truth = _by_hand(20000.0)
    truth = ls.Stack(truth.ambient, truth.layers, ls.KubelkaMunk(
        1.5, ls.Mixture(np.array([0.6, 0.3]), truth.exit.paint.pigments), 20000.0, 0.8))
    y = np.asarray(ls.reflectance(truth, wl, ls.Directional(45.0, 0.0)))
    np.savetxt(tmp_path / "d.csv", np.column_stack([wl, y]), delimiter=",", header="wavelength_nm,45/0", comments="",
               fmt="%.17g")
    assert main(["fit", str(tmp_path / "s.toml"), str(tmp_path / "d.csv"), "-g", "45/0", "-o",
                 str(tmp_path / "f.json")]) == 0
    fit = json.loads((tmp_path / "f.json").read_text())["fits"][0]
    assert fit["converged"]
    assert fit["parameters"]["thickness_nm"]["value"] == pytest.approx(20000.0, rel=1e-6)
    assert fit["parameters"]["concentration[red]"]["value"] == pytest.approx(0.3, rel=1e-6)
    (tmp_path / "all.toml").write_text(BODY_FILE.replace("concentration = 0.6", "concentration = { value = 0.6, free = true }"))
    assert main(["fit", str(tmp_path / "all.toml"), str(tmp_path / "d.csv"), "-g", "45/0", "-o",
                 str(tmp_path / "g.json")]) == 0
    warnings = " ".join(json.loads((tmp_path / "g.json").read_text())["fits"][0]["quality"]["warnings"])
    assert "cannot separate" in warnings and "thickness_nm" in warnings


def test_pigment_maps_from_the_command_line(tmp_path):
    """``layerstack fit-cube`` with a stack file that declares the body and its pigments: the
    red's concentration and the paint thickness of every pixel of a small noise-free cube come
    back as maps (zarr), equal to the values the cube was made from."""
    xr = pytest.importorskip("xarray")
    pytest.importorskip("zarr")
    from layerstack_cli import main

    (tmp_path / "s.toml").write_text(BODY_FILE)
    wl = np.arange(400.0, 701.0, 20.0)
    red = np.array([[0.2, 0.3, 0.4], [0.25, 0.35, 0.45]])
    thickness = np.array([[15000.0, 20000.0, 25000.0], [30000.0, 35000.0, 40000.0]])
    base = _by_hand()
    cube = np.stack([np.stack([np.asarray(ls.reflectance(ls.Stack(base.ambient, base.layers, ls.KubelkaMunk(
        1.5, ls.Mixture(np.array([0.6, c]), base.exit.paint.pigments), x, 0.8)), wl, ls.Directional(45.0, 0.0)))
        for c, x in zip(rc, rx)]) for rc, rx in zip(red, thickness)])
    np.save(tmp_path / "cube.npy", cube)
    out = tmp_path / "maps.zarr"
    assert main(["fit-cube", str(tmp_path / "s.toml"), str(tmp_path / "cube.npy"), "-w", "400:700:20", "-g", "45/0",
                 "--sigma", "1e-3", "--no-quicklook", "-o", str(out)]) == 0
    maps = xr.open_zarr(out, consolidated=False)
    assert {"concentration_red", "concentration_red_stderr", "thickness_nm"} <= set(maps.data_vars)
    np.testing.assert_allclose(maps["concentration_red"].values, red, rtol=1e-6)
    np.testing.assert_allclose(maps["thickness_nm"].values, thickness, rtol=1e-6)
    assert np.all(maps["status"].values == 0)


def test_a_grey_varnish_and_a_darker_paint_are_named_as_one_combination():
    """An opaque white with a black whose K/S is flat, under a grey varnish: the readings depend on
    the varnish's α·h and the black's concentration only through one number per wavelength, the
    same at every wavelength — the report says that the two are not identified separately and
    which combination is."""
    import fitting

    white, black = ls.Paint(2e-6, 3e-3, name="white"), ls.Paint(5e-3, 1e-4, name="black")

    def stack(h, c_black):
        return ls.Stack(1.0, [ls.Layer(1.5, h, coherent=False, alpha=2e-5, name="varnish")],
                        ls.KubelkaMunk(1.5, ls.Mixture(np.array([1.0, c_black]), [white, black]), None, 0.0))

    g = ls.Directional(45.0, 0.0)
    data = np.asarray(ls.reflectance(stack(2e4, 0.02), WL, g))
    data = data + 0.002 * np.random.default_rng(0).standard_normal(data.shape)
    objective = fitting.Objective(stack(1.5e4, 0.03), WL, fitting.Dataset(g, data, sigma=0.002),
                                  [fitting.thickness("varnish"),
                                   fitting.Parameter(("exit", "paint", "concentrations", 1), name="black")])
    report = fitting.fit(objective).report()
    assert "NOT IDENTIFIABLE" in report and "thickness[varnish]" in report and "black" in report
