r"""Hemispherical (Lambertian) integrals on fixed, critical-angle-aware Gauss–Legendre nodes.

A Lambertian flux arriving on a stack from medium *f* gives the diffuse reflectance
(Simonot et al. eqs. 18, 47, 62)

.. math::
    r = \int_0^{\pi/2} R(\theta)\sin 2\theta\, d\theta = \int_0^1 R(\mu)\, d\mu,
    \qquad \mu = \sin^2\theta,\; s = n_f\sqrt{\mu},

and likewise the diffuse transmittance (eqs. 49, 63). :math:`R(\mu)` has square-root branch
points at every critical angle :math:`\mu_c = (n_j/n_f)^2 < 1` of a thick medium *j* and at grazing
incidence :math:`\mu = 1` (PHYSICS.md, trap 4). Thin coherent films add none: the response of a
finite film is even in its own :math:`q_j`. We therefore split [0, 1] at the critical angles
and, on each segment :math:`[a, b]`, substitute :math:`\mu = a + (b-a)\,g(g(v))` with
:math:`g(v) = (1-\cos\pi v)/2`, then apply Gauss–Legendre in v. One application of g already
turns square-root end-point singularities on both sides into smooth integrands (16 nodes give
3e-13 on the internal diffuse reflectance of glass); the second one clusters nodes harder at the
ends, where a weakly absorbing thick layer seen near its own grazing direction contributes the
sharp Beer factor :math:`\exp(-\alpha h/\cos\theta)` (measured: αh = 0.01 next to grazing, 24
nodes: 4e-8 with the double map against 6e-7 with the single one). The error decreases much
faster than the :math:`N^{-3}` of plain Gauss–Legendre. The number of segments is static (one per thick medium); the
split points are traced, so the indices themselves can be fitted.

Accuracy against node count (max |error| of r and t against the adaptive
scipy references of tests/reference.py). "named": the three minimal multilayer reproducers of
tests/test_quadrature.py (low-index film / lossless thick layers / weakly absorbing thick layers);
"Beer": α layers of αh = 1e-4 … 3 (n = 1.5 over 1.5, 1.6, 1.4, from 1.6, two layers), both sides.
Maps: dcos-k = k-fold g; ts-T = tanh–sinh truncated at ±T (N points); asym-k = g then k-fold
top-only s(v) = sin(πv/2) (bottom end ~v², top end ~(1−v)^(2^(k+1))).

=========  =====  ==========================  ========
rule       N/seg  named (film, lossless, abs)  Beer
=========  =====  ==========================  ========
dcos-2     24     3.0e-9, 2.8e-10, 1.1e-8      4.1e-8
dcos-2     32     8.6e-12, 1.5e-12, 2.7e-9     2.1e-9
dcos-2     40     5e-15, 3e-14, 6.6e-10        3.7e-10
dcos-2     48     3e-15, 4e-15, 1.7e-11        7.0e-11
dcos-1     48     3e-15, 4e-15, 2.8e-9         3.7e-8
dcos-3     48     1.7e-11, 2.2e-13, 8.2e-11    1.8e-11
ts-2.5     32…48  ≥ 5e-10 (truncation floor)   ≥ 1.3e-9
ts-3       48     7e-14, 5e-14, 3.0e-10        5.6e-11
asym-1     32     6e-14, 4e-13, 6.2e-9         1.8e-9
asym-1     48     3e-15, 4e-15, 6.9e-11        8.9e-11
asym-2     40     7e-14, 1e-13, 5.6e-10        3.4e-11
asym-2     48     3e-15, 3e-15, 3.8e-11        1.7e-12
=========  =====  ==========================  ========

Random 1–4 layer stacks (tests/test_quadrature.py generator; 120 stacks × 2 sides, seeds 31415 and
4242, all patterns): dcos-2 24 → 3.9e-7, dcos-2 48 → 7.7e-11, asym-2 48 → 1.2e-8 (its weak
bottom-end clustering fails there), so of the rules tried only dcos-2 at 48 meets 1e-10 everywhere.

Smooth cases converge fastest with weak end clustering (dcos-1, asym-1: 1e-13 at 32 nodes); the
limiting case is a weakly absorbing thick layer near its own critical angle (the Beer boundary
layer exp(−αh/cosθ_j) and, for complex n_j, a branch point just off the real axis), which needs
strong clustering at the segment's top and ~48 nodes with every fixed map tried. DEFAULT_NODES is
therefore 48 (dcos-2), the only rule measured within 1e-10 everywhere. Its cost is contained by
:func:`evanescent_beyond`: past the critical angle of a thick medium of real index nothing
behind that medium is reached, so those segments skip its layers' adding rule (see
``layerstack_jax._stacks.illumination._reach``); on the P2 benchmark stack half of the nodes are such.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from .._base.validate import is_concrete

__all__ = ["DEFAULT_NODES", "unit_rule", "hemispherical_rule", "evanescent_beyond", "plain_gauss_legendre_rule"]

#: Default Gauss–Legendre nodes per segment (accuracy measured in tests/test_quadrature.py and
#: the benchmarks' accuracy-vs-cost table).
DEFAULT_NODES = 48

#: Interval below its end point over which a zero-width segment spreads its (zero-weight) nodes.
_EMPTY_SPREAD = 1e-4


@functools.lru_cache(maxsize=None)
def unit_rule(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre rule on [0, 1] composed with the end-point map; float64 numpy constants.

    Returns ``(x, w)`` with :math:`\\sum_i w_i f(x_i) \\approx \\int_0^1 f(x) dx`.
    """
    v, wv = np.polynomial.legendre.leggauss(nodes)
    x = 0.5 * (v + 1.0)
    w = 0.5 * wv
    for _ in range(2):  # x <- g(x), w <- w g'(x)
        w = w * 0.5 * np.pi * np.sin(np.pi * x)
        x = 0.5 * (1.0 - np.cos(np.pi * x))
    return x, w


def hemispherical_rule(n_from, n_thick, nodes: int = DEFAULT_NODES):
    r"""Nodes and weights in :math:`\mu = \sin^2\theta` of the integration medium.

    Args:
        n_from: real index of the medium the Lambertian light comes from, broadcastable to ``*B``
            (``(wl,)`` or scalar).
        n_thick: indices (complex allowed) of the other thick media of the stack; each one with
            Re n < n_from adds a split point. A static number of segments, ``len(n_thick) + 1``.
        nodes: Gauss–Legendre nodes per segment.

    Returns:
        ``(mu, w)`` shaped ``(node, *B)`` with ``node = nodes * (len(n_thick) + 1)``; both
        dimensionless (μ in [0, 1]; the weights sum to 1, so the Lambertian mean of f is
        ``sum(w * f(mu), axis=0)``).
    """
    x, w = unit_rule(nodes)
    splits, order = _binding_splits(n_from, n_thick)
    n_from = np.real(np.asarray(n_from)) if is_concrete(n_from) else jnp.real(jnp.asarray(n_from))
    shape = jnp.broadcast_shapes(jnp.shape(n_from), *(jnp.shape(c) for c in splits))
    if not splits:
        inner = jnp.zeros((0, *shape))
    elif order is not None:  # already in ascending order at every wavelength
        inner = jnp.stack([jnp.broadcast_to(jnp.asarray(c), shape) for c in splits])
    else:
        inner = jnp.sort(jnp.stack([jnp.broadcast_to(c, shape) for c in splits]), axis=0)
    edges = jnp.concatenate([jnp.zeros((1, *shape)), inner, jnp.ones((1, *shape))])
    lo, hi = edges[:-1], edges[1:]  # (seg, *B)
    width = (hi - lo)[:, None]
    x = jnp.asarray(x, dtype=width.dtype).reshape((1, -1) + (1,) * len(shape))
    w = jnp.asarray(w, dtype=width.dtype).reshape((1, -1) + (1,) * len(shape))
    # Nodes are laid out downwards from the segment's top and never ON it. A zero-width segment
    # (traced layout: a split point at 1 for a medium index-matched to n_from, or two equal split
    # points) spreads its zero-weight nodes over (hi - _EMPTY_SPREAD, hi) instead of stacking them
    # on hi, where the integrand can be 0/0 (a zero-thickness film between two media with q = 0
    # at grazing incidence); d(weight)/d(width) then multiplies ~f(hi-), the value the adjacent
    # segment sees, so the gradient stays finite and close to the one-sided limit.
    empty = width <= 0
    spread = jnp.where(empty, _EMPTY_SPREAD, width)
    top = hi[:, None]
    mu = jnp.minimum(top - spread * (1.0 - x), top - jnp.abs(top) * jnp.finfo(width.dtype).eps)
    wt = width * w
    return mu.reshape((-1, *shape)), wt.reshape((-1, *shape))


def _binding_splits(n_from, n_thick):
    r"""Split points :math:`\mu_c = (\operatorname{Re} n_j / n_f)^2` clipped to [0, 1], and, when known at
    trace time, which media they belong to.

    Returns ``(splits, order)``. With concrete indices, split points that cannot bind
    (:math:`n_j \ge n_f` at every wavelength) are dropped and equal ones merged; if the remaining
    ones keep one order at every wavelength they come sorted and ``order`` is a tuple, one entry
    per split point in ascending μ, of the tuple of positions in ``n_thick`` of the media that
    share it. Otherwise (traced indices, or dispersion curves that cross) ``order`` is None and
    the caller sorts per wavelength.
    """
    if not is_concrete((n_from, *n_thick)):
        n_from = jnp.real(jnp.asarray(n_from))
        return [jnp.clip((jnp.real(jnp.asarray(n)) / n_from) ** 2, 0.0, 1.0) for n in n_thick], None
    n_from_np = np.real(np.asarray(n_from))
    kept: list = []  # [split point, [positions]]
    for i, n in enumerate(n_thick):
        c = np.clip((np.real(np.asarray(n)) / n_from_np) ** 2, 0.0, 1.0)
        if np.all(c >= 1.0):
            continue
        same = [k for k in kept if np.shape(c) == np.shape(k[0]) and np.array_equal(c, k[0])]
        if same:
            same[0][1].append(i)
        else:
            kept.append([c, [i]])
    if not kept:
        return [], ()
    shape = np.broadcast_shapes(*(np.shape(k[0]) for k in kept))
    stacked = np.stack([np.broadcast_to(k[0], shape) for k in kept]).reshape(len(kept), -1)
    rank = np.argsort(stacked, axis=0, kind="stable")
    if np.all(rank == rank[:, :1]) and np.all(np.diff(stacked[rank[:, 0]], axis=0) >= 0):
        ordered = [kept[j] for j in rank[:, 0]]
        return [k[0] for k in ordered], tuple(tuple(k[1]) for k in ordered)
    return [k[0] for k in kept], None


def evanescent_beyond(n_from, n_thick) -> tuple | None:
    r"""Per segment of :func:`hemispherical_rule` (ascending μ), the positions in ``n_thick`` of
    the media whose critical angle lies at or below the segment at every wavelength: light from
    ``n_from`` is evanescent in them over the whole segment. None when this is not known at
    trace time (traced indices, or split points whose order changes with wavelength)."""
    _, order = _binding_splits(n_from, n_thick)
    if order is None:
        return None
    out, seen = [()], ()
    for group in order:
        seen = seen + tuple(group)
        out.append(tuple(sorted(seen)))
    return tuple(out)


def plain_gauss_legendre_rule(total_nodes: int):
    """Plain Gauss–Legendre on [0, 1] in μ, no splitting: for comparisons in benchmarks only."""
    v, wv = np.polynomial.legendre.leggauss(total_nodes)
    return 0.5 * (v + 1.0), 0.5 * wv
