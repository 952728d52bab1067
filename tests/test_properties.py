"""Property-based tests (hypothesis): identities every stack must satisfy.

* lossless stacks (coherent, incoherent, mixed): R + T = 1 per polarization and angle, both sides;
* diffuse (Lambertian) light on a lossless stack: r + t = 1 (Simonot eq. 19);
* reciprocity T_front = T_back for real outer media (eq. 44), absorbing or not;
* normal incidence: s and p coincide;
* absorbing stacks: 0 ≤ R, T and R + T ≤ 1.

The stack *structure* is fixed per test (so each compiles once); hypothesis draws the values
(indices, thicknesses, α, angles, wavelengths), which are traced leaves of jitted functions.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given
from hypothesis import strategies as st

import layerstack_jax as ls

TOL = 1e-12

n_real = st.floats(1.0, 3.0)
n_outer = st.floats(1.0, 2.0)
k_abs = st.floats(0.0, 5.0)
d_film = st.floats(0.0, 500.0)
h_thick = st.floats(500.0, 1e5)
alpha_st = st.floats(0.0, 1e-4)
angle_deg = st.floats(0.0, 89.0)
wl_nm = st.floats(300.0, 1500.0)

angles4 = st.lists(angle_deg, min_size=3, max_size=3).map(lambda a: jnp.deg2rad(jnp.array([0.0, *a])))
wls3 = st.lists(wl_nm, min_size=3, max_size=3).map(jnp.array)


def _stack(pattern, n, d, alpha=None):
    """pattern: string of 'c' / 'i'; n: indices of ambient, layers, exit (complex allowed for
    layers); d: thicknesses; alpha: per incoherent layer (or None)."""
    layers = []
    for j, ch in enumerate(pattern):
        nj = complex(n[j + 1])
        a = None if (alpha is None or ch == "c") else alpha[j]
        layers.append(ls.Layer(ls.Index(nj.real, nj.imag), d[j], coherent=(ch == "c"), alpha=a))
    return ls.Stack(float(n[0]), layers, ls.Substrate(float(n[-1])))


@jax.jit
def _spec(stack, wl, ang):
    return ls.specular(stack, wl, angle_rad=ang)


def _check_lossless(out, back_mask):
    """R + T = 1 from the front everywhere and from the back where light from the exit medium
    exists at that Snell invariant (``back_mask`` over the angle axis)."""
    for R, T in ((out.R_front, out.T_front), (out.R_back, out.T_back)):
        assert np.all(np.isfinite(np.asarray(R))) and np.all(np.isfinite(np.asarray(T)))
    assert float(jnp.max(jnp.abs(out.R_front + out.T_front - 1.0))) <= TOL
    assert float(jnp.max(jnp.abs(out.R_back + out.T_back - 1.0)[back_mask])) <= TOL


def _check_normal_and_reciprocity(out):
    # axis 0 of the angle axis is normal incidence
    assert float(jnp.max(jnp.abs(out.R_front[0, 0] - out.R_front[0, 1]))) <= 1e-14
    assert float(jnp.max(jnp.abs(out.T_front[0, 0] - out.T_front[0, 1]))) <= 1e-14
    assert float(jnp.max(jnp.abs(out.R_back[0, 0] - out.R_back[0, 1]))) <= 1e-14


def _reciprocity_mask(n0, ne, ang):
    """Angles at which light from the exit side exists at the same Snell invariant."""
    return np.asarray(n0 * np.sin(np.asarray(ang)) < ne * (1 - 1e-9))


@given(
    n=st.lists(n_real, min_size=3, max_size=3),
    outer=st.tuples(n_outer, n_outer),
    d=st.lists(d_film, min_size=3, max_size=3),
    ang=angles4,
    wl=wls3,
)
def test_lossless_coherent(n, outer, d, ang, wl):
    out = _spec(_stack("ccc", [outer[0], *n, outer[1]], d), wl, ang)
    m = _reciprocity_mask(outer[0], outer[1], ang)
    _check_lossless(out, m)
    _check_normal_and_reciprocity(out)
    assert float(jnp.max(jnp.abs(out.T_front - out.T_back)[m])) <= TOL


@given(
    n=st.lists(n_real, min_size=2, max_size=2),
    outer=st.tuples(n_outer, n_outer),
    h=st.lists(h_thick, min_size=2, max_size=2),
    ang=angles4,
    wl=wls3,
)
def test_lossless_incoherent(n, outer, h, ang, wl):
    out = _spec(_stack("ii", [outer[0], *n, outer[1]], h, [0.0, 0.0]), wl, ang)
    m = _reciprocity_mask(outer[0], outer[1], ang)
    _check_lossless(out, m)
    _check_normal_and_reciprocity(out)
    assert float(jnp.max(jnp.abs(out.T_front - out.T_back)[m])) <= TOL


@given(
    n=st.lists(n_real, min_size=4, max_size=4),
    outer=st.tuples(n_outer, n_outer),
    d=st.tuples(d_film, h_thick, d_film, d_film),
    ang=angles4,
    wl=wls3,
)
def test_lossless_mixed(n, outer, d, ang, wl):
    out = _spec(_stack("cicc", [outer[0], *n, outer[1]], d), wl, ang)
    m = _reciprocity_mask(outer[0], outer[1], ang)
    _check_lossless(out, m)
    _check_normal_and_reciprocity(out)
    assert float(jnp.max(jnp.abs(out.T_front - out.T_back)[m])) <= TOL


@given(
    n=st.lists(st.tuples(st.floats(0.05, 3.0), k_abs), min_size=4, max_size=4),
    k_thick=st.floats(0.0, 1e-4),
    outer=st.tuples(n_outer, n_outer),
    d=st.tuples(d_film, h_thick, d_film, d_film),
    alpha=alpha_st,
    ang=angles4,
    wl=wls3,
)
def test_absorbing_mixed_bounds_reciprocity_normal_incidence(n, k_thick, outer, d, alpha, ang, wl):
    idx = [complex(a, b) for a, b in n]
    idx[1] = complex(idx[1].real + 1.0, k_thick)  # the thick layer: n >= 1.05, weakly absorbing
    out = _spec(_stack("cicc", [outer[0], *idx, outer[1]], d, [None, alpha, None, None]), wl, ang)
    m = _reciprocity_mask(outer[0], outer[1], ang)
    for R, T, mask in ((out.R_front, out.T_front, slice(None)), (out.R_back, out.T_back, m)):
        R, T = np.asarray(R), np.asarray(T)
        assert np.all(np.isfinite(R)) and np.all(np.isfinite(T))
        R, T = R[mask], T[mask]
        assert np.all(R >= 0.0) and np.all(T >= 0.0)
        assert np.all(R + T <= 1.0 + 1e-13)
    _check_normal_and_reciprocity(out)
    assert float(jnp.max(jnp.abs(out.T_front - out.T_back)[m])) <= TOL


@jax.jit
def _diff(stack, wl):
    return ls.diffuse(stack, wl, "front"), ls.diffuse(stack, wl, "back")


@given(
    n=st.lists(n_real, min_size=3, max_size=3),
    outer=st.tuples(n_outer, n_outer),
    # films >= 1 nm: a zero-thickness film between index-matched media is the known jit NaN
    # (test_quadrature.py::test_jit_zero_thickness_film_between_index_matched_media)
    d=st.tuples(st.floats(1.0, 500.0), h_thick, st.floats(1.0, 500.0)),
    wl=wls3,
)
def test_diffuse_lossless_r_plus_t(n, outer, d, wl):
    """Eq. 19, and 0 <= r <= 1, for a lossless mixed stack, both sides, jitted (traced quadrature
    layout: split points at run time, zero-width segments kept)."""
    front, back = _diff(_stack("cic", [outer[0], *n, outer[1]], d), wl)
    for x in (front, back):
        assert float(jnp.max(jnp.abs(x.r + x.t - 1.0))) <= TOL
        assert bool(jnp.all((x.r >= 0.0) & (x.r <= 1.0)))
    # Lambertian reciprocity n0² t_front = n_exit² t_back holds for any stack (étendue)
    assert float(jnp.max(jnp.abs(outer[0] ** 2 * front.t - outer[1] ** 2 * back.t))) <= 1e-9
