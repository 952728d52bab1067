"""The derivative of a coherent packet (``_coherent._packet``, a custom JVP in the loop form of
its forward: ``_derivatives._packet_sweep``) against JAX's own derivative of a plain packet written out here
(:func:`_plain_packet`: ``jnp.sqrt``, the Fresnel formulas, ``jnp.exp`` and complex division,
no custom rule): values to 1e-13, forward and reverse derivatives to 1e-12, for every kind of
tangent alone and all together, from one film to eleven (short packets by both rules), with an opaque
metal film (its phase factor underflows) and an absorbing exit medium; and through the public
API (``specular``) with the library's ``_packet`` swapped for the plain one. Also
``_fresnel.reciprocal`` against numpy.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_jax._kernels import coherent as _coherent
from layerstack_jax._kernels import coherent_derivatives as _derivatives
from layerstack_jax._kernels.fresnel import reciprocal
from _helpers import relative_error


def _decaying_sqrt(n, s):
    """sqrt(n² - s²) with Im >= 0 (the decaying wave), from the principal ``jnp.sqrt``."""
    w = jnp.sqrt(n * n - (s * s).astype(n.dtype))
    return jnp.where(jnp.imag(w) < 0, -w, w)


def _plain_packet(n, q_ends, d, s, wavelength):
    """(gamma, tau) ``(2, *B)`` of a packet by the textbook recursion (Hirayama eqs. 1-4, 24),
    differentiated by JAX's own rules."""
    films = n.shape[0] - 2
    q = [q_ends[0]] + [_decaying_sqrt(n[j], s) for j in range(1, films + 1)] + [q_ends[1]]

    def fresnel(j):  # interface j -> j + 1
        ni, nf, qi, qf = n[j], n[j + 1], q[j], q[j + 1]
        r_s, t_s = (qi - qf) / (qi + qf), 2 * qi / (qi + qf)
        den = nf ** 2 * qi + ni ** 2 * qf
        r_p, t_p = (nf ** 2 * qi - ni ** 2 * qf) / den, 2 * ni * nf * qi / den
        return jnp.stack(jnp.broadcast_arrays(r_s, r_p)), jnp.stack(jnp.broadcast_arrays(t_s, t_p))

    gamma, tau = fresnel(films)
    for j in range(films, 0, -1):  # film j, the interface above it j - 1
        r, t = fresnel(j - 1)
        e1 = jnp.exp(1j * (2 * jnp.pi / wavelength).astype(q[j].dtype) * q[j] * d[j - 1].astype(q[j].dtype))
        den = 1.0 + r * gamma * e1 * e1
        gamma, tau = (r + gamma * e1 * e1) / den, t * tau * e1 / den
    return gamma, tau



def _inputs(rng, films: int, metal: bool = False):
    """A physical packet on a (3 angles, 4 wavelengths) grid: absorbing films, an absorbing exit
    medium, thicknesses 20-300 nm (film 1 of a metal packet an opaque 10 µm)."""
    wl = jnp.asarray(np.linspace(420.0, 810.0, 4))[None, :]
    n_film = 1.3 + 1.2 * rng.uniform(size=(films, 1, 4)) + 1j * 0.05 * rng.uniform(size=(films, 1, 4))
    if metal:
        n_film[1 % films] = 0.96 + 6.69j
    n = jnp.asarray(np.concatenate([np.full((1, 1, 4), 1.0 + 0j), n_film, np.full((1, 1, 4), 1.52 + 0.01j)]))
    s = jnp.asarray(np.sin(np.deg2rad([0.0, 37.0, 71.0])))[:, None]
    q_ends = jnp.stack([_decaying_sqrt(n[0], s), _decaying_sqrt(n[-1], s)])
    d = rng.uniform(20.0, 300.0, size=(films, 1, 1))
    if metal:
        d[1 % films] = 1e4
    return n, q_ends, jnp.asarray(d), s, wl


def _tangents(rng, args):
    n, q_ends, d, s, wl = args
    c = lambda x: jnp.asarray(rng.normal(size=x.shape) + 1j * rng.normal(size=x.shape))
    return (c(n), c(q_ends), jnp.asarray(rng.normal(size=d.shape)), jnp.asarray(rng.normal(size=s.shape)),
            jnp.asarray(rng.normal(size=wl.shape)))


_MASKS = [(0, 0, 1, 0, 0), (1, 0, 0, 0, 0), (0, 1, 0, 0, 0), (0, 0, 0, 1, 0), (0, 0, 0, 0, 1), (1, 0, 1, 0, 0),
          (1, 1, 1, 1, 1)]


_THRESHOLD = _coherent._SCAN_THRESHOLD  # before any test lowers it


@pytest.fixture(params=["default", "sweep"])
def path(request, monkeypatch):
    """Short packets take the stored-coefficient rule by default; "sweep" forces the loop form
    (``_packet_jvp_sweep``) for any number of films."""
    if request.param == "sweep":
        for module in (_coherent, _derivatives):  # the forward's loops and the rule's choice of form
            monkeypatch.setattr(module, "_SCAN_THRESHOLD", 0)
    return request.param


# 11 films (the loop form by default, as "sweep" forces it for 1 and 3): ~90 s of compiling
@pytest.mark.parametrize("films,metal", [(1, False), (3, True), pytest.param(11, True, marks=pytest.mark.slow)])
def test_packet_matches_plain_values_and_derivatives(films, metal, path):
    if films > _THRESHOLD and path == "sweep":
        pytest.skip("the default already")
    rng = np.random.default_rng(100 + films)
    args = _inputs(rng, films, metal)
    tangents = _tangents(rng, args)
    got, want = jax.jit(_coherent._packet)(*args), _plain_packet(*args)
    for a, b in zip(got, want):
        assert relative_error(a, b) <= 1e-13, relative_error(a, b)

    def loss(fn):  # a real function of both outputs, for reverse mode
        def f(*xs):
            gamma, tau = fn(*xs)
            return jnp.sum(jnp.abs(gamma) ** 2 + jnp.real((0.3 - 0.7j) * tau) + jnp.abs(tau) ** 2)
        return f

    @jax.jit
    def derivatives(args, tangents):
        out = []
        for mask in _MASKS:
            live = [i for i, m in enumerate(mask) if m]

            def restrict(fn):
                def g(*xs):
                    full = list(args)
                    for i, x in zip(live, xs):
                        full[i] = x
                    return fn(*full)
                return g

            primals = tuple(args[i] for i in live)
            pair = []
            for fn in (_coherent._packet, _plain_packet):
                jvp = jax.jvp(restrict(fn), primals, tuple(tangents[i] for i in live))[1]
                grad = jax.grad(loss(restrict(fn)), argnums=tuple(range(len(live))))(*primals)
                pair.append((jvp, grad))
            out.append(pair)
        return out

    for mask, ((d_new, g_new), (d_ref, g_ref)) in zip(_MASKS, derivatives(args, tangents)):
        for a, b in zip((*d_new, *g_new), (*d_ref, *g_ref)):
            assert relative_error(a, b) <= 1e-12, (mask, relative_error(a, b))


def test_thickness_gradient_of_reflectance_only():
    """The P1 case's form: the gradient of a mean reflectance (τ has no cotangent) with
    respect to the thicknesses alone, as a jitted value-and-gradient."""
    rng = np.random.default_rng(7)
    n, q_ends, d, s, wl = _inputs(rng, 10)

    def mean_r(fn):
        return lambda d_: jnp.mean(jnp.abs(fn(n, q_ends, d_, s, wl)[0]) ** 2)

    v, g = jax.jit(jax.value_and_grad(mean_r(_coherent._packet)))(d)
    v_ref, g_ref = jax.value_and_grad(mean_r(_plain_packet))(d)
    assert abs(float(v) - float(v_ref)) <= 1e-14
    assert relative_error(g, g_ref) <= 1e-12, relative_error(g, g_ref)


@pytest.mark.parametrize("kind", ["thickness", "index"])
def test_specular_derivatives_match_plain_packet(kind, path, monkeypatch):
    """Through the public API: jacfwd and jacrev of all four intensities equal those with the
    library's packet replaced by the plain one (no custom rule)."""
    wl = jnp.array([400.0, 533.0, 650.0, 780.0])
    angles = jnp.deg2rad(jnp.array([0.0, 35.0, 60.0, 80.0]))[:, None]

    def f(p):
        if kind == "thickness":
            layers = [ls.Layer(2.3, p[0]), ls.Layer(ls.Index(0.2, 3.1), p[1]), ls.Layer(1.46, p[2])]
        else:
            layers = [ls.Layer(ls.Index(p[0], p[1]), 35.0), ls.Layer(p[2], 140.0), ls.Layer(2.0, 90.0)]
        out = ls.specular(ls.Stack(1.0, layers, ls.Substrate(1.52)), wl, angle_rad=angles, both_sides=True)
        return jnp.concatenate([jnp.ravel(x) for x in (out.R_front, out.T_front, out.R_back, out.T_back)])

    p = jnp.array([80.0, 25.0, 120.0]) if kind == "thickness" else jnp.array([0.2, 3.1, 1.46])
    jf, jr = jax.jit(jax.jacfwd(f))(p), jax.jit(jax.jacrev(f))(p)
    monkeypatch.setattr(_coherent, "_packet", _plain_packet)
    ref = jax.jit(jax.jacfwd(f))(p)
    assert np.all(np.isfinite(np.asarray(jf)))
    assert relative_error(jf, ref) <= 1e-12 and relative_error(jr, ref) <= 1e-12, (relative_error(jf, ref), relative_error(jr, ref))


def test_reciprocal_matches_numpy():
    rng = np.random.default_rng(3)
    w = (rng.normal(size=10000) + 1j * rng.normal(size=10000)) * 10.0 ** rng.uniform(-3, 3, size=10000)
    got = np.asarray(jax.jit(reciprocal)(jnp.asarray(w)))
    want = 1.0 / w
    assert np.max(np.abs(got - want) / np.abs(want)) <= 2.5 * np.finfo(np.float64).eps  # ~2 ulp
