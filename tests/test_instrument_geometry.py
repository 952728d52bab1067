"""Spectrophotometers as instruments do it (issue 15): the specular port's cone, the sphere
multiplier (wall and port reflectance), a cover glass, finite apertures of a 45/0 instrument —
each a differentiable field of the geometry, the ideal instrument by default.

References are independent of the code under test: closed forms written here, scipy adaptive
quadrature (``dblquad``) of the library's own *point* readings over the cones, and the stack
with the cover glass written out as layers.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import fitting as ft
import layerstack_jax as ls
from layerstack_cli._columns import polarized_columns
from layerstack_jax._instruments import optical_parts as G
from layerstack_jax._stacks.stack import resolve
from layerstack_jax._instruments.instrument import GAP_NM, cap_measure, cone_projected_solid_angle, cone_rule

WL = np.array([420.0, 550.0, 680.0])
GRID = jnp.asarray(WL)
#: hemispherical nodes: every comparison here is between readings that share the back-side
#: diffuse r_b, t_b (or between two spellings of one stack), so a small rule keeps them exact
#: and the tests fast
NODES = 8


def _stack(rho=0.7):
    """A coated background: a coherent film on a weakly absorbing varnish over a Lambertian
    background (the angle dependence of T then has interference and Beer structure)."""
    return ls.Stack(1.0, [ls.Layer(1.46, 180.0), ls.Layer(1.52, 20_000.0, coherent=False, alpha=2e-5)],
                    ls.LambertianBackground(1.5, rho))


ST = _stack()
#: one thick varnish over the background: a lighter program for the jit / gradient / fit tests
VARNISH = ls.Stack(1.0, [ls.Layer(1.52, 20_000.0, coherent=False, alpha=2e-5)], ls.LambertianBackground(1.5, 0.7))


# ------------------------------------------------------------------ the ideal instrument, bit for bit
def _old_sphere(rs, g, nodes):
    """The ideal sphere's reading as written before issue 15 (Simonot eqs. 69, 78)."""
    front = ls._stacks.recursion.join_interfaces(rs, G._incidence(rs, g.incidence_deg), both_sides=False)
    o = G._optics(g, rs, None, None, *G._back_hemisphere(rs, nodes), nodes=nodes)
    d, rho = G._diffuse_back(rs, o), rs.rho_g
    total = d.t * rho * ls._stacks.recursion.natural(front.T_front) / (1.0 - rho * d.r)
    return total + ls._stacks.recursion.natural(front.R_front) if g.specular == "included" else total


def _old_directional(rs, g, nodes):
    front = ls._stacks.recursion.join_interfaces(rs, G._incidence(rs, g.incidence_deg), both_sides=False)
    view = ls._stacks.recursion.join_interfaces(rs, G._incidence(rs, g.viewing_deg), both_sides=False)
    o = G._optics(g, rs, None, None, *G._back_hemisphere(rs, nodes), nodes=nodes)
    d, rho = G._diffuse_back(rs, o), rs.rho_g
    ratio = ls._kernels.fresnel.exit_medium_ratio(rs.n[0], rs.n[-1])
    nat = ls._stacks.recursion.natural
    return ratio * nat(front.T_front) * nat(view.T_front) * rho / (1.0 - rho * d.r)


def test_defaults_read_bit_for_bit_as_the_ideal_instrument():
    """Every new field at its default (or given as an explicit 0 / None) reads exactly what the
    ideal formulas read (array_equal, not allclose); through the public ``ls.reflectance`` (one
    compiled XLA program, whose fusions may round differently from the op-by-op formula) to 4 ulp."""
    rs = resolve(ST, WL)
    nodes = NODES
    for spec in ("excluded", "included"):
        want = np.asarray(_old_sphere(rs, ls.Sphere(8.0, spec), nodes))
        for g in (ls.Sphere(8.0, spec), ls.Sphere(8.0, spec, port_half_angle_deg=0.0, wall_reflectance=None,
                                                    sample_port_fraction=0.0, cover_index=None)):
            assert np.array_equal(np.asarray(g.measure(ST, WL, nodes=nodes)), want)
        np.testing.assert_array_max_ulp(np.asarray(ls.reflectance(ST, WL, g, nodes=nodes,
                                                                  optics=ls.fixed_optics(ST, WL, g, nodes=nodes))),
                                        want, maxulp=4)
    want = np.asarray(_old_directional(rs, ls.Directional(45.0, 0.0), nodes))
    for g in (ls.Directional(45.0, 0.0), ls.Directional(45.0, 0.0, 0.0, 0.0)):
        assert np.array_equal(np.asarray(g.measure(ST, WL, nodes=nodes)), want)
    assert ls.Sphere(8.0).label == "sphere:8:sce" and ls.Directional(45.0, 0.0).label == "45/0"


# ------------------------------------------------------------------ the cone rule
@pytest.mark.parametrize("axis, beta", [(0.0, 5.0), (8.0, 5.0), (8.0, 12.0), (30.0, 10.0), (45.0, 44.0)])
def test_cone_rule_closed_forms(axis, beta):
    """Solid angle 2π(1 − cos β) and projected solid angle π cos θ_a sin²β (the Lambertian
    fraction lost into the port is cos θ_a sin²β; at normal incidence sin²β), also for a cone
    that contains the normal (8°, 12°)."""
    cos_t, sin_t, w = cone_rule(axis, beta, 8)
    solid = cap_measure(beta) * jnp.sum(w, axis=-1)
    projected = cap_measure(beta) * jnp.sum(w * cos_t, axis=-1)
    assert float(solid) == pytest.approx(2 * np.pi * (1 - np.cos(np.deg2rad(beta))), rel=1e-14)
    closed = np.pi * np.cos(np.deg2rad(axis)) * np.sin(np.deg2rad(beta)) ** 2
    assert abs(float(projected) - closed) <= 1e-14
    assert abs(float(cone_projected_solid_angle(axis, beta)) - closed) <= 1e-15
    np.testing.assert_allclose(cos_t ** 2 + sin_t ** 2, 1.0, rtol=0, atol=1e-15)
    # every direction lies within β of the axis
    ax = np.array([np.sin(np.deg2rad(axis)), np.cos(np.deg2rad(axis))])
    assert np.all(np.asarray(cos_t) * ax[1] + np.asarray(sin_t) * ax[0] >= np.cos(np.deg2rad(beta)) - 1e-15)


def _normal_frame_cone_integral(f, axis, beta):
    """∫_cone f(θ) cos θ dΩ by scipy ``dblquad`` in the surface's own frame (polar θ, azimuth φ
    about the normal; an independent parametrisation from the library's cone frame): the cone
    holds the directions with cos θ cos θ_a + sin θ sin θ_a cos φ ≥ cos β."""
    a, b = np.deg2rad(axis), np.deg2rad(beta)

    def phi_max(t):
        if np.sin(a) * np.sin(t) == 0.0:
            return np.pi if np.cos(t - a) >= np.cos(b) else 0.0
        c = (np.cos(b) - np.cos(t) * np.cos(a)) / (np.sin(t) * np.sin(a))
        return float(np.arccos(np.clip(c, -1.0, 1.0)))

    lo, hi = max(0.0, a - b), a + b
    pieces = sorted({lo, hi, *([b - a] if lo < b - a < hi else [])})  # the kink where φ_max reaches π
    total = 0.0
    for t0, t1 in zip(pieces[:-1], pieces[1:]):
        val, err = integrate.dblquad(lambda p, t: f(t) * np.cos(t) * np.sin(t), t0, t1, 0.0, phi_max,
                                     epsabs=1e-13, epsrel=1e-12)
        total += 2.0 * val
    return total


@functools.lru_cache(maxsize=None)
def _point(ti, tv):
    """The library's ideal 45/0-type point reading of ST at (θ_i, θ_v) in radians, ``(wl,)``,
    cached (scipy asks for the same θ once per inner integral)."""
    return np.asarray(_directional_jit(jnp.float64(np.rad2deg(ti)), jnp.float64(np.rad2deg(tv))))


@jax.jit
def _directional_jit(ti, tv):
    return ls.Directional(ti, tv).measure(ST, GRID, nodes=NODES)


@pytest.mark.parametrize("axis, beta", [(8.0, 5.0), (8.0, 12.0), (30.0, 10.0)])
def test_port_cone_loss_matches_scipy(axis, beta):
    """SCE with a port cone: the ideal SCE reading minus the diffuse light leaving into the
    cone, (1/π) ∫_cone R_f(θ) cos θ dΩ with R_f the library's own 45/0-type reflectance factor
    (radiance) at (θ_0, θ): scipy dblquad against the library's fixed nodes, ≤ 1e-8."""
    ideal = np.asarray(ls.Sphere(axis).measure(ST, WL, nodes=NODES))
    coned = np.asarray(ls.Sphere(axis, port_half_angle_deg=beta).measure(ST, WL, nodes=NODES))
    at = _point
    t0 = np.deg2rad(axis)
    for k in range(len(WL)):
        lost = _normal_frame_cone_integral(lambda t: at(t0, t)[k], axis, beta) / np.pi
        assert abs((ideal[k] - coned[k]) - lost) <= 1e-8, (k, ideal[k] - coned[k], lost)
    assert np.all(ideal - coned > 1e-4)  # a visible loss (~ cos θ0 sin²β of the diffuse part)


def test_port_cone_lambertian_limit():
    """A bare Lambertian background seen from a medium of its own index (no interface: T = 1,
    the exit radiance is constant): the fraction of the diffuse reading lost into the port is
    exactly cos θ_0 sin²β."""
    bare = ls.Stack(1.0, [], ls.LambertianBackground(1.0, 0.6))
    for axis, beta in ((0.0, 7.0), (8.0, 5.0), (20.0, 15.0)):
        ideal = np.asarray(ls.Sphere(axis).measure(bare, WL, nodes=48))
        coned = np.asarray(ls.Sphere(axis, port_half_angle_deg=beta).measure(bare, WL, nodes=48))
        frac = np.cos(np.deg2rad(axis)) * np.sin(np.deg2rad(beta)) ** 2
        np.testing.assert_allclose(1.0 - coned / ideal, frac, rtol=1e-12)


def test_port_cone_under_jit_gradient_and_errors():
    """The half-angle is a traced leaf: at β = 0 the compiled reading is the ideal one and its
    derivative is finite (and 0: the loss is ∝ sin²β), also with the port on the normal; at 6°
    the derivative matches a central difference; a cone below the horizon is refused eagerly
    and at run time, naming the field."""
    f = jax.jit(lambda b, axis: ls.Sphere(axis, port_half_angle_deg=b).measure(VARNISH, GRID, nodes=NODES))
    np.testing.assert_allclose(f(0.0, 8.0), ls.Sphere(8.0).measure(VARNISH, WL, nodes=NODES), rtol=0, atol=1e-15)
    g = jax.jit(jax.grad(lambda b, axis: f(b, axis)[1]))
    assert float(g(0.0, 8.0)) == 0.0 and float(g(0.0, 0.0)) == 0.0
    h = 1e-4
    fd = (float(f(6.0 + h, 8.0)[1]) - float(f(6.0 - h, 8.0)[1])) / (2 * h)
    assert float(g(6.0, 8.0)) == pytest.approx(fd, rel=1e-6)
    with pytest.raises(ls.LayerstackError, match="port_half_angle_deg"):
        ls.Sphere(8.0, port_half_angle_deg=85.0)
    with pytest.raises(ls.LayerstackError, match="port_half_angle_deg"):
        ls.Sphere(8.0, port_half_angle_deg=-1.0)
    with pytest.raises(Exception, match="port_half_angle_deg"):
        jax.block_until_ready(f(85.0, 8.0))
    with pytest.raises(ls.LayerstackError, match="SCE only"):
        ls.Sphere(8.0, "included", port_half_angle_deg=5.0)


# ------------------------------------------------------------------ sphere multiplier
def _substitution_closed_form(stack, ideal, rho_w, fs, fh, rho_ref, nodes=None):
    """R = ρs (1 − ρw(1 − fs − fh) − ρref fs) / (1 − ρw(1 − fs − fh) − ρ's fs), with ρ's the
    hemispherical reflectance for Lambertian light, r_f + t_f ρg t_b / (1 − ρg r_b)."""
    nodes = NODES if nodes is None else nodes
    front = ls.diffuse(stack, WL, "front", nodes=nodes)
    if isinstance(stack.exit, ls.LambertianBackground):
        back = ls.diffuse(stack, WL, "back", nodes=nodes)
        rho = stack.exit.reflectance
        lam = np.asarray(front.r) + np.asarray(front.t) * rho * np.asarray(back.t) / (1 - rho * np.asarray(back.r))
    else:
        lam = np.asarray(front.r)
    fw = 1.0 - fs - fh
    return ideal * (1 - rho_w * fw - rho_ref * fs) / (1 - rho_w * fw - lam * fs)


@pytest.mark.parametrize("spec", ["excluded", "included"])
def test_sphere_multiplier_matches_closed_form(spec):
    """Wall reflectance 0.97, sample port 3 %, open ports 2 %, reference 0.99: the reading
    equals the substitution formula written here ≤ 1e-12; with f_s = 0 it is the ideal
    reading; with the port cone as well, ρ_s is the coned reading."""
    ideal = np.asarray(ls.Sphere(8.0, spec).measure(ST, WL, nodes=NODES))
    g = ls.Sphere(8.0, spec, wall_reflectance=0.97, sample_port_fraction=0.03, open_port_fraction=0.02,
                  reference_reflectance=0.99)
    got = np.asarray(g.measure(ST, WL, nodes=NODES))
    want = _substitution_closed_form(ST, ideal, 0.97, 0.03, 0.02, 0.99)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert np.all(np.abs(got - ideal) > 1e-3)  # a dark sample against a white standard reads low
    np.testing.assert_allclose(ls.invert_background(ST, WL, got, g, nodes=NODES), 0.7, rtol=0, atol=1e-12)
    zero = ls.Sphere(8.0, spec, wall_reflectance=0.97, sample_port_fraction=0.0, open_port_fraction=0.02)
    np.testing.assert_allclose(zero.measure(ST, WL, nodes=NODES), ideal, rtol=1e-15, atol=0)
    # spectra: the wall given on the grid, the reference defaulting to the wall
    wall = np.array([0.95, 0.97, 0.98])
    got = ls.Sphere(8.0, spec, wall_reflectance=wall, sample_port_fraction=0.03).measure(ST, WL, nodes=NODES)
    np.testing.assert_allclose(got, _substitution_closed_form(ST, ideal, wall, 0.03, 0.0, wall), rtol=0, atol=1e-12)
    if spec == "excluded":
        coned = np.asarray(ls.Sphere(8.0, port_half_angle_deg=5.0).measure(ST, WL, nodes=NODES))
        both = ls.Sphere(8.0, port_half_angle_deg=5.0, wall_reflectance=0.97, sample_port_fraction=0.03)
        np.testing.assert_allclose(both.measure(ST, WL, nodes=NODES), _substitution_closed_form(ST, coned, 0.97, 0.03, 0.0, 0.97),
                                   rtol=0, atol=1e-12)


def test_sphere_multiplier_over_a_substrate_and_errors():
    """Over a specular substrate (SCI: ρ_s = R(θ0), ρ'_s = its diffuse r_f); a reference sample
    reads its own reflectance; fractions without a wall reflectance and fractions adding up
    to more than 1 are refused, naming the field."""
    sub = ls.Stack(1.0, [ls.Layer(2.0, 80.0)], ls.Substrate(1.5))
    ideal = np.asarray(ls.Sphere(8.0, "included").measure(sub, WL, nodes=NODES))
    g = ls.Sphere(8.0, "included", wall_reflectance=0.98, sample_port_fraction=0.04, reference_reflectance=0.5)
    np.testing.assert_allclose(g.measure(sub, WL, nodes=NODES), _substitution_closed_form(sub, ideal, 0.98, 0.04, 0.0, 0.5),
                               rtol=0, atol=1e-12)
    from layerstack_jax._instruments.instrument import substituted_reading
    assert float(substituted_reading(0.42, 0.42, 0.98, 0.05, 0.01, 0.42)) == pytest.approx(0.42, rel=1e-15)
    with pytest.raises(ls.LayerstackError, match="wall_reflectance"):
        ls.Sphere(8.0, sample_port_fraction=0.03)
    with pytest.raises(ls.LayerstackError, match="sample_port_fraction"):
        ls.Sphere(8.0, wall_reflectance=0.98, sample_port_fraction=0.7, open_port_fraction=0.5)
    with pytest.raises(ls.LayerstackError, match="wall_reflectance"):
        ls.Sphere(8.0, wall_reflectance=1.2)
    f = jax.jit(lambda w: ls.Sphere(8.0, "included", wall_reflectance=w, sample_port_fraction=0.04).measure(sub, GRID))
    np.testing.assert_allclose(f(0.98), ls.Sphere(8.0, "included", wall_reflectance=0.98,
                                                  sample_port_fraction=0.04).measure(sub, WL), rtol=1e-14)
    with pytest.raises(Exception, match="wall_reflectance"):
        jax.block_until_ready(f(1.2))


# ------------------------------------------------------------------ cover glass
def _written_out(stack, n, d, alpha, contact):
    glass = [ls.Layer(n, d, coherent=False, alpha=alpha, name="cover")]
    gap = [] if contact else [ls.Layer(1.0, GAP_NM, coherent=False, name="gap")]
    return ls.Stack(stack.ambient, [*glass, *gap, *stack.layers], stack.exit)


@pytest.mark.parametrize("contact", [False, True])
def test_cover_glass_is_the_stack_with_the_glass_written_out(contact):
    """Sphere SCE/SCI (with a port cone), 45/0 (with apertures) and the Substrate case: the
    reading through the cover glass equals the same geometry on the stack with the glass (and
    the air gap) written out as incoherent layers, ≤ 1e-12; invert_background recovers ρg."""
    cover = dict(cover_index=1.52, cover_thickness_nm=1.0e6, cover_alpha_per_nm=1e-7, cover_contact=contact)
    out = _written_out(ST, 1.52, 1.0e6, 1e-7, contact)
    for g, bare in ((ls.Sphere(8.0, **cover), ls.Sphere(8.0)),
                    (ls.Sphere(8.0, "included", **cover), ls.Sphere(8.0, "included")),
                    (ls.Sphere(8.0, port_half_angle_deg=4.0, **cover), ls.Sphere(8.0, port_half_angle_deg=4.0)),
                    (ls.Directional(45.0, 0.0, 2.0, 3.0, **cover), ls.Directional(45.0, 0.0, 2.0, 3.0))):
        got = np.asarray(g.measure(ST, WL, nodes=NODES))
        np.testing.assert_allclose(got, bare.measure(out, WL, nodes=NODES), rtol=0, atol=1e-12)
        assert np.all(np.abs(got - np.asarray(bare.measure(ST, WL, nodes=NODES))) > 1e-4)
        np.testing.assert_allclose(ls.invert_background(ST, WL, got, g, nodes=NODES), 0.7, rtol=0, atol=1e-12)
    sub = ls.Stack(1.0, [ls.Layer(2.0, 80.0)], ls.Substrate(1.5))
    np.testing.assert_allclose(ls.Sphere(8.0, "included", **cover).measure(sub, WL, nodes=NODES),
                               ls.Sphere(8.0, "included").measure(_written_out(sub, 1.52, 1.0e6, 1e-7, contact), WL,
                                                                   nodes=NODES),
                               rtol=0, atol=1e-12)


def test_cover_glass_checks():
    with pytest.raises(ls.LayerstackError, match="cover_index"):
        ls.Sphere(8.0, cover_index=-1.5)
    with pytest.raises(ls.LayerstackError, match="cover_thickness_nm"):
        ls.Directional(45.0, 0.0, cover_index=1.5, cover_thickness_nm=-1.0)
    f = jax.jit(lambda n: ls.Sphere(8.0, cover_index=n).measure(ST, GRID, nodes=NODES))
    with pytest.raises(Exception, match="cover"):
        jax.block_until_ready(f(-1.0))


# ------------------------------------------------------------------ apertures of 45/0
def _aperture_mean(f, axis, beta):
    """∫_cone f cos θ dΩ / ∫_cone cos θ dΩ (scipy; the denominator in closed form)."""
    return _normal_frame_cone_integral(f, axis, beta) / (np.pi * np.cos(np.deg2rad(axis)) * np.sin(np.deg2rad(beta)) ** 2)


def test_apertures_match_scipy():
    """45/0 with a 3° illumination cone (viewing a point) and with a 5° viewing cone about the
    normal (illumination a point): the cos θ dΩ-weighted mean of the library's point reading
    by scipy dblquad ≤ 1e-8; both cones: the product structure of the point reading
    (R(θi, θv) R(θi0, θv0) = R(θi, θv0) R(θi0, θv), checked here on random angles) makes the
    double mean the product of the single ones over the central reading."""
    at = _point
    ill = np.asarray(ls.Directional(45.0, 0.0, illumination_half_angle_deg=3.0).measure(ST, WL, nodes=NODES))
    view = np.asarray(ls.Directional(45.0, 0.0, viewing_half_angle_deg=5.0).measure(ST, WL, nodes=NODES))
    point = np.asarray(ls.Directional(45.0, 0.0).measure(ST, WL, nodes=NODES))
    ti, tv = np.deg2rad(45.0), 0.0
    for k in range(len(WL)):
        assert abs(ill[k] - _aperture_mean(lambda t: at(t, tv)[k], 45.0, 3.0)) <= 1e-8
        assert abs(view[k] - _aperture_mean(lambda t: at(ti, t)[k], 0.0, 5.0)) <= 1e-8
    assert np.all(np.abs(ill - point) > 1e-7) and np.all(np.abs(view - point) > 1e-7)
    rng = np.random.default_rng(7)
    for a, b, c, d in rng.uniform(0.0, 1.2, size=(3, 4)):
        np.testing.assert_allclose(at(a, b) * at(c, d), at(a, d) * at(c, b), rtol=1e-12)
    both = np.asarray(ls.Directional(45.0, 0.0, 3.0, 5.0).measure(ST, WL, nodes=NODES))
    np.testing.assert_allclose(both, ill * view / point, rtol=1e-13)


def test_apertures_arrays_jit_and_inversion():
    """Array angles (*angle, wl); compiled with traced half-angles and angle it equals the eager
    reading, with a finite gradient at 0; invert_background recovers ρg through the apertures;
    a cone below the horizon is refused."""
    g = ls.Directional(np.array([45.0, 30.0]), 0.0, 2.0, 4.0)
    r = np.asarray(g.measure(VARNISH, WL, nodes=NODES))
    assert r.shape == (2, 3)
    np.testing.assert_allclose(ls.invert_background(VARNISH, WL, r, g, nodes=NODES), 0.7, rtol=0, atol=1e-12)
    f = jax.jit(lambda bi, bv, ti: ls.Directional(ti, 0.0, bi, bv).measure(VARNISH, GRID, nodes=NODES))
    np.testing.assert_allclose(f(2.0, 4.0, 45.0), r[0], rtol=1e-14)
    np.testing.assert_allclose(f(2.0, 4.0, 30.0), r[1], rtol=1e-14)
    np.testing.assert_allclose(f(0.0, 0.0, 45.0), ls.Directional(45.0, 0.0).measure(VARNISH, WL, nodes=NODES),
                               rtol=1e-14)
    grad = jax.jit(jax.grad(lambda b: f(b, b, 45.0)[0]))
    assert np.isfinite(float(grad(0.0))) and np.isfinite(float(grad(3.0)))
    with pytest.raises(ls.LayerstackError, match="illumination_half_angle_deg"):
        ls.Directional(80.0, 0.0, illumination_half_angle_deg=15.0)


# ------------------------------------------------------------------ CLI spellings
def test_cli_spellings_round_trip():
    for text in ("sphere:8:sce:cone=5", "sphere:8:sci:wall=0.98:port=0.03:open=0.02:ref=0.99",
                 "sphere:8:sce:cone=4:cover=1.52:cover_d=1e+06:contact", "45/0:illum=2:view=4", "0/45:cover=1.5"):
        g = ls.parse_geometry(text)
        assert ls.parse_geometry(g.label) == g, (text, g.label)
    g = ls.parse_geometry("sphere:8:sce:cone=5")
    assert isinstance(g, ls.Sphere) and float(g.port_half_angle_deg) == 5.0
    g = ls.parse_geometry("45/0:illum=2:view=4")
    assert float(g.illumination_half_angle_deg) == 2.0 and float(g.viewing_half_angle_deg) == 4.0
    with pytest.raises(ls.LayerstackError, match="bogus"):
        ls.parse_geometry("sphere:8:sce:bogus=1")
    with pytest.raises(ls.LayerstackError, match="SCE only"):
        ls.parse_geometry("sphere:8:sci:cone=5")
    # the old spellings are untouched
    assert ls.parse_geometry("brdf:45:0") == ls.BRDF(45.0, 0.0)
    assert ls.parse_geometry("specular:30") == ls.Specular(30.0)


# ------------------------------------------------------------------ fittable
def test_fit_recovers_port_half_angle():
    """The port cone's half-angle, freed with fitting.instrument, recovered from noise-free
    synthetic SCE spectra (true 6°, start 3°) to rel 1e-4, with ρg fitted alongside."""
    wl = np.linspace(420.0, 680.0, 3)
    data = np.asarray(ls.Sphere(8.0, port_half_angle_deg=6.0).measure(VARNISH, wl, nodes=NODES))
    ds = [ft.Dataset(ls.Sphere(8.0, port_half_angle_deg=3.0), data, sigma=1e-3)]
    params = [ft.instrument("port_half_angle_deg", lower=0.0, upper=30.0)]
    obj = ft.Objective(VARNISH, wl, ds, params, nodes=NODES)
    res = ft.fit(obj)
    assert res.converged
    assert res.values["port_half_angle_deg"] == pytest.approx(6.0, rel=1e-4)


def test_fit_recovers_cover_index():
    """The cover glass's index (45/0, air gap) recovered from noise-free synthetic data (true
    1.52, start 1.45) to rel 1e-4."""
    wl = np.linspace(420.0, 680.0, 3)
    true = ls.Directional(45.0, 0.0, cover_index=1.52, cover_thickness_nm=1e6)
    data = np.asarray(true.measure(VARNISH, wl, nodes=NODES))
    start = eqx.tree_at(lambda g: g.cover_index, true, 1.45)
    obj = ft.Objective(VARNISH, wl, [ft.Dataset(start, data, sigma=1e-3)],
                       [ft.instrument("cover_index", lower=1.2, upper=2.0)], nodes=NODES)
    res = ft.fit(obj)
    assert res.converged
    assert res.values["cover_index"] == pytest.approx(1.52, rel=1e-4)


def test_optics_of_another_aperture_or_port_are_refused():
    """fixed_optics made for the ideal instrument are not silently reused by one with a cone
    (nor the other way round): a LayerstackError says to rebuild them."""
    ideal = ls.fixed_optics(VARNISH, WL, ls.Directional(45.0, 0.0), nodes=NODES)
    with pytest.raises(ls.LayerstackError, match="rebuild"):
        ls.reflectance(VARNISH, WL, ls.Directional(45.0, 0.0, 2.0, 0.0), nodes=NODES, optics=ideal)
    coned = ls.fixed_optics(VARNISH, WL, ls.Directional(45.0, 0.0, 0.0, 3.0), nodes=NODES)
    with pytest.raises(ls.LayerstackError, match="rebuild"):
        ls.reflectance(VARNISH, WL, ls.Directional(45.0, 0.0), nodes=NODES, optics=coned)
    np.testing.assert_allclose(ls.reflectance(VARNISH, WL, ls.Directional(45.0, 0.0, 0.0, 3.0), nodes=NODES,
                                              optics=coned),
                               ls.Directional(45.0, 0.0, 0.0, 3.0).measure(VARNISH, WL, nodes=NODES), rtol=1e-15)
    plain = ls.fixed_optics(VARNISH, WL, ls.Sphere(8.0), nodes=NODES)
    with pytest.raises(ls.LayerstackError, match="rebuild"):
        ls.reflectance(VARNISH, WL, ls.Sphere(8.0, port_half_angle_deg=5.0), nodes=NODES, optics=plain)


def test_brdf_as_built_is_the_directional_reading_over_pi():
    """BRDF takes the same apertures and cover glass: its reading is Directional's / π (eq. 76);
    ideal by default (to 4 ulp: BRDF's reading is its own compiled program); spelled brdf:I:V:illum=…; the polarized BRDF refuses them."""
    kw = dict(illumination_half_angle_deg=2.0, viewing_half_angle_deg=3.0, cover_index=1.5)
    got = np.asarray(ls.BRDF(45.0, 0.0, **kw).measure(VARNISH, WL, nodes=NODES))
    want = np.asarray(ls.Directional(45.0, 0.0, **kw).measure(VARNISH, WL, nodes=NODES)) / np.pi
    np.testing.assert_allclose(got, want, rtol=1e-15)
    np.testing.assert_allclose(ls.invert_background(VARNISH, WL, got, ls.BRDF(45.0, 0.0, **kw), nodes=NODES), 0.7,
                               rtol=0, atol=1e-12)
    ideal = np.asarray(ls.BRDF(45.0, 0.0).measure(VARNISH, WL, nodes=NODES))
    np.testing.assert_array_max_ulp(ideal, np.asarray(ls.Directional(45.0, 0.0).measure(VARNISH, WL, nodes=NODES))
                                    / np.pi, maxulp=4)
    g = ls.parse_geometry("brdf:45:0:illum=2:view=3:cover=1.5")
    assert g == ls.BRDF(45.0, 0.0, **kw) and ls.parse_geometry(g.label) == g
    assert ls.BRDF(45.0, 0.0).label == "brdf:45:0"
    with pytest.raises(ls.LayerstackError, match="ideal instrument"):
        polarized_columns(g, VARNISH, WL, "brdf", "ss", NODES)
