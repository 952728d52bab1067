r"""A Mitsuba 3 BSDF for objects coated with multilayer films, read from pre-computed tables.

Hirayama et al. §5: the composite reflectances of the coating are tabulated over angle and
wavelength before rendering and interpolated at each ray. This plugin does that inside
Mitsuba 3's spectral variants: at each shading point it reads the wavelengths Mitsuba draws
(``si.wavelengths``, nm), interpolates

* the specular (delta, mirror-direction) reflectance :math:`k_r(\theta, \lambda)` and
* the diffuse BRDF :math:`k_d(\omega_l \to \omega_v, \lambda)` (1/sr, specular delta
  excluded; the light on the tables' incidence axis, the viewer on their outgoing axis),

which are the two terms of their eq. (8), and importance-samples them. Smooth objects have
``k_d = 0`` (one delta lobe); rough ones a weaker delta (the coherent part) and a glossy lobe.
In the polarized variants the BSDF is a depolarizing Mueller matrix (the tables are for
natural light).

Two implementations of one surface model (:mod:`layerstack_jax.render._lookup`):

* vectorized variants (``llvm_ad_spectral``, ``cuda_ad_spectral``, ``*_polarized``): each call
  sees a whole wavefront of rays and computes with Dr.Jit arrays
  (:mod:`layerstack_jax.render._wavefront`); the tables are differentiable scene parameters;
* scalar variants (``scalar_spectral``, ``scalar_spectral_polarized``): plain Python per ray
  (:class:`~layerstack_jax.render._lookup.TableSurface`), the fallback where Dr.Jit's LLVM
  backend cannot run (:mod:`layerstack_jax.render._llvm`).

**Orientation.** In radiance transport (Mitsuba's path tracers) ``si.wi`` points back along the
path, towards the camera, and ``wo`` towards the light: the plugin reads
:math:`k_d(\omega_l = wo \to \omega_v = si.wi)`; in importance transport (light tracing) the
roles swap. The lobe is sampled for the light direction given the view (any other pairing is
still unbiased, the sampling density being positive everywhere).

Mitsuba is optional (``pip install layerstack-jax[render]``) and imported only here, when a
function of this module is called.

Example::

    import mitsuba as mi
    from layerstack_jax.render import best_variant, coated_bsdf
    mi.set_variant(best_variant())        # 'llvm_ad_spectral' where LLVM >= 17 is installed
    bsdf = coated_bsdf(tables)            # tables: a CoatingTables
    scene = mi.load_dict({..., "sphere": {"type": "sphere", "bsdf": bsdf}})
"""

from __future__ import annotations

import itertools
import threading
import time

from .._base.validate import LayerstackError
from ._llvm import configure as _configure_llvm
from ._llvm import require_llvm
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
    """``(mitsuba, drjit)``, or an :class:`ImportError` that says how to install them. Points
    Dr.Jit at an LLVM it can use first (:func:`layerstack_jax.render._llvm.configure`)."""
    _configure_llvm()
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
        raise LayerstackError("no Mitsuba variant is set: call mi.set_variant('llvm_ad_spectral') (or 'scalar_spectral') first")
    if "spectral" not in variant or "mono" in variant:
        raise LayerstackError(
            f"Mitsuba variant {variant!r}: the coated BSDF needs a spectral variant ('llvm_ad_spectral', "
            "'cuda_ad_spectral', 'scalar_spectral' or their '_polarized' forms): it reads the wavelengths of each ray"
        )
    return variant


def _spectrum_maker(mi):
    polarized = mi.is_polarized

    def spectrum(values):
        s = mi.UnpolarizedSpectrum(*values) if isinstance(values, (list, tuple)) else values
        return mi.depolarizer(s) if polarized else s

    return spectrum


def _flags(mi):
    delta = mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.FrontSide
    glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
    return delta, glossy


def _init_common(self, mi, props):
    """Constructor work shared by the scalar and the vectorized classes."""
    key = props["surface_id"]
    if key not in _SURFACES:
        raise LayerstackError(f"{PLUGIN_NAME}: unknown surface_id {key!r} (make the BSDF with coated_bsdf(tables))")
    self.surface: TableSurface = _SURFACES[key][0]
    self.timings = _SURFACES[key][1]
    if self.timings is not None:  # profiling: time every call of the BSDF interface
        for name in ("sample", "eval", "pdf", "eval_pdf"):
            setattr(self, name, _timed(getattr(self, name), name, self.timings))
    self.surface_id = key
    delta, glossy = _flags(mi)
    self.m_components = [delta, glossy]
    flags = 0
    if self.surface.has_specular:
        flags |= delta
    if self.surface.has_diffuse:
        flags |= glossy
    self.m_flags = flags if flags else delta


def _to_string(self):
    lo, hi = self.surface.wavelength_range
    return (f"CoatedBSDF[surface_id={self.surface_id!r}, specular={self.surface.has_specular}, "
            f"diffuse={self.surface.has_diffuse}, tables {lo:.0f}-{hi:.0f} nm]")


def _make_scalar_class(mi):
    """The ``mi.BSDF`` subclass for a scalar variant (Mitsuba's classes are per variant): plain
    Python per ray on :class:`TableSurface`."""
    spectrum = _spectrum_maker(mi)
    zero = spectrum([0.0] * 4)

    class CoatedBSDF(mi.BSDF):
        """Coated surface from tables: delta lobe :math:`k_r` (component 0), glossy lobe
        :math:`k_d` (component 1). Property ``surface_id``: key returned by :func:`coated_bsdf`."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            _init_common(self, mi, props)

        # -- helpers --------------------------------------------------------------------------
        def _lobes(self, ctx):
            spec = self.surface.has_specular and ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 0)
            diff = self.surface.has_diffuse and ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 1)
            return spec, diff

        def _p_spec(self, cos_v, spec, diff):
            if spec and diff:
                return self.surface.specular_probability(cos_v)
            return 1.0 if spec else 0.0

        def _brdf(self, ctx, wi, wo, wl):
            """k_d with the light on the tables' incidence axis: in radiance transport ``wo``
            points to the light and ``si.wi`` to the viewer; in importance transport the reverse."""
            if ctx.mode == mi.TransportMode.Radiance:
                return self.surface.brdf(wo, wi, wl)
            return self.surface.brdf(wi, wo, wl)

        def _eval(self, ctx, si, wo):
            wi = (si.wi.x, si.wi.y, si.wi.z)
            w = (wo.x, wo.y, wo.z)
            spec, diff = self._lobes(ctx)
            if not diff or wi[2] <= 0.0 or w[2] <= 0.0:
                return None, 0.0
            f = self._brdf(ctx, wi, w, si.wavelengths)
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
            f = self._brdf(ctx, wi, wo, wl)
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

        to_string = _to_string

    return CoatedBSDF


def _make_vector_class(mi, dr):
    """The ``mi.BSDF`` subclass for a vectorized variant (``llvm_*``/``cuda_*``): each method sees
    a whole wavefront of shading points and computes with Dr.Jit arrays
    (:class:`~layerstack_jax.render._wavefront.WavefrontSurface`)."""
    from ._wavefront import WavefrontSurface

    spectrum = _spectrum_maker(mi)
    delta_type, glossy_type = int(mi.BSDFFlags.DeltaReflection), int(mi.BSDFFlags.GlossyReflection)

    class CoatedBSDF(mi.BSDF):
        """Coated surface from tables (vectorized): delta lobe :math:`k_r` (component 0), glossy
        lobe :math:`k_d` (component 1). Parameters ``k_r`` and ``k_d`` (flat, row-major as in
        ``CoatingTables``, one-node grids padded to two) are differentiable; the sampling
        densities stay those of the tables the BSDF was made with."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            _init_common(self, mi, props)
            s = self.surface
            self.wave = WavefrontSurface(s.arrays, s.has_specular, s.has_diffuse, mi, dr)

        def _lobes(self, ctx):
            spec = self.surface.has_specular and ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 0)
            diff = self.surface.has_diffuse and ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 1)
            return spec, diff

        def _p_spec(self, cos_v, spec, diff):
            if spec and diff:
                return self.wave.specular_probability(cos_v)
            return mi.Float(1.0 if spec else 0.0)

        def _brdf(self, ctx, wi, wo, wl, active):
            if ctx.mode == mi.TransportMode.Radiance:
                return self.wave.brdf(wo, wi, wl, active)
            return self.wave.brdf(wi, wo, wl, active)

        def _eval_pdf(self, ctx, si, wo, active):
            spec, diff = self._lobes(ctx)
            if not diff:
                return spectrum(dr.zeros(mi.UnpolarizedSpectrum)), mi.Float(0.0)
            active = active & (si.wi.z > 0.0) & (wo.z > 0.0)
            f = self._brdf(ctx, si.wi, wo, si.wavelengths, active) * wo.z
            pdf = (1.0 - self._p_spec(si.wi.z, spec, diff)) * self.wave.lobe_pdf(si.wi, wo)
            return spectrum(dr.select(active, f, 0.0)), dr.select(active, pdf, 0.0)

        def sample(self, ctx, si, sample1, sample2, active=True):
            bs = dr.zeros(mi.BSDFSample3f)
            spec, diff = self._lobes(ctx)
            if not (spec or diff):
                return bs, spectrum(dr.zeros(mi.UnpolarizedSpectrum))
            cos_v = si.wi.z
            active = active & (cos_v > 0.0)
            wl = si.wavelengths
            p_spec = self._p_spec(cos_v, spec, diff)
            pick_spec = active & (sample1 < p_spec) if spec else mi.Bool(False)
            value = dr.zeros(mi.UnpolarizedSpectrum)
            if spec:  # the mirror direction, weight k_r / P(choice)
                k_r = self.wave.specular(cos_v, wl, pick_spec)
                value = dr.select(pick_spec, k_r / dr.maximum(p_spec, 1e-30), value)
            wo = mi.Vector3f(-si.wi.x, -si.wi.y, cos_v)
            pdf = p_spec
            if diff:
                pick_diff = active & ~pick_spec
                u = (sample1 - p_spec) / dr.maximum(1.0 - p_spec, 1e-30)
                w_d = self.wave.sample_lobe(si.wi, u, sample2)
                pdf_d = (1.0 - p_spec) * self.wave.lobe_pdf(si.wi, w_d)
                pick_diff &= (w_d.z > 0.0) & (pdf_d > 0.0)
                f = self._brdf(ctx, si.wi, w_d, wl, pick_diff)
                value = dr.select(pick_diff, f * (w_d.z / dr.maximum(pdf_d, 1e-30)), value)
                wo = dr.select(pick_diff, w_d, wo)
                pdf = dr.select(pick_diff, pdf_d, pdf)
                active = pick_spec | pick_diff
            bs.wo = wo
            bs.pdf = dr.select(active, pdf, 0.0)
            bs.eta = 1.0
            bs.sampled_type = dr.select(pick_spec, mi.UInt32(delta_type), mi.UInt32(glossy_type))
            bs.sampled_component = dr.select(pick_spec, mi.UInt32(0), mi.UInt32(1))
            return bs, spectrum(dr.select(active, value, 0.0))

        def eval(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active)[0]

        def pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active)[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active)

        def traverse(self, callback):
            put = getattr(callback, "put", None) or callback.put_parameter  # Mitsuba >= 3.6 / older
            put("k_r", self.wave.k_r, mi.ParamFlags.Differentiable)
            put("k_d", self.wave.k_d, mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys=None):
            pass

        to_string = _to_string

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
        variant: if given, ``mi.set_variant(variant)`` first. Must be a spectral variant: the
            vectorized ``'llvm_ad_spectral'``, ``'cuda_ad_spectral'`` (and their ``_polarized``
            forms), where the plugin evaluates a whole wavefront of rays per call with Dr.Jit
            arrays, or the scalar ``'scalar_spectral'``, ``'scalar_spectral_polarized'``, where it
            is plain Python called once per ray (much slower; the fallback where Dr.Jit's LLVM
            backend is missing, see :func:`best_variant`). Other variants raise
            :class:`~layerstack_jax.LayerstackError`.

    Returns:
        The plugin name, for ``{"type": name, "surface_id": ...}`` scene dictionaries.
    """
    mi, dr = import_mitsuba()
    if variant is not None:
        if variant.startswith("llvm"):
            require_llvm()
        mi.set_variant(variant)
    current = _check_variant(mi)
    with _LOCK:
        if current not in _REGISTERED:
            cls = _make_scalar_class(mi) if current.startswith("scalar") else _make_vector_class(mi, dr)
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
        A ``mi.BSDF`` to put in a scene dictionary (``"bsdf": coated_bsdf(tables)``). In a
        vectorized variant its parameters ``k_r`` and ``k_d`` (``mi.traverse``) are the flat tables,
        differentiable (:func:`layerstack_jax.render.render_vjp`).
    """
    mi, _ = import_mitsuba()  # first: without the extra, say how to install it
    surface = TableSurface(tables)
    name = register(variant)
    key = f"coating-{next(_IDS)}"
    _SURFACES[key] = (surface, timings)
    return mi.load_dict({"type": name, "surface_id": key})
