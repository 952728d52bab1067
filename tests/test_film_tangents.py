"""Closed-form derivative of the coherent-film recursion (``_coherent._rouard``, a custom JVP).

Checked against three independent sources:

* the plain recursion written out here (:func:`_plain_rouard`: ``jnp.exp`` and two divisions per
  film, as before the closed form), differentiated by JAX's own rules: values to 1e-14,
  forward and reverse derivatives to 1e-12, for random complex inputs (unrolled and ``lax.scan``
  packets, each kind of tangent alone and together);
* the same, through the public API (``specular``, ``reflectance``) on physical stacks (the
  library's ``_rouard`` swapped for :func:`_plain_rouard` gives the reference derivative);
* central finite differences of the library's own values (rel. 1e-6), including metals (an
  opaque 10 µm film), a film at its own critical angle (the lifted branch point), total internal
  reflection and grazing incidence (no NaN).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_jax._kernels import coherent as _coherent
from layerstack_jax._kernels import coherent_derivatives as _derivatives
from _helpers import relative_error

WL = jnp.array([400.0, 533.0, 650.0, 780.0])


def _plain_rouard(r, t, phase):
    """The recursion of ``_coherent._rouard`` with no custom derivative (Hirayama eqs. 3-4)."""
    gamma, tau = r[-1], t[-1]
    for j in range(phase.shape[0] - 1, -1, -1):
        e1 = jnp.exp(1j * phase[j])
        e2 = e1 * e1
        den = 1.0 + r[j] * gamma * e2
        gamma, tau = (r[j] + gamma * e2) / den, t[j] * tau * e1 / den
    return gamma, tau



def _random_packet(rng, films: int, batch=(3, 5)):
    def c(*shape, scale=0.5):
        return jnp.asarray(scale * (rng.normal(size=shape) + 1j * rng.normal(size=shape)))

    r, t = c(films + 1, 2, *batch), c(films + 1, 2, *batch, scale=1.0)
    phase = jnp.asarray(rng.uniform(0, 7, (films, 1, *batch)) + 1j * rng.uniform(0, 0.6, (films, 1, *batch)))
    return r, t, phase


@pytest.mark.parametrize("films", [0, 1, 2, 3, 11])  # 11 > _SCAN_THRESHOLD: the lax.scan path
def test_rouard_matches_plain_recursion_values_and_derivatives(films):
    rng = np.random.default_rng(films)
    args = _random_packet(rng, films)
    tangents = _random_packet(rng, films)
    assert relative_error(_coherent._rouard(*args)[0], _plain_rouard(*args)[0]) <= 1e-14
    assert relative_error(_coherent._rouard(*args)[1], _plain_rouard(*args)[1]) <= 1e-14
    masks = [(1, 1, 1), (0, 0, 1), (1, 0, 0), (0, 1, 0), (1, 0, 1)] if films < 11 else [(1, 1, 1), (0, 0, 1)]

    def loss(fn):  # a real function of both outputs, for reverse mode
        return lambda *xs: jnp.sum(jnp.abs(fn(*xs)[0]) ** 2 + jnp.real((0.3 - 0.7j) * fn(*xs)[1]))

    @jax.jit
    def derivatives(args, tangents):
        out = []
        for mask in masks:
            def restrict(fn, mask=mask):
                return lambda *xs: fn(*[x if m else a for x, a, m in zip(xs, args, mask)])

            out.append([(jax.jvp(restrict(fn), args, tangents)[1], jax.grad(loss(restrict(fn)), argnums=(0, 1, 2))(*args))
                        for fn in (_coherent._rouard, _plain_rouard)])
        return out

    for mask, ((d_new, g_new), (d_ref, g_ref)) in zip(masks, derivatives(args, tangents)):
        for a, b in zip((*d_new, *g_new), (*d_ref, *g_ref)):
            assert relative_error(a, b) <= 1e-12, (mask, relative_error(a, b))


def _film_stack(d, kind):
    """Stacks of coherent films whose thicknesses are ``d`` (nm)."""
    if kind == "dielectric":
        return ls.Stack(1.0, [ls.Layer(2.3, d[0]), ls.Layer(1.46, d[1])], ls.Substrate(1.52))
    if kind == "metal":  # an opaque 10 µm aluminium-like film between two dielectric films
        return ls.Stack(1.0, [ls.Layer(1.46, d[0]), ls.Layer(ls.Index(0.96, 6.69), d[1]), ls.Layer(2.0, d[2])],
                        ls.Substrate(1.52))
    if kind == "thin-metal":  # silver-like 20 nm on glass, seen from the glass side through an air gap
        return ls.Stack(1.5, [ls.Layer(ls.Index(0.05, 3.3), d[0]), ls.Layer(1.0, d[1])], ls.Substrate(1.52))
    if kind == "many":  # 11 films: the lax.scan path
        return ls.Stack(1.0, [ls.Layer(2.3 if i % 2 else 1.46, d[i]) for i in range(11)], ls.Substrate(1.52))
    raise ValueError(kind)


_THICKNESS = {"dielectric": [80.0, 120.0], "metal": [60.0, 1e4, 90.0], "thin-metal": [20.0, 300.0],
              "many": [70.0 + 9.0 * i for i in range(11)]}
# 41.81°: the air gap of "thin-metal" exactly at its critical angle from the glass (q = 0, the
# lifted branch point); 60°: total internal reflection there; 89.9°: grazing.
_ANGLES = jnp.deg2rad(jnp.array([0.0, 35.0, float(np.degrees(np.arcsin(1 / 1.5))), 60.0, 89.9]))


def _spectrum(kind, angles=_ANGLES):
    """All four intensities of both polarizations, flattened: ``f(d) -> (n,)``."""
    def f(d):
        out = ls.specular(_film_stack(d, kind), WL, angle_rad=angles[:, None], both_sides=True)
        return jnp.concatenate([jnp.ravel(x) for x in (out.R_front, out.T_front, out.R_back, out.T_back)])
    return f


def _central_difference(f, x, j, h):
    """4th-order central difference of ``f`` along ``x[j]`` with step h."""
    e = jnp.zeros_like(x).at[j].set(h)
    return (8 * (f(x + e) - f(x - e)) - (f(x + 2 * e) - f(x - 2 * e))) / (12 * h)


def _with_plain_rouard(monkeypatch, fn, *args):
    """``fn()`` with the library's ``_rouard`` swapped for :func:`_plain_rouard`, every packet
    taking the derivative rule that calls it (beyond ``_SCAN_THRESHOLD`` films the library uses a
    loop-form rule of its own, which would otherwise be compared with itself)."""
    for module in (_coherent, _derivatives):  # the forward's packets and the stored-coefficient rule
        monkeypatch.setattr(module, "_rouard", _plain_rouard)
        monkeypatch.setattr(module, "_SCAN_THRESHOLD", 10 ** 6)
    try:
        return fn(*args)
    finally:
        monkeypatch.undo()


@pytest.mark.parametrize("kind", ["dielectric", "metal", "thin-metal", "many"])
def test_thickness_jacobian_matches_autodiff_and_finite_differences(kind, monkeypatch):
    f = _spectrum(kind)
    d = jnp.asarray(_THICKNESS[kind])
    jf = jax.jit(jax.jacfwd(f))(d)
    jr = jax.jit(jax.jacrev(f))(d)
    ref = _with_plain_rouard(monkeypatch, lambda: jax.jit(jax.jacfwd(f))(d))
    assert np.all(np.isfinite(np.asarray(jf))) and np.all(np.isfinite(np.asarray(jr)))
    # rows (quantity, angle, 1, pol, wl): at the critical angle (index 2) the air gap's q is the
    # lifted branch point, where the values themselves carry ~1e-11 of cancellation (the
    # silver case: R_back p 0.514353243257 vs 0.514353243263 in long double) and both
    # derivatives ~3e-10 (0.0219304008467 closed form, ...469 autodiff, ...404 long double)
    by_angle = [np.asarray(x).reshape(4, len(_ANGLES), -1, d.shape[0]) for x in (jf, jr, ref)]
    regular = [np.delete(x, 2, axis=1) for x in by_angle]
    for x in regular[:2]:
        assert relative_error(x, regular[2]) <= 1e-12, relative_error(x, regular[2])
    for x in by_angle[:2]:
        assert relative_error(x[:, 2], by_angle[2][:, 2]) <= 1e-9, relative_error(x[:, 2], by_angle[2][:, 2])
    # 4th-order central differences, per film (h = 0.05 nm, the opaque film 1 nm: the values'
    # ~1e-11 rounding noise at the branch point stays below 1e-8 of each column's scale)
    fj = jax.jit(f)
    for j in range(d.shape[0]):
        fd = _central_difference(fj, d, j, 1.0 if d[j] > 1e3 else 0.05)
        scale = max(float(jnp.max(jnp.abs(fd))), 1e-12)
        assert float(jnp.max(jnp.abs(jf[:, j] - fd))) <= 1e-6 * scale + 1e-13, (kind, j)


def test_opaque_film_has_no_sensitivity_below_it():
    """Nothing under an opaque metal film is seen from the front: the front reflectance's
    derivative with respect to the film below it is exactly 0 (the phase factor underflows),
    and that of the metal thickness itself too."""
    def r_front(d):
        out = ls.specular(_film_stack(d, "metal"), WL, angle_rad=_ANGLES[:, None], both_sides=False)
        return out.R_front
    jac = jax.jacfwd(r_front)(jnp.asarray(_THICKNESS["metal"]))
    assert np.all(np.asarray(jac[..., 1]) == 0.0) and np.all(np.asarray(jac[..., 2]) == 0.0)
    assert np.max(np.abs(np.asarray(jac[..., 0]))) > 1e-4


def test_index_gradients_match_autodiff(monkeypatch):
    """A film's index enters the interfaces' r, t and the phase: all three tangents at once."""
    def f(p):
        stack = ls.Stack(1.0, [ls.Layer(ls.Index(p[0], p[1]), 35.0), ls.Layer(p[2], 140.0)], ls.Substrate(1.52))
        out = ls.specular(stack, WL, angle_rad=_ANGLES[:, None], both_sides=True)
        return jnp.concatenate([jnp.ravel(x) for x in (out.R_front, out.T_front, out.R_back, out.T_back)])
    p = jnp.array([0.2, 3.1, 1.46])
    jf, jr = jax.jit(jax.jacfwd(f))(p), jax.jit(jax.jacrev(f))(p)
    ref = _with_plain_rouard(monkeypatch, lambda: jax.jit(jax.jacfwd(f))(p))
    assert np.all(np.isfinite(np.asarray(jf)))
    assert relative_error(jf, ref) <= 1e-12 and relative_error(jr, ref) <= 1e-12


def test_exact_grazing_incidence_is_finite():
    """90° from the ambient: zero flux, T = 0; values and derivatives finite."""
    f = _spectrum("dielectric", jnp.deg2rad(jnp.array([90.0])))
    d = jnp.asarray(_THICKNESS["dielectric"])
    assert np.all(np.isfinite(np.asarray(f(d))))
    for jac in (jax.jacfwd, jax.jacrev):
        assert np.all(np.isfinite(np.asarray(jax.jit(jac(f))(d))))


def _mixed(h):
    """Two films on an absorbing incoherent varnish over a Lambertian background (the P3 stack,
    benchmarks/mixed.py), 45°/0°, 8 nodes per hemisphere segment."""
    k = 2e-5 * WL / (4 * jnp.pi)
    stack = ls.Stack(1.0, [ls.Layer(2.3, h[0]), ls.Layer(1.46, h[1]), ls.Layer(ls.Index(1.6, k), h[2], coherent=False)],
                     ls.LambertianBackground(1.55, 0.6))
    return ls.reflectance(stack, WL, ls.Directional(45.0, 0.0), nodes=8)


def test_mixed_stack_jacobian_matches_autodiff_and_finite_differences(monkeypatch):
    h = jnp.array([80.0, 120.0, 1.2e4])
    jf = jax.jit(jax.jacfwd(_mixed))(h)
    jr = jax.jit(jax.jacrev(_mixed))(h)
    ref = _with_plain_rouard(monkeypatch, lambda: jax.jit(jax.jacfwd(_mixed))(h))
    assert relative_error(jf, ref) <= 1e-12 and relative_error(jr, ref) <= 1e-12
    fj = jax.jit(_mixed)
    for j, step in enumerate((0.05, 0.05, 1.0)):
        fd = _central_difference(fj, h, j, step)
        assert float(jnp.max(jnp.abs(jf[:, j] - fd))) <= 1e-6 * float(jnp.max(jnp.abs(fd))), j


def test_second_derivatives_match_autodiff(monkeypatch):
    """The custom JVP's rule is itself differentiable: the Hessian of a least-squares-like
    function of two film thicknesses equals that of the plain recursion (measured 1.9e-15)."""
    def f(d):
        return jnp.sum(_spectrum("dielectric")(d) ** 2)

    d = jnp.asarray(_THICKNESS["dielectric"])
    got = jax.jit(jax.hessian(f))(d)
    want = _with_plain_rouard(monkeypatch, lambda: jax.jit(jax.hessian(f))(d))
    assert relative_error(got, want) <= 1e-12, relative_error(got, want)
