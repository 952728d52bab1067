r"""A Mitsuba 3 BSDF for objects coated with multilayer films, read from pre-computed tables.

Hirayama et al. §5: the composite reflectances of the coating are tabulated over angle and
wavelength before rendering and interpolated at each ray. This plugin does that inside
Mitsuba 3's spectral variants (``scalar_spectral``; ``scalar_spectral_polarized`` with a
depolarizing Mueller matrix, the tables being for natural light): at each shading point it reads
the wavelengths Mitsuba draws (``si.wavelengths``, nm), interpolates

* the specular (delta, mirror-direction) reflectance :math:`k_r(\theta_i, \lambda)` and
* the diffuse BRDF :math:`k_d(\omega_i, \omega_o, \lambda)` (1/sr, specular delta excluded),

which are the two terms of their eq. (8), and importance-samples them
(:class:`layerstack_jax.render._lookup.TableSurface`). Smooth objects have ``k_d = 0`` (one
delta lobe); rough ones a weaker delta (the coherent part) and a glossy lobe.

Mitsuba is optional (``pip install layerstack-jax[render]``) and imported only here, when a
function of this module is called. The work per ray is plain Python: it suits the scalar
variants, which call a BSDF once per ray (see :func:`register`).

Example::

    import mitsuba as mi
    from layerstack_jax.render import coated_bsdf
    mi.set_variant("scalar_spectral")
    bsdf = coated_bsdf(tables)            # tables: a CoatingTables
    scene = mi.load_dict({..., "sphere": {"type": "sphere", "bsdf": bsdf}})
"""

from __future__ import annotations

import itertools
import threading
import time

from .._validate import LayerstackError
from ._lookup import TableSurface

__all__ = ["PLUGIN_NAME", "import_mitsuba", "register", "coated_bsdf"]

#: Name under which the plugin is registered with Mitsuba (``{"type": PLUGIN_NAME, ...}``).
PLUGIN_NAME = "layerstack_coated"

_INSTALL = "pip install 'layerstack-jax[render]'"
_SURFACES: dict = {}  # id -> TableSurface, looked up by the plugin's constructor
_IDS = itertools.count()
_REGISTERED: set = set()
_LOCK = threading.Lock()


def import_mitsuba():
    """``(mitsuba, drjit)``, or an :class:`ImportError` that says how to install them."""
    try:
        import drjit
        import mitsuba
    except ImportError as err:
        raise ImportError(
            f"layerstack_jax.render needs Mitsuba 3 (the 'render' extra): {_INSTALL}  ({err})"
        ) from err
    return mitsuba, drjit


def _check_variant(mi) -> str:
    variant = mi.variant()
    if variant is None:
        raise LayerstackError("no Mitsuba variant is set: call mi.set_variant('scalar_spectral') first")
    if "spectral" not in variant or not variant.startswith("scalar"):
        raise LayerstackError(
            f"Mitsuba variant {variant!r}: the coated BSDF needs a scalar spectral variant "
            "('scalar_spectral' or 'scalar_spectral_polarized'): it reads si.wavelengths per ray"
        )
    return variant


def _make_class(mi):
    """The ``mi.BSDF`` subclass for the current variant (Mitsuba's classes are per variant)."""
    polarized = mi.is_polarized
    delta = mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.FrontSide
    glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide

    def spectrum(values):
        s = mi.UnpolarizedSpectrum(*values)
        return mi.depolarizer(s) if polarized else s

    zero = spectrum([0.0] * 4)

    class CoatedBSDF(mi.BSDF):
        """Coated surface from tables: delta lobe :math:`k_r` (component 0), glossy lobe
        :math:`k_d` (component 1). Property ``surface_id``: key returned by :func:`coated_bsdf`."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            key = props["surface_id"]
            if key not in _SURFACES:
                raise LayerstackError(f"{PLUGIN_NAME}: unknown surface_id {key!r} (make the BSDF with coated_bsdf(tables))")
            self.surface: TableSurface = _SURFACES[key][0]
            self.timings = _SURFACES[key][1]
            if self.timings is not None:  # profiling: time every call of the BSDF interface
                for name in ("sample", "eval", "pdf", "eval_pdf"):
                    setattr(self, name, _timed(getattr(self, name), name, self.timings))
            self.surface_id = key
            self.m_components = [delta, glossy]
            flags = 0
            if self.surface.has_specular:
                flags |= delta
            if self.surface.has_diffuse:
                flags |= glossy
            self.m_flags = flags if flags else delta

        # -- helpers --------------------------------------------------------------------------
        def _lobes(self, ctx):
            spec = self.surface.has_specular and ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 0)
            diff = self.surface.has_diffuse and ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 1)
            return spec, diff

        def _p_spec(self, cos_i, spec, diff):
            if spec and diff:
                return self.surface.specular_probability(cos_i)
            return 1.0 if spec else 0.0

        def _eval(self, ctx, si, wo):
            wi = (si.wi.x, si.wi.y, si.wi.z)
            w = (wo.x, wo.y, wo.z)
            spec, diff = self._lobes(ctx)
            if not diff or wi[2] <= 0.0 or w[2] <= 0.0:
                return None, 0.0
            f = self.surface.brdf(wi, w, si.wavelengths)
            pdf = (1.0 - self._p_spec(wi[2], spec, diff)) * self.surface.lobe_pdf(wi, w)
            return [v * w[2] for v in f], pdf

        # -- the BSDF interface ---------------------------------------------------------------
        def sample(self, ctx, si, sample1, sample2, active=True):
            bs = mi.BSDFSample3f()
            cos_i = si.wi.z
            spec, diff = self._lobes(ctx)
            if not active or cos_i <= 0.0 or not (spec or diff):
                return bs, zero
            wl = si.wavelengths
            p_spec = self._p_spec(cos_i, spec, diff)
            if sample1 < p_spec:  # delta lobe: the mirror direction, weight k_r / P(choice)
                bs.wo = mi.Vector3f(-si.wi.x, -si.wi.y, cos_i)
                bs.pdf = p_spec
                bs.eta = 1.0
                bs.sampled_type = int(mi.BSDFFlags.DeltaReflection)
                bs.sampled_component = 0
                return bs, spectrum([v / p_spec for v in self.surface.specular(cos_i, wl)])
            u = (sample1 - p_spec) / (1.0 - p_spec)
            wi = (si.wi.x, si.wi.y, cos_i)
            wo = self.surface.sample_lobe(wi, u, (sample2.x, sample2.y))
            if wo[2] <= 0.0:
                return bs, zero
            pdf = (1.0 - p_spec) * self.surface.lobe_pdf(wi, wo)
            if not pdf > 0.0:
                return bs, zero
            bs.wo = mi.Vector3f(*wo)
            bs.pdf = pdf
            bs.eta = 1.0
            bs.sampled_type = int(mi.BSDFFlags.GlossyReflection)
            bs.sampled_component = 1
            f = self.surface.brdf(wi, wo, wl)
            return bs, spectrum([v * wo[2] / pdf for v in f])

        def eval(self, ctx, si, wo, active=True):
            if not active:
                return zero
            value, _ = self._eval(ctx, si, wo)
            return zero if value is None else spectrum(value)

        def pdf(self, ctx, si, wo, active=True):
            if not active:
                return 0.0
            return self._eval(ctx, si, wo)[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            if not active:
                return zero, 0.0
            value, pdf = self._eval(ctx, si, wo)
            return (zero if value is None else spectrum(value)), pdf

        def traverse(self, callback):
            pass

        def parameters_changed(self, keys=None):
            pass

        def to_string(self):
            lo, hi = self.surface.wavelength_range
            return (f"CoatedBSDF[surface_id={self.surface_id!r}, specular={self.surface.has_specular}, "
                    f"diffuse={self.surface.has_diffuse}, tables {lo:.0f}-{hi:.0f} nm]")

    return CoatedBSDF


def _timed(method, name: str, timings: dict):
    """``method`` that adds its wall time (s) and call count to ``timings[name]`` = [s, calls]."""
    clock = time.perf_counter
    entry = timings.setdefault(name, [0.0, 0])

    def timed(*args):
        t0 = clock()
        try:
            return method(*args)
        finally:
            entry[0] += clock() - t0
            entry[1] += 1

    return timed


def register(variant: str | None = None) -> str:
    """Register the coated BSDF with Mitsuba under :data:`PLUGIN_NAME` for the current variant.

    Args:
        variant: if given, ``mi.set_variant(variant)`` first. Must be a scalar spectral variant
            (``'scalar_spectral'``, ``'scalar_spectral_polarized'``): the plugin is Python called
            once per ray, and reads the ray's wavelengths. Other variants raise
            :class:`~layerstack_jax.LayerstackError`.

    Returns:
        The plugin name, for ``{"type": name, "surface_id": ...}`` scene dictionaries.
    """
    mi, _ = import_mitsuba()
    if variant is not None:
        mi.set_variant(variant)
    current = _check_variant(mi)
    with _LOCK:
        if current not in _REGISTERED:
            cls = _make_class(mi)
            mi.register_bsdf(PLUGIN_NAME, lambda props: cls(props))
            _REGISTERED.add(current)
    return PLUGIN_NAME


def coated_bsdf(tables, *, variant: str | None = None, timings: dict | None = None):
    """A Mitsuba BSDF object for a coated surface described by ``tables``.

    Args:
        tables: a ``CoatingTables`` (fields and units in :mod:`layerstack_jax.render._lookup`);
            validated (:class:`~layerstack_jax.LayerstackError` naming the field).
        variant: optional Mitsuba variant to set first (see :func:`register`).
        timings: a dict to profile the plugin: each call of ``sample``, ``eval``, ``pdf``,
            ``eval_pdf`` adds its wall time to ``timings[name] = [seconds, calls]``.

    Returns:
        A ``mi.BSDF`` to put in a scene dictionary (``"bsdf": coated_bsdf(tables)``).
    """
    mi, _ = import_mitsuba()  # first: without the extra, say how to install it
    surface = TableSurface(tables)
    name = register(variant)
    key = f"coating-{next(_IDS)}"
    _SURFACES[key] = (surface, timings)
    return mi.load_dict({"type": name, "surface_id": key})
