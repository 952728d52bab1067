r"""Interpolation and importance sampling of a coated surface's reflectance tables (Hirayama §5).

Hirayama et al. pre-compute the composite reflectances of a coated object over incidence angle
and wavelength and interpolate them linearly while ray tracing (their §5). This module does
that for one shading point at a time — the work a scalar renderer asks of a BSDF — in plain
Python on nested lists (a few µs per call; no NumPy dispatch per ray), so that the Mitsuba
plugin in :mod:`layerstack_jax.render._mitsuba` is a thin adapter and everything here is
tested without Mitsuba.

The surface model is Hirayama's eq. (8): a specular (mirror-direction, delta) reflectance
:math:`k_r(\theta_i, \lambda)` plus a diffuse BRDF :math:`k_d(\omega_i, \omega_o, \lambda)`
(1/sr, natural light, specular delta excluded). The tables are those of the
``CoatingTables`` contract of :mod:`layerstack_jax._appearance.render_tables` (duck-typed here):

======================  ============  ==================================================
field                   shape         meaning
======================  ============  ==================================================
``wavelength_nm``       (L,)          ascending vacuum wavelengths, nm
``cos_theta``           (A,)          ascending cos(incidence) in (0, 1]
``k_r``                 (A, L)        specular reflectance, natural light
``k_t``                 (A, L)        specular transmittance (zeros: opaque substrate)
``phi_out``             (P,)          azimuth of the outgoing direction relative to the
                                      plane of incidence, radians in [0, π]
``cos_theta_out``       (B,)          ascending cos(outgoing polar angle)
``k_d``                 (A, B, P, L)  diffuse BRDF, 1/sr
======================  ============  ==================================================

**Azimuth convention** (that of :mod:`layerstack_jax._appearance.render_tables`). φ is measured from the
forward (specular) side of the plane of incidence and folded into [0, π]: φ = 0 is the mirror
direction's azimuth, φ = π back towards the source. With Mitsuba's outward ``wi`` and ``wo``,
φ is the angle between the surface projections of ``wo`` and of the mirror direction of ``wi``
(:func:`layerstack_jax.rough_brdf`'s ``azimuth_deg`` is 180° − φ). At normal incidence φ is
undefined and taken as 0.

**Interpolation.** Linear in cos θ_i, cos θ_o, Δφ and λ (multilinear), clamped to the end
values outside each grid (Mitsuba samples 360–830 nm; tables usually cover less).

**Orientation.** The tables' incidence axis is the *light* (Hirayama's ω_l) and the outgoing
axis the *viewer* (ω_i): :meth:`TableSurface.brdf` takes ``(light, view)``. A path tracer
gathering radiance stands at the viewer's side: Mitsuba's ``si.wi`` points back along the path
(towards the camera) and the direction it samples, ``wo``, towards the light. Literal-form
tables (``form="literal"``) are not reciprocal, so the order matters.

**Sampling** (what a radiance path tracer needs: a light direction given the view). Lobe choice
with probability :math:`P_s(\mu_v) = \bar k_r(\mu_v) / (\bar k_r(\mu_v) + \bar a(\mu_v))`
for the delta lobe, where bars are means over the table's wavelengths and
:math:`a(\mu_v) = \int k_d(\omega_l \to \omega_v) \cos\theta_l\, d\omega_l` is the
albedo of :math:`k_d` seen from the view direction. The diffuse lobe is drawn from a
piecewise-constant density over (cos θ_l, Δφ) cells (each table cell cut into ``SPLIT`` ×
``SPLIT``), built per *view* node from :math:`\bar k_d\cos\theta_l` and mixed
stochastically between the two nodes that bracket :math:`\mu_v` (an exact mixture, whose pdf is the same mixture of the two densities), with a
defensive share ``DEFENSIVE`` of cosine-weighted sampling so that the pdf is positive wherever
:math:`k_d` may be. Any orientation may be evaluated with this density (it is positive
everywhere): only its efficiency depends on how well it follows the integrand.
"""

from __future__ import annotations

import math
import warnings
from bisect import bisect_right
from typing import NamedTuple

import numpy as np

from .._appearance.render_tables import CoatingTables  # the one table type (re-exported here)
from .._base.validate import LayerstackError

__all__ = ["CoatingTables", "TableSurface", "SurfaceArrays", "DEFENSIVE"]

#: Share of cosine-weighted directions in the sampling of the diffuse lobe.
DEFENSIVE = 0.1
#: Sampling cells per table cell along each axis (the density then follows the multilinear
#: interpolation of the table, not only its values at the cell centres).
SPLIT = 4

_FIELDS = ("wavelength_nm", "cos_theta", "k_r", "k_t", "phi_out", "cos_theta_out", "k_d")


def _grid(name: str, x, lo: float, hi: float) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim != 1 or a.size == 0:
        raise LayerstackError(f"tables.{name} must be a non-empty 1-D array, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise LayerstackError(f"tables.{name} contains NaN or infinite values")
    if np.any(np.diff(a) <= 0):
        raise LayerstackError(f"tables.{name} must be strictly ascending")
    if a[0] < lo or a[-1] > hi:
        raise LayerstackError(f"tables.{name} must lie in [{lo}, {hi}], got [{a[0]}, {a[-1]}]")
    return a


def _values(name: str, x, shape: tuple) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.shape != shape:
        raise LayerstackError(f"tables.{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise LayerstackError(f"tables.{name} contains NaN or infinite values")
    if np.any(a < 0):
        raise LayerstackError(f"tables.{name} must be >= 0, got min {a.min()!r}")
    return a


def _padded(grid: np.ndarray, values: np.ndarray, axis: int):
    """A one-node grid becomes two equal nodes (constant along that axis), so that every grid
    has a bracketing pair."""
    if grid.size > 1:
        return grid, values
    return np.array([grid[0], grid[0] + 1.0]), np.concatenate([values, values], axis=axis)


def _bracket(grid: list, x: float):
    """``(i, t)`` with ``grid[i] <= x <= grid[i + 1]`` and weight ``t`` of node ``i + 1``, clamped
    to the end nodes outside the grid (``len(grid) >= 2``)."""
    i = bisect_right(grid, x) - 1
    if i < 0:
        return 0, 0.0
    if i >= len(grid) - 1:
        return len(grid) - 2, 1.0
    return i, (x - grid[i]) / (grid[i + 1] - grid[i])


def _azimuth(wi, wo) -> float:
    """φ in [0, π] of the outward direction ``wo`` from the forward side of the plane of
    incidence of the outward direction ``wi`` (both ``(x, y, z)``, local frame): the angle between
    the surface projections of ``wo`` and of the mirror direction ``(-x, -y, z)`` of ``wi``; 0 when
    either projection vanishes (azimuth undefined)."""
    si2 = wi[0] * wi[0] + wi[1] * wi[1]
    so2 = wo[0] * wo[0] + wo[1] * wo[1]
    if si2 <= 1e-24 or so2 <= 1e-24:
        return 0.0
    c = -(wi[0] * wo[0] + wi[1] * wo[1]) / math.sqrt(si2 * so2)
    return math.acos(max(-1.0, min(1.0, c)))


def _interp_mean(grid: np.ndarray, values: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Linear, clamped interpolation of ``values`` (node axis first) at ``x`` (vectorized)."""
    i = np.clip(np.searchsorted(grid, x, side="right") - 1, 0, grid.size - 2)
    t = np.clip((x - grid[i]) / (grid[i + 1] - grid[i]), 0.0, 1.0)
    shape = (-1,) + (1,) * (values.ndim - 1)
    return (1 - t).reshape(shape) * values[i] + t.reshape(shape) * values[i + 1]


class _LobeDistribution(NamedTuple):
    mu_edges: list  # (Cb + 1,) cell edges in the sampled cosine
    phi_edges: list  # (Cp + 1,) cell edges in Δφ ∈ [0, π]
    cdf: list  # per conditioning node: (Cb * Cp,) cumulative probabilities (last = 1), or None
    density: list  # per conditioning node: (Cb * Cp,) solid-angle pdf of each cell, or None
    albedo: list  # per conditioning node: albedo of the λ-mean k_d over the sampled directions


def _refined(edges: np.ndarray, split: int) -> np.ndarray:
    """``edges`` with each interval cut into ``split`` equal parts."""
    parts = [np.linspace(a, b, split + 1)[:-1] for a, b in zip(edges[:-1], edges[1:])]
    return np.concatenate(parts + [edges[-1:]])


def _cells(cos_o: np.ndarray, phi: np.ndarray, split: int = 1):
    """Cell edges of the lobe's sampling grid: between the nodes of the outgoing grid, extended
    to cos θo ∈ [0, 1] and Δφ ∈ [0, π], each interval cut into ``split`` parts."""
    mu_edges = np.unique(np.concatenate([[0.0], cos_o[(cos_o > 0) & (cos_o < 1)], [1.0]]))
    phi_edges = np.unique(np.concatenate([[0.0], phi[(phi > 0) & (phi < np.pi)], [np.pi]]))
    return _refined(mu_edges, split), _refined(phi_edges, split)


def _cell_weights(cos_o: np.ndarray, phi: np.ndarray, table: np.ndarray, mu_edges, phi_edges) -> np.ndarray:
    r""":math:`\int_\text{cell} k_d \cos\theta_o\, d\omega` per cell (both azimuth signs), by the
    midpoint rule: ``table`` ``(B, P, ...)`` (grids padded to two nodes) → ``(Cb, Cp, ...)``."""
    mu_c = 0.5 * (mu_edges[1:] + mu_edges[:-1])
    phi_c = 0.5 * (phi_edges[1:] + phi_edges[:-1])
    along_mu = _interp_mean(cos_o, table, mu_c)  # (Cb, P, ...)
    cell = np.moveaxis(_interp_mean(phi, np.moveaxis(along_mu, 1, 0), phi_c), 0, 1)  # (Cb, Cp, ...)
    extra = (1,) * (table.ndim - 2)
    solid = (mu_c * np.diff(mu_edges))[:, None] * np.diff(phi_edges)[None, :] * 2.0
    return cell * solid.reshape(solid.shape + extra)


def _lobe_distribution(cos_o: np.ndarray, phi: np.ndarray, kd_mean: np.ndarray) -> _LobeDistribution:
    r"""Piecewise-constant sampling densities of :math:`\bar k_d \cos\theta_o` per incidence node
    (``kd_mean``: ``(A, B, P)``), with cells from :func:`_cells`; the value in a cell is the
    λ-mean BRDF at its centre (bilinear, clamped) times its mean cos θo."""
    mu_edges, phi_edges = _cells(cos_o, phi, SPLIT)
    d_mu, d_phi = np.diff(mu_edges), np.diff(phi_edges)
    cos_o, kd_mean = _padded(cos_o, kd_mean, 1)
    phi, kd_mean = _padded(phi, kd_mean, 2)
    cdf, density, albedo = [], [], []
    for table in kd_mean:  # (B, P) per incidence node
        weight = _cell_weights(cos_o, phi, table, mu_edges, phi_edges)
        total = float(weight.sum())
        albedo.append(total)
        if total <= 0.0:
            cdf.append(None)
            density.append(None)
            continue
        p = (weight / total).ravel()
        c = np.cumsum(p)
        c[-1] = 1.0
        cdf.append(c.tolist())
        density.append((p / (2.0 * np.outer(d_mu, d_phi).ravel())).tolist())
    return _LobeDistribution(mu_edges.tolist(), phi_edges.tolist(), cdf, density, albedo)


def _albedo(cos_o: np.ndarray, phi: np.ndarray, k_d: np.ndarray) -> np.ndarray:
    r"""Directional albedo :math:`\int k_d\cos\theta_o d\omega` per incidence node and wavelength,
    ``(A, L)`` (midpoint rule on the sampling cells)."""
    mu_edges, phi_edges = _cells(cos_o, phi)
    cos_o, k_d = _padded(cos_o, k_d, 1)
    phi, k_d = _padded(phi, k_d, 2)
    return np.stack([_cell_weights(cos_o, phi, t, mu_edges, phi_edges).sum(axis=(0, 1)) for t in k_d])


class TableSurface:
    """A coated surface read from its tables: :meth:`specular`, :meth:`brdf`, and the sampling
    routines a path tracer needs, one shading point at a time (plain Python floats).

    Args:
        tables: a ``CoatingTables`` (or any object with its fields). Validated: ascending
            grids, cosines in [0, 1], Δφ in [0, π], finite non-negative values, matching shapes;
            a warning when ``k_r + albedo(k_d) > 1`` somewhere (the surface would create energy)
            or when ``k_t`` is non-zero (transmission is not rendered: the surface is opaque).
    """

    def __init__(self, tables):
        missing = [f for f in _FIELDS if not hasattr(tables, f)]
        if missing:
            raise LayerstackError(f"tables lack the field(s) {missing} of CoatingTables")
        wl = _grid("wavelength_nm", tables.wavelength_nm, 1.0, np.inf)
        cos_t = _grid("cos_theta", tables.cos_theta, 0.0, 1.0)
        A, L = cos_t.size, wl.size
        k_r = _values("k_r", tables.k_r, (A, L))
        k_t = _values("k_t", tables.k_t, (A, L))
        if np.size(tables.k_d) == 0 and np.size(tables.cos_theta_out) * np.size(tables.phi_out) == 0:
            # specular-only tables (k_d of shape (A, 0, 0, L)): no diffuse lobe
            cos_o, phi, k_d = np.array([1.0]), np.array([0.0]), np.zeros((A, 1, 1, L))
        else:
            cos_o = _grid("cos_theta_out", tables.cos_theta_out, 0.0, 1.0)
            phi = _grid("phi_out", tables.phi_out, 0.0, np.pi)
            k_d = _values("k_d", tables.k_d, (A, cos_o.size, phi.size, L))
        if np.any(k_t > 0):
            warnings.warn("tables.k_t is non-zero: the rendered surface is opaque, its transmittance is not rendered", stacklevel=2)
        self.has_specular = bool(np.any(k_r > 0))
        self.has_diffuse = bool(np.any(k_d > 0))
        albedo_max = float(np.max(k_r + _albedo(cos_o, phi, k_d)))
        if albedo_max > 1.05:  # midpoint rule on the table grid: a few per cent high on coarse peaked lobes
            warnings.warn(f"tables: k_r + albedo of k_d reaches {albedo_max:.4f} > 1 (the surface creates energy)", stacklevel=2)
        # sampling: light directions (the table's incidence grid) given the view (its outgoing grid)
        lobe = _lobe_distribution(cos_t, phi, np.swapaxes(k_d.mean(axis=-1), 0, 1))
        kr_at_view = _interp_mean(cos_t, k_r.mean(axis=-1), cos_o) if A > 1 else np.full(cos_o.size, k_r.mean())
        alb = np.asarray(lobe.albedo)
        p_spec = np.where(kr_at_view + alb > 0, kr_at_view / np.maximum(kr_at_view + alb, 1e-300), 0.0)
        # pad one-node grids
        cos_t_p, k_r_p = _padded(cos_t, k_r, 0)
        _, k_d_p = _padded(cos_t, k_d, 0)
        wl_p, k_r_p = _padded(wl, k_r_p, 1)
        _, k_d_p = _padded(wl, k_d_p, 3)
        cos_o_p, k_d_p = _padded(cos_o, k_d_p, 1)
        phi_p, k_d_p = _padded(phi, k_d_p, 2)
        _, p_spec = _padded(cos_o, p_spec, 0)
        if cos_o.size == 1:
            lobe = lobe._replace(cdf=lobe.cdf * 2, density=lobe.density * 2, albedo=lobe.albedo * 2)
        #: the padded grids, tables and sampling data as numpy arrays (read by the vectorized plugin)
        self.arrays = _surface_arrays(wl_p, cos_t_p, cos_o_p, phi_p, k_r_p, k_d_p, p_spec, lobe)
        # nested lists for fast scalar indexing
        self._wl, self._cos_t, self._cos_o, self._phi = (g.tolist() for g in (wl_p, cos_t_p, cos_o_p, phi_p))
        self._k_r, self._k_d = k_r_p.tolist(), k_d_p.tolist()
        self._p_spec_nodes = p_spec.tolist()
        self._lobe = lobe
        self.wavelength_range = (float(wl[0]), float(wl[-1]))

    # -- evaluation ---------------------------------------------------------------------------
    def _wl_brackets(self, wavelengths):
        return [_bracket(self._wl, float(w)) for w in wavelengths]

    def specular(self, cos_i: float, wavelengths) -> list:
        """Specular reflectance :math:`k_r` (dimensionless) at incidence cosine ``cos_i`` for each
        of ``wavelengths`` (nm); zeros for ``cos_i <= 0``."""
        if cos_i <= 0.0:
            return [0.0] * len(wavelengths)
        a, ta = _bracket(self._cos_t, cos_i)
        r0, r1 = self._k_r[a], self._k_r[a + 1]
        out = []
        for l, tl in self._wl_brackets(wavelengths):
            v0 = r0[l] + tl * (r0[l + 1] - r0[l])
            v1 = r1[l] + tl * (r1[l + 1] - r1[l])
            out.append(v0 + ta * (v1 - v0))
        return out

    def brdf(self, light, view, wavelengths) -> list:
        """Diffuse BRDF :math:`k_d(\\omega_l \\to \\omega_v)` (1/sr) from the light direction
        ``light`` (the tables' incidence axis) to the view direction ``view`` (outward unit
        vectors, local frame, z = normal) at each of ``wavelengths`` (nm); zeros unless both are
        above the surface."""
        if light[2] <= 0.0 or view[2] <= 0.0 or not self.has_diffuse:
            return [0.0] * len(wavelengths)
        a, ta = _bracket(self._cos_t, light[2])
        b, tb = _bracket(self._cos_o, view[2])
        p, tp = _bracket(self._phi, _azimuth(light, view))
        kd = self._k_d
        corners = []
        for ia, wa in ((a, 1.0 - ta), (a + 1, ta)):
            if wa == 0.0:
                continue
            for ib, wb in ((b, 1.0 - tb), (b + 1, tb)):
                if wb == 0.0:
                    continue
                row = kd[ia][ib]
                for ip, wp in ((p, 1.0 - tp), (p + 1, tp)):
                    if wp != 0.0:
                        corners.append((wa * wb * wp, row[ip]))
        out = []
        for l, tl in self._wl_brackets(wavelengths):
            s = 0.0
            for w, spec in corners:
                s += w * (spec[l] + tl * (spec[l + 1] - spec[l]))
            out.append(s)
        return out

    # -- sampling -----------------------------------------------------------------------------
    def specular_probability(self, cos_v: float) -> float:
        """Probability of choosing the delta lobe at view cosine ``cos_v``."""
        if not self.has_diffuse:
            return 1.0
        if not self.has_specular:
            return 0.0
        a, ta = _bracket(self._cos_o, cos_v)
        p = self._p_spec_nodes
        return p[a] + ta * (p[a + 1] - p[a])

    def _node_pdf(self, node: int, cos_l: float, dphi: float) -> float:
        density = self._lobe.density[node]
        if density is None:
            return cos_l / math.pi
        lobe = self._lobe
        b = min(max(bisect_right(lobe.mu_edges, cos_l) - 1, 0), len(lobe.mu_edges) - 2)
        p = min(max(bisect_right(lobe.phi_edges, dphi) - 1, 0), len(lobe.phi_edges) - 2)
        return density[b * (len(lobe.phi_edges) - 1) + p]

    def lobe_pdf(self, view, light) -> float:
        """Solid-angle pdf (1/sr) of drawing the light direction ``light`` from the diffuse lobe
        given the view direction ``view`` (outward unit vectors; the delta lobe's choice
        probability not included)."""
        if view[2] <= 0.0 or light[2] <= 0.0:
            return 0.0
        a, ta = _bracket(self._cos_o, view[2])
        dphi = _azimuth(view, light)
        table = (1.0 - ta) * self._node_pdf(a, light[2], dphi) if ta < 1.0 else 0.0
        if ta > 0.0:
            table += ta * self._node_pdf(a + 1, light[2], dphi)
        return (1.0 - DEFENSIVE) * table + DEFENSIVE * light[2] / math.pi

    def sample_lobe(self, view, u: float, u2: tuple):
        """Draw a light direction from the diffuse lobe given the view direction ``view``, with
        uniform numbers ``u`` and ``u2 = (x, y)`` in [0, 1); returns the unit vector ``(x, y, z)``
        (local frame)."""
        if u < DEFENSIVE:  # cosine-weighted hemisphere
            r = math.sqrt(u2[0])
            ph = 2.0 * math.pi * u2[1]
            return (r * math.cos(ph), r * math.sin(ph), math.sqrt(max(0.0, 1.0 - u2[0])))
        u = (u - DEFENSIVE) / (1.0 - DEFENSIVE)
        a, ta = _bracket(self._cos_o, view[2])
        node = a + 1 if u < ta else a
        cdf = self._lobe.cdf[node]
        if cdf is None:
            r = math.sqrt(u2[0])
            ph = 2.0 * math.pi * u2[1]
            return (r * math.cos(ph), r * math.sin(ph), math.sqrt(max(0.0, 1.0 - u2[0])))
        lobe = self._lobe
        k = min(bisect_right(cdf, u2[0]), len(cdf) - 1)
        lo = cdf[k - 1] if k > 0 else 0.0
        frac = min(max((u2[0] - lo) / max(cdf[k] - lo, 1e-300), 0.0), 1.0)
        n_phi = len(lobe.phi_edges) - 1
        b, p = divmod(k, n_phi)
        mu = lobe.mu_edges[b] + frac * (lobe.mu_edges[b + 1] - lobe.mu_edges[b])
        y = 2.0 * u2[1]
        sign = 1.0 if y < 1.0 else -1.0
        y = y if y < 1.0 else y - 1.0
        dphi = lobe.phi_edges[p] + y * (lobe.phi_edges[p + 1] - lobe.phi_edges[p])
        phi_o = math.atan2(-view[1], -view[0]) + sign * dphi  # from the view's mirror azimuth
        s = math.sqrt(max(0.0, 1.0 - mu * mu))
        return (s * math.cos(phi_o), s * math.sin(phi_o), mu)


class SurfaceArrays(NamedTuple):
    """A :class:`TableSurface`'s data as flat numpy float64 arrays (one-node grids padded to two),
    for the vectorized plugin: grids ``wl`` (L,), ``cos_t`` (A,), ``cos_o`` (B,), ``phi`` (P,);
    ``k_r`` (A·L,), ``k_d`` (A·B·P·L,) row-major; ``p_spec`` (B,) delta-lobe probability at the
    view nodes; lobe sampling cells ``mu_edges`` (Cb + 1,) in cos θ_l and ``phi_edges`` (Cp + 1,);
    per view node ``cdf`` and ``density`` (B·Cb·Cp,), ``has_cdf`` (B,) 1.0 where the node has
    a table density (else cosine-weighted)."""

    wl: np.ndarray
    cos_t: np.ndarray
    cos_o: np.ndarray
    phi: np.ndarray
    k_r: np.ndarray
    k_d: np.ndarray
    p_spec: np.ndarray
    mu_edges: np.ndarray
    phi_edges: np.ndarray
    cdf: np.ndarray
    density: np.ndarray
    has_cdf: np.ndarray


def _surface_arrays(wl, cos_t, cos_o, phi, k_r, k_d, p_spec, lobe: _LobeDistribution) -> SurfaceArrays:
    cells = (len(lobe.mu_edges) - 1) * (len(lobe.phi_edges) - 1)
    cdf = np.stack([np.asarray(c, float) if c is not None else np.linspace(1.0 / cells, 1.0, cells) for c in lobe.cdf])
    density = np.stack([np.asarray(d, float) if d is not None else np.zeros(cells) for d in lobe.density])
    has_cdf = np.array([c is not None for c in lobe.cdf], float)
    return SurfaceArrays(*(np.ascontiguousarray(x, dtype=float).ravel() for x in (
        wl, cos_t, cos_o, phi, k_r, k_d, p_spec, lobe.mu_edges, lobe.phi_edges, cdf, density, has_cdf)))
