r"""The table lookups and the importance sampling of :mod:`layerstack_jax.render._lookup`, written
with Dr.Jit arrays: one call evaluates a whole wavefront of shading points.

Mitsuba's vectorized variants (``llvm_ad_spectral``, ``cuda_ad_spectral`` and their polarized
forms) call a BSDF once per bounce with arrays of every ray still alive, and record the calls
into one compiled kernel. The functions here are the same arithmetic as the scalar
:class:`~layerstack_jax.render._lookup.TableSurface` (multilinear interpolation, clamped at the
grid ends; the same lobe choice, piecewise-constant cells and defensive cosine share), on the
same padded arrays (:class:`~layerstack_jax.render._lookup.SurfaceArrays`): binary searches on
the grids (``dr.binary_search``), gathers from flat tables (``dr.gather``) and masks
(``dr.select``) instead of branches. Values are differentiable with respect to the tables
``k_r`` and ``k_d`` (Dr.Jit's automatic differentiation through the gathers); the sampling
densities are fixed when the surface is made.

Orientation as in the scalar module: ``brdf(light, view, ...)`` reads the tables' incidence axis
at the light; the lobe is sampled for a light direction given the view.
"""

from __future__ import annotations

import math

from ._lookup import DEFENSIVE, SurfaceArrays

__all__ = ["WavefrontSurface"]


class WavefrontSurface:
    """A coated surface's tables as Dr.Jit arrays of the current Mitsuba variant.

    Args:
        arrays: :attr:`TableSurface.arrays <layerstack_jax.render._lookup.TableSurface>`.
        has_specular, has_diffuse: the surface's lobes (as in ``TableSurface``).
        mi, dr: the ``mitsuba`` and ``drjit`` modules, a vectorized variant set.

    Attributes ``k_r`` and ``k_d`` (flat ``mi.Float``) are the tables that :meth:`specular` and
    :meth:`brdf` read at each call: a Mitsuba parameter update replaces their contents.
    """

    def __init__(self, arrays: SurfaceArrays, has_specular: bool, has_diffuse: bool, mi, dr):
        self.mi, self.dr = mi, dr
        F = mi.Float
        self.has_specular, self.has_diffuse = has_specular, has_diffuse
        self.n_wl, self.n_cos_t, self.n_cos_o, self.n_phi = (a.size for a in (arrays.wl, arrays.cos_t, arrays.cos_o, arrays.phi))
        self.wl, self.cos_t, self.cos_o, self.phi = (F(a) for a in (arrays.wl, arrays.cos_t, arrays.cos_o, arrays.phi))
        self.k_r, self.k_d = F(arrays.k_r), F(arrays.k_d)
        self.p_spec = F(arrays.p_spec)
        self.n_mu_edges, self.n_phi_edges = arrays.mu_edges.size, arrays.phi_edges.size
        self.n_cells = (self.n_mu_edges - 1) * (self.n_phi_edges - 1)
        self.mu_edges, self.phi_edges = F(arrays.mu_edges), F(arrays.phi_edges)
        self.cdf, self.density, self.has_cdf = F(arrays.cdf), F(arrays.density), F(arrays.has_cdf)

    # -- grids --------------------------------------------------------------------------------
    def _index(self, grid, n: int, x):
        """``i`` with ``grid[i] <= x < grid[i + 1]``, clamped to ``[0, n - 2]`` (bisect_right − 1)."""
        dr, F = self.dr, self.mi.Float
        r = dr.binary_search(0, n - 1, lambda k: dr.gather(F, grid, k) <= x)
        return dr.maximum(r, 1) - 1

    def _bracket(self, grid, n: int, x):
        """``(i, t)``: index of the cell of ``x`` and weight of node ``i + 1``, clamped to the end
        nodes outside the grid (``_lookup._bracket``)."""
        dr, F = self.dr, self.mi.Float
        i = self._index(grid, n, x)
        g0, g1 = dr.gather(F, grid, i), dr.gather(F, grid, i + 1)
        return i, dr.clip((x - g0) / (g1 - g0), 0.0, 1.0)

    def _wl_brackets(self, wavelengths):
        return [self._bracket(self.wl, self.n_wl, wavelengths[j]) for j in range(len(wavelengths))]

    def _spectrum(self, values):
        return self.mi.UnpolarizedSpectrum(*values)

    # -- evaluation ---------------------------------------------------------------------------
    def specular(self, cos_i, wavelengths, active=True):
        """:math:`k_r` at incidence cosine ``cos_i`` for each of the ray's ``wavelengths`` (nm); zero
        where ``cos_i <= 0`` or not ``active``."""
        dr, F = self.dr, self.mi.Float
        L = self.n_wl
        a, ta = self._bracket(self.cos_t, self.n_cos_t, cos_i)
        out = []
        for l, tl in self._wl_brackets(wavelengths):
            row0, row1 = a * L + l, (a + 1) * L + l
            v0 = dr.lerp(dr.gather(F, self.k_r, row0, active), dr.gather(F, self.k_r, row0 + 1, active), tl)
            v1 = dr.lerp(dr.gather(F, self.k_r, row1, active), dr.gather(F, self.k_r, row1 + 1, active), tl)
            out.append(dr.select(active & (cos_i > 0.0), dr.lerp(v0, v1, ta), 0.0))
        return self._spectrum(out)

    def azimuth(self, u, v):
        """Δφ in [0, π] between the surface projections of ``v`` and of the mirror direction of
        ``u`` (symmetric in ``u``, ``v``); 0 where either projection vanishes."""
        dr = self.dr
        su2 = dr.square(u.x) + dr.square(u.y)
        sv2 = dr.square(v.x) + dr.square(v.y)
        ok = (su2 > 1e-12) & (sv2 > 1e-12)
        c = -(u.x * v.x + u.y * v.y) * dr.rsqrt(dr.select(ok, su2 * sv2, 1.0))
        return dr.select(ok, dr.acos(dr.clip(c, -1.0, 1.0)), 0.0)

    def brdf(self, light, view, wavelengths, active=True):
        """:math:`k_d(\\omega_l \\to \\omega_v)` (1/sr) for outward ``light`` and ``view``
        directions (local frame); zero unless both are above the surface and ``active``."""
        dr, F = self.dr, self.mi.Float
        if not self.has_diffuse:
            return self._spectrum([F(0.0)] * len(wavelengths))
        active = active & (light.z > 0.0) & (view.z > 0.0)
        L, P, B = self.n_wl, self.n_phi, self.n_cos_o
        a, ta = self._bracket(self.cos_t, self.n_cos_t, light.z)
        b, tb = self._bracket(self.cos_o, self.n_cos_o, view.z)
        p, tp = self._bracket(self.phi, self.n_phi, self.azimuth(light, view))
        base = ((a * B + b) * P + p) * L
        corners = []
        for da, wa in ((0, 1.0 - ta), (1, ta)):
            for db, wb in ((0, 1.0 - tb), (1, tb)):
                for dp, wp in ((0, 1.0 - tp), (1, tp)):
                    corners.append((base + (da * B * P + db * P + dp) * L, wa * wb * wp))
        out = []
        for l, tl in self._wl_brackets(wavelengths):
            s = F(0.0)
            for index, w in corners:
                v0 = dr.gather(F, self.k_d, index + l, active)
                v1 = dr.gather(F, self.k_d, index + l + 1, active)
                s = dr.fma(w, dr.lerp(v0, v1, tl), s)
            out.append(dr.select(active, s, 0.0))
        return self._spectrum(out)

    # -- sampling -----------------------------------------------------------------------------
    def specular_probability(self, cos_v):
        """Probability of choosing the delta lobe at view cosine ``cos_v``."""
        dr, F = self.dr, self.mi.Float
        if not self.has_diffuse:
            return F(1.0)
        if not self.has_specular:
            return F(0.0)
        a, ta = self._bracket(self.cos_o, self.n_cos_o, cos_v)
        return dr.lerp(dr.gather(F, self.p_spec, a), dr.gather(F, self.p_spec, a + 1), ta)

    def _node_pdf(self, node, cos_l, dphi):
        dr, F = self.dr, self.mi.Float
        b = self._index(self.mu_edges, self.n_mu_edges, cos_l)
        p = self._index(self.phi_edges, self.n_phi_edges, dphi)
        table = dr.gather(F, self.density, node * self.n_cells + b * (self.n_phi_edges - 1) + p)
        return dr.select(dr.gather(F, self.has_cdf, node) > 0.5, table, cos_l * (1.0 / math.pi))

    def lobe_pdf(self, view, light):
        """Solid-angle pdf (1/sr) of drawing ``light`` from the diffuse lobe given ``view``."""
        dr = self.dr
        a, ta = self._bracket(self.cos_o, self.n_cos_o, view.z)
        dphi = self.azimuth(view, light)
        table = dr.lerp(self._node_pdf(a, light.z, dphi), self._node_pdf(a + 1, light.z, dphi), ta)
        pdf = (1.0 - DEFENSIVE) * table + DEFENSIVE * light.z * (1.0 / math.pi)
        return dr.select((view.z > 0.0) & (light.z > 0.0), pdf, 0.0)

    def sample_lobe(self, view, u, u2):
        """A light direction drawn from the diffuse lobe given ``view`` (uniform ``u`` and
        ``u2 = (x, y)`` in [0, 1))."""
        mi, dr = self.mi, self.dr
        F, U = mi.Float, mi.UInt32
        cosine = u < DEFENSIVE
        u = (u - DEFENSIVE) * (1.0 / (1.0 - DEFENSIVE))
        a, ta = self._bracket(self.cos_o, self.n_cos_o, view.z)
        node = dr.select(u < ta, a + 1, a)
        cosine |= dr.gather(F, self.has_cdf, node) < 0.5
        start = node * self.n_cells
        k = dr.binary_search(0, self.n_cells - 1, lambda j: dr.gather(F, self.cdf, start + j) <= u2.x)
        hi = dr.gather(F, self.cdf, start + k)
        lo = dr.select(k > 0, dr.gather(F, self.cdf, start + dr.maximum(k, 1) - 1), 0.0)
        frac = dr.clip((u2.x - lo) / dr.maximum(hi - lo, 1e-30), 0.0, 1.0)
        n_phi = self.n_phi_edges - 1
        b, p = k // U(n_phi), k % U(n_phi)
        m0 = dr.gather(F, self.mu_edges, b)
        mu = m0 + frac * (dr.gather(F, self.mu_edges, b + 1) - m0)
        y = 2.0 * u2.y
        back = y >= 1.0
        y = dr.select(back, y - 1.0, y)
        p0 = dr.gather(F, self.phi_edges, p)
        dphi = p0 + y * (dr.gather(F, self.phi_edges, p + 1) - p0)
        phi_l = dr.atan2(-view.y, -view.x) + dr.select(back, -dphi, dphi)
        # the cosine-weighted share (and nodes without a table density)
        r = dr.sqrt(u2.x)
        phi_c = 2.0 * math.pi * u2.y
        mu = dr.select(cosine, dr.safe_sqrt(1.0 - u2.x), mu)
        s = dr.select(cosine, r, dr.safe_sqrt(1.0 - mu * mu))
        phi_l = dr.select(cosine, phi_c, phi_l)
        sin_p, cos_p = dr.sincos(phi_l)
        return mi.Vector3f(s * cos_p, s * sin_p, mu)
