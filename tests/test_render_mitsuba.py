"""The Mitsuba 3 plugin renders what the library predicts (skipped without the `render` extra).

Every rendering test runs in each spectral variant: the scalar one (plain Python per ray) and the
vectorized ones (Dr.Jit arrays per wavefront: ``llvm_ad_spectral`` where an LLVM >= 17 is
installed, ``cuda_ad_spectral`` with a CUDA GPU), each skipped with the reason where absent.

Each scene is rendered with a ``specfilm`` whose channels are 10 nm boxes (450, 550, 650 nm): a
channel reads ∫ L(λ) s(λ) dλ, so channel / 10 nm is the radiance at that wavelength, and the
expected values are written from the library's own physics evaluated at the exact angles (not
from the tables the plugin reads):

* smooth coating, uniform environment of radiance 1: the mirror reflection reads R(θ_v)
  (``ls.specular``, natural light);
* rough coating (``ls.rough_brdf``, GGX), one directional light of irradiance 1: the pixel
  reads f(θ_l, θ_v, Δφ) cos θ_l (the delta lobe cannot reach a directional light);
* orientation: films on a rough object in the literal form of Hirayama's diffuse term
  (``ls.coated_rough(form="literal")``), which is not reciprocal: the pixel must read
  k_d(light → view) cos θ_l, not k_d(view → light); and the reciprocal radiometric form;
* white furnace: a sphere of a lossless film over a white (ρg = 1) Lambertian background, in a
  uniform environment: R + diffuse albedo = 1 exactly, so the sphere must read 1 and never more;
* the vectorized and the scalar plugin agree pixel by pixel within the Monte-Carlo error.

Angles are on the tables' nodes, so what is compared is the renderer's radiometry and the
plugin's lobes and sampling, with the wavelength interpolation (2–5 nm tables) as the only
approximation."""

from __future__ import annotations

import math

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")

import jax  # noqa: E402

import layerstack_jax as ls  # noqa: E402
from layerstack_jax._base.validate import LayerstackError  # noqa: E402
from layerstack_jax.render import CoatingTables, coated_bsdf  # noqa: E402
from layerstack_jax.render._llvm import llvm_problem  # noqa: E402

BANDS = (450.0, 550.0, 650.0)
HALF = 5.0  # nm, half width of each specfilm channel
VARIANTS = ("scalar_spectral", "llvm_ad_spectral", "cuda_ad_spectral")


def _use(variant):
    """Set ``variant``, or skip the test saying why it is absent here."""
    if variant.startswith("llvm") and llvm_problem():
        pytest.skip(f"{variant} unavailable: {llvm_problem()}")
    if variant.startswith("cuda"):
        import drjit as dr

        if not dr.has_backend(dr.JitBackend.CUDA):
            pytest.skip(f"{variant} unavailable: no CUDA GPU on this machine")
    if variant not in mi.variants():
        pytest.skip(f"{variant} unavailable: not in this Mitsuba build ({mi.variants()})")
    mi.set_variant(variant)


@pytest.fixture(params=VARIANTS)
def variant(request):
    _use(request.param)
    yield request.param
    mi.set_variant("scalar_spectral")


def _film(center, width=1, height=1):
    band = {"type": "regular", "wavelength_min": center - HALF, "wavelength_max": center + HALF, "values": "1, 1"}
    return {"type": "specfilm", "width": width, "height": height, "rfilter": {"type": "box"}, "band": band}


def _band_average(fn):
    """Mean of fn(wl) (wl: (n,) nm → (..., n)) over each 10 nm channel, (..., 3)."""
    out = []
    for c in BANDS:
        wl = np.linspace(c - HALF, c + HALF, 41)
        out.append(np.asarray(fn(wl)).mean(axis=-1))
    return np.stack(out, axis=-1)


def _camera(theta_deg, distance=20.0, fov=0.05, phi_deg=0.0, width=1, height=1, spp=64):
    th, ph = math.radians(theta_deg), math.radians(phi_deg)
    origin = [distance * math.sin(th) * math.cos(ph), distance * math.sin(th) * math.sin(ph), distance * math.cos(th)]
    up = [0, 0, 1] if theta_deg > 1 else [0, 1, 0]
    return {
        "type": "perspective",
        "fov": fov,
        "to_world": mi.ScalarTransform4f().look_at(origin=origin, target=[0, 0, 0], up=up),
        "film": {"width": width, "height": height},
        "sampler": {"type": "independent", "sample_count": spp},
    }


def _render(scene_dict):
    """Radiance per channel, ``(height, width, 3)``: one render per 10 nm channel (a film with
    one narrow channel draws all of a ray's wavelengths inside it)."""
    out = []
    for c in BANDS:
        sensor = dict(scene_dict["sensor"])
        size = sensor["film"]
        sensor["film"] = _film(c, size["width"], size["height"])
        scene = mi.load_dict({**scene_dict, "sensor": sensor})
        out.append(np.array(mi.render(scene, seed=1))[..., 0] / (2 * HALF))
    return np.stack(out, axis=-1)


STACK = ls.Stack(1.0, [ls.Layer(1.4, 400.0), ls.Layer(complex(0.3, 3.0), 8.0)], ls.Substrate(complex(1.2, 6.0)))
ANGLES_DEG = np.arange(0.0, 90.0, 10.0)  # table nodes; cos ascending below
COS = np.cos(np.radians(ANGLES_DEG))[::-1].copy()
WL = np.concatenate([np.arange(c - 7.5, c + 7.6, 2.5) for c in BANDS])  # the tables cover the channels


@jax.jit
def _R_rad(angle_rad, wl):
    return ls.specular(STACK, wl, angle_rad=angle_rad, both_sides=False).natural().R_front


def _R(angle_deg, wl):
    """Natural-light specular reflectance of STACK, ``(*angle, wl)`` (compiled once per shape)."""
    return np.asarray(_R_rad(np.radians(np.asarray(angle_deg, float)), np.asarray(wl, float)))


def _smooth_tables():
    k_r = _R(np.degrees(np.arccos(COS)), WL)
    return CoatingTables(WL, COS, k_r, np.zeros_like(k_r), np.array([0.0]), np.array([1.0]), np.zeros((COS.size, 1, 1, WL.size)))


@pytest.mark.parametrize("theta_v", [20.0, 60.0])
def test_smooth_mirror_reads_specular_reflectance(variant, theta_v):
    bsdf = coated_bsdf(_smooth_tables())
    got = _render({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "env": {"type": "constant", "radiance": {"type": "uniform", "value": 1.0}},
        "plane": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(50.0), "bsdf": bsdf},
        "sensor": _camera(theta_v, spp=128),
    })[0, 0]
    expected = _band_average(lambda wl: _R(theta_v, wl))
    assert np.abs(got - expected).max() < 2e-3 * expected.max() + 1e-4, (got, expected)
    assert np.ptp(expected) > 0.05  # the coating is coloured: the channels test the wavelength lookup


AZ_DEG = np.array([0.0, 45.0, 90.0, 135.0, 180.0])
ALPHA = 0.35
LOBE = 0.5  # share of the reflection in the glossy lobe, the rest in the delta lobe


@jax.jit
def _rough_jit(theta_i, theta_o, az, wl):
    return ls.rough_brdf(STACK, wl, theta_i, theta_o, az, roughness=ALPHA).specular


def _rough(theta_i, theta_o, az, wl):
    """GGX microfacet BRDF (1/sr) of STACK, angles in degrees, ``(*angle, wl)``."""
    args = np.broadcast_arrays(*(np.asarray(x, float) for x in (theta_i, theta_o, az)))
    return np.asarray(_rough_jit(*args, np.asarray(wl, float)))


@pytest.fixture(scope="module")
def rough_tables():
    ti, to, phi = np.meshgrid(np.degrees(np.arccos(COS)), np.degrees(np.arccos(COS)), AZ_DEG, indexing="ij")
    # the tables' φ is measured from the forward (specular) side: rough_brdf's azimuth is 180° − φ
    k_d = LOBE * _rough(ti, to, 180.0 - phi, WL)  # (A, B, P, L)
    k_r = (1 - LOBE) * _R(np.degrees(np.arccos(COS)), WL)  # a delta lobe as well (never seen by a directional light)
    return CoatingTables(WL, COS, k_r, np.zeros_like(k_r), np.radians(AZ_DEG), COS, k_d)


@pytest.mark.parametrize("theta_l, theta_v, az", [(40.0, 20.0, 180.0), (60.0, 50.0, 135.0), (20.0, 70.0, 90.0), (30.0, 30.0, 45.0)])
def test_rough_plane_under_directional_light_reads_brdf_cos_irradiance(variant, rough_tables, theta_l, theta_v, az):
    bsdf = coated_bsdf(rough_tables)
    # light travels along -l; the camera sits at azimuth 0, the light at azimuth az from it
    l = [math.sin(math.radians(theta_l)) * math.cos(math.radians(az)), math.sin(math.radians(theta_l)) * math.sin(math.radians(az)),
         math.cos(math.radians(theta_l))]
    got = _render({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sun": {"type": "directional", "direction": [-x for x in l], "irradiance": {"type": "uniform", "value": 1.0}},
        "plane": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(50.0), "bsdf": bsdf},
        "sensor": _camera(theta_v, spp=64),
    })[0, 0]
    # rough_brdf's azimuth is between the two outward directions (180°: mirror side)
    expected = LOBE * _band_average(lambda wl: _rough(theta_l, theta_v, az, wl)) * math.cos(math.radians(theta_l))
    assert np.abs(got - expected).max() < 3e-3 * expected.max() + 1e-5, (got, expected)


def _furnace_tables():
    """Lossless films over a white Lambertian background: all the light comes back out. The
    diffuse BRDF is K T(θi) T(θo) (Simonot eq. 77): ``ls.reflectance`` at normal incidence and
    viewing gives K T(0)², ``ls.specular`` the T(θ) of every node."""
    stack = ls.Stack(1.0, [ls.Layer(1.4, 400.0), ls.Layer(2.0, 120.0)], ls.LambertianBackground(1.5, 1.0))

    @jax.jit
    def optics(theta):
        response = ls.specular(stack, WL, angle_rad=theta, both_sides=False).natural()
        return response.R_front, response.T_front, ls.reflectance(stack, WL, ls.BRDF(0.0, 0.0))

    k_r, T, f0 = (np.asarray(x) for x in optics(np.concatenate([np.arccos(COS_F), [0.0]])))
    k_r, T, T0 = k_r[:-1], T[:-1], T[-1]
    k_d = (f0 / T0**2 * T[:, None, :] * T[None, :, :])[:, :, None, :]
    return CoatingTables(WL, COS_F, k_r, np.zeros_like(k_r), np.array([0.0]), COS_F, k_d)


COS_F = np.linspace(0.0, 1.0, 41)[1:]


def test_white_furnace_does_not_gain_energy(variant):
    tables = _furnace_tables()
    albedo = tables.k_r[-1] + 2 * np.pi * np.trapezoid(tables.k_d[-1, :, 0] * COS_F[:, None], COS_F, axis=0)
    assert np.abs(albedo - 1).max() < 0.02  # the tables themselves conserve energy (up to the trapezoid rule)
    bsdf = coated_bsdf(tables)
    img = _render({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "env": {"type": "constant", "radiance": {"type": "uniform", "value": 1.0}},
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "sensor": _camera(0.0, distance=5.0, fov=14.0, width=8, height=8, spp=64),
    })
    disc = img.reshape(-1, 3)
    mean, err = disc.mean(axis=0), disc.std(axis=0) / math.sqrt(disc.shape[0] * 64)
    assert np.all(mean <= 1.0 + 4 * err + 2e-3), (mean, err)  # (float32 in the vectorized variants: ~1e-6)
    assert np.all(mean >= 0.97), mean


def test_plugin_rejects_non_spectral_variants_and_bad_tables():
    for other in ("scalar_rgb", "llvm_ad_rgb"):
        if other.startswith("llvm") and llvm_problem():
            continue
        mi.set_variant(other)
        try:
            with pytest.raises(LayerstackError, match="spectral variant"):
                coated_bsdf(_smooth_tables())
        finally:
            mi.set_variant("scalar_spectral")
    t = _smooth_tables()
    with pytest.raises(LayerstackError, match="k_r must have shape"):
        coated_bsdf(t._replace(k_r=t.k_r[:, :3]))


def test_missing_llvm_is_one_sentence_not_an_abort(monkeypatch):
    """Without an LLVM >= 17 Dr.Jit's LLVM backend aborts the process: the library says what to
    install instead, before the variant is set."""
    from layerstack_jax.render import _llvm

    monkeypatch.delenv("DRJIT_LIBLLVM_PATH", raising=False)
    monkeypatch.setattr(_llvm, "find_llvm", lambda min_version=_llvm.MIN_LLVM: None)
    monkeypatch.setattr(_llvm.sys, "platform", "linux")
    problem = _llvm.llvm_problem()
    assert "apt-get install libllvm19" in problem and "scalar_spectral" in problem
    assert _llvm.best_variant() in ("scalar_spectral", "cuda_ad_spectral")
    with pytest.raises(LayerstackError, match="LLVM >= 17"):
        coated_bsdf(_smooth_tables(), variant="llvm_ad_spectral")
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/nonexistent/libLLVM.so")
    assert "does not exist" in _llvm.llvm_problem()
    # library names: Debian's libLLVM.so.19.1 and libLLVM-15.so.1, llvm-19/lib/libLLVM.so.1 (ABI number 1)
    versions = [_llvm._version(p) for p in ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", "/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1",
                                            "/usr/lib/llvm-19/lib/libLLVM.so.1")]
    assert versions == [19, 15, 19]


@pytest.mark.parametrize("variant_polarized", [v + "_polarized" for v in VARIANTS])
def test_polarized_variant_renders_a_depolarizer(variant_polarized):
    _use(variant_polarized)
    try:
        bsdf = coated_bsdf(_smooth_tables())
        got = _render({
            "type": "scene",
            "integrator": {"type": "path", "max_depth": 3},
            "env": {"type": "constant", "radiance": {"type": "uniform", "value": 1.0}},
            "plane": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(50.0), "bsdf": bsdf},
            "sensor": _camera(60.0, spp=64),
        })[0, 0]
    finally:
        mi.set_variant("scalar_spectral")
    expected = _band_average(lambda wl: _R(60.0, wl))
    assert np.abs(got - expected).max() < 2e-3 * expected.max() + 1e-4


# -- orientation: a non-reciprocal k_d (Hirayama's diffuse term as printed) -------------------
COATED = ls.Stack(1.0, [ls.Layer(1.4, 600.0), ls.Layer(2.0, 90.0)], ls.Substrate(complex(1.2, 6.0)))
SIGMA, TAU = 30.0, 300.0
PHI_DEG = np.array([0.0, 90.0, 180.0])  # the tables' φ: from the forward (specular) side


@jax.jit(static_argnames="form")
def _coated_kd_jit(theta_l, theta_v, phi, wl, form):
    return ls.coated_rough(COATED, wl, theta_l, theta_v, phi, sigma_nm=SIGMA, tau_nm=TAU, form=form, n_terms=40).k_d


def _coated_kd(theta_l, theta_v, phi, wl, form):
    """k_d(light → view) (1/sr) of COATED from the library, angles in degrees, ``(*angle, wl)``."""
    args = np.broadcast_arrays(*(np.asarray(x, float) for x in (theta_l, theta_v, phi)))
    return np.asarray(_coated_kd_jit(*args, np.asarray(wl, float), form=form))


@pytest.fixture(scope="module", params=["literal", "radiometric"])
def coated_tables(request):
    form = request.param
    deg = np.degrees(np.arccos(COS))
    tl, tv, ph = np.meshgrid(deg, deg, PHI_DEG, indexing="ij")
    k_d = _coated_kd(tl, tv, ph, WL, form)  # (A, B, P, L): light on the incidence axis
    k_r = 0.3 * _R(deg, WL)  # a delta lobe too (a directional light never sees it)
    return form, CoatingTables(WL, COS, k_r, np.zeros_like(k_r), np.radians(PHI_DEG), COS, k_d)


@pytest.mark.parametrize("theta_l, theta_v, phi", [(40.0, 20.0, 0.0), (20.0, 60.0, 90.0), (70.0, 30.0, 180.0)])
def test_orientation_light_on_the_incidence_axis(variant, coated_tables, theta_l, theta_v, phi):
    """A plane under a directional light reads k_d(light → view) cos θ_l E, for a table that is
    not reciprocal (literal form: k_d(l → v) / k_d(v → l) is far from 1 at these angles) as for
    one that is (radiometric)."""
    form, tables = coated_tables
    bsdf = coated_bsdf(tables)
    # camera at azimuth 0; φ from the forward side, so the light sits at azimuth 180° − φ
    az = math.radians(180.0 - phi)
    l = [math.sin(math.radians(theta_l)) * math.cos(az), math.sin(math.radians(theta_l)) * math.sin(az), math.cos(math.radians(theta_l))]
    got = _render({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sun": {"type": "directional", "direction": [-x for x in l], "irradiance": {"type": "uniform", "value": 1.0}},
        "plane": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(50.0), "bsdf": bsdf},
        "sensor": _camera(theta_v, spp=32),
    })[0, 0]
    cos_l = math.cos(math.radians(theta_l))
    forward = _band_average(lambda wl: _coated_kd(theta_l, theta_v, phi, wl, form)) * cos_l
    reverse = _band_average(lambda wl: _coated_kd(theta_v, theta_l, phi, wl, form)) * cos_l
    assert np.abs(got - forward).max() < 3e-3 * forward.max() + 1e-5, (got, forward, reverse)
    if form == "literal":  # the test can tell the two orientations apart
        assert np.abs(reverse / forward - 1).min() > 0.1, (forward, reverse)
    else:
        assert np.allclose(reverse, forward, rtol=1e-6)


def _small_scene(bsdf, spp, size=(20, 14)):
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4},
        "env": {"type": "constant", "radiance": {"type": "uniform", "value": 0.5}},
        "sun": {"type": "directional", "direction": [0.4, 0.7, -0.6], "irradiance": {"type": "uniform", "value": 2.0}},
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, -1]) @ mi.ScalarTransform4f().scale(4.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.4}}},
        "sensor": {"type": "perspective", "fov": 45.0,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0.0, -4.0, 1.5], target=[0, 0, -0.2], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": size[0], "height": size[1], "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
    }


def _seeded_renders(variant, tables, seeds, spp):
    mi.set_variant(variant)
    scene = mi.load_dict(_small_scene(coated_bsdf(tables), spp))
    return np.stack([np.array(mi.render(scene, seed=s)) for s in seeds])


@pytest.mark.parametrize("vector", ["llvm_ad_spectral", "cuda_ad_spectral"])
def test_vectorized_and_scalar_agree_pixel_by_pixel(vector, coated_tables):
    """A rough coated sphere (both lobes, literal and radiometric tables) on a floor under a sun
    and a sky: each pixel's mean over 8 independent renders of each variant, compared with the
    error of the difference estimated from the renders' spread."""
    form, tables = coated_tables
    _use(vector)
    seeds = range(8)
    try:
        fast = _seeded_renders(vector, tables, seeds, 8)
        slow = _seeded_renders("scalar_spectral", tables, [100 + s for s in seeds], 8)
    finally:
        mi.set_variant("scalar_spectral")
    n = len(seeds)
    diff = fast.mean(0) - slow.mean(0)
    sigma = np.sqrt(fast.var(0, ddof=1) / n + slow.var(0, ddof=1) / n)
    z = diff / np.maximum(sigma, 1e-4 * np.abs(slow.mean(0)).max())
    assert np.mean(np.abs(z) > 4) < 0.01, (np.sort(np.abs(z).ravel())[-10:], form)
    assert abs(z.mean()) < 4 / math.sqrt(z.size) + 0.05, z.mean()  # no bias across the image
    # the whole image: the difference of the means against its spread over the renders
    means_f, means_s = fast.mean(axis=(1, 2, 3)), slow.mean(axis=(1, 2, 3))
    err = math.sqrt(means_f.var(ddof=1) / n + means_s.var(ddof=1) / n)
    assert abs(means_f.mean() - means_s.mean()) < 4 * err, (means_f.mean(), means_s.mean(), err)


def test_paper_scenes_load_and_render(variant):
    """Fig. 8 and Fig. 9 scenes load and render (tiny, built-in BSDFs for the objects but one
    coated sphere), and the lamp spectrum is colour-science's CIE FL8 up to its normalization."""
    colour = pytest.importorskip("colour")
    from layerstack_jax.render._scenes import fig8_scene, fig9_scene, fluorescent_spectrum

    spec = fluorescent_spectrum("FL8", 2.0)
    values = np.array([float(x) for x in spec["values"].split(",")])
    ref = np.asarray(colour.SDS_ILLUMINANTS["FL8"].values)
    assert np.allclose(values, 2.0 * ref / ref.mean(), rtol=1e-5) and values.mean() == pytest.approx(2.0, rel=1e-5)
    with pytest.raises(LayerstackError, match="F-series"):
        fluorescent_spectrum("D65")
    coated = coated_bsdf(_smooth_tables())
    metal = {"type": "conductor"}
    for scene in (fig8_scene(coated, metal, width=8, height=6, spp=2), fig9_scene(metal, metal, coated, width=8, height=6, spp=2)):
        img = np.array(mi.render(mi.load_dict(scene)))
        assert img.shape == (6, 8, 3) and np.all(np.isfinite(img)) and img.mean() > 0


@pytest.mark.parametrize("vector", ["llvm_ad_spectral", "cuda_ad_spectral"])
def test_wavefront_lookups_equal_the_scalar_ones(vector):
    """The Dr.Jit lookups (_wavefront) against the scalar ones (_lookup) on random tables and
    random directions, lane by lane: k_r, k_d, the lobe choice, the pdf and the sampled direction
    for the same uniform numbers (float32 vs float64: 1e-4 relative)."""
    from layerstack_jax.render._lookup import TableSurface
    from layerstack_jax.render._wavefront import WavefrontSurface

    _use(vector)
    try:
        import drjit as dr

        rng = np.random.default_rng(7)
        A, B, P, L = 7, 6, 5, 9
        wl = np.sort(rng.uniform(380, 780, L))
        t = CoatingTables(wl, np.sort(rng.uniform(0.05, 1.0, A)), rng.uniform(0, 0.4, (A, L)), np.zeros((A, L)),
                          np.sort(rng.uniform(0, np.pi, P)), np.sort(rng.uniform(0.05, 1.0, B)), rng.uniform(0, 0.1, (A, B, P, L)))
        surf = TableSurface(t)
        wave = WavefrontSurface(surf.arrays, surf.has_specular, surf.has_diffuse, mi, dr)
        n = 400

        def dirs(cos):
            phi = rng.uniform(-np.pi, np.pi, n)
            s = np.sqrt(1 - cos**2)
            return np.stack([s * np.cos(phi), s * np.sin(phi), cos], -1)

        light, view = dirs(rng.uniform(0.0, 1.0, n)), dirs(rng.uniform(0.0, 1.0, n))
        lams = rng.uniform(360, 830, (n, 4))  # beyond the tables: clamped
        u, u2 = rng.random(n), rng.random((n, 2))
        V = lambda a: mi.Vector3f(*(mi.Float(a[:, k]) for k in range(3)))  # noqa: E731
        spec = mi.UnpolarizedSpectrum(*(mi.Float(lams[:, k]) for k in range(4)))
        got = {
            "k_r": np.array(wave.specular(mi.Float(view[:, 2]), spec)),
            "k_d": np.array(wave.brdf(V(light), V(view), spec)),
            "p_spec": np.array(wave.specular_probability(mi.Float(view[:, 2]))),
            "pdf": np.array(wave.lobe_pdf(V(view), V(light))),
            "sample": np.array(wave.sample_lobe(V(view), mi.Float(u), mi.Point2f(mi.Float(u2[:, 0]), mi.Float(u2[:, 1])))),
        }
    finally:
        mi.set_variant("scalar_spectral")
    want = {
        "k_r": np.array([surf.specular(view[j, 2], lams[j]) for j in range(n)]).T,
        "k_d": np.array([surf.brdf(light[j], view[j], lams[j]) for j in range(n)]).T,
        "p_spec": np.array([surf.specular_probability(view[j, 2]) for j in range(n)]),
        "pdf": np.array([surf.lobe_pdf(view[j], light[j]) for j in range(n)]),
        "sample": np.array([surf.sample_lobe(view[j], u[j], tuple(u2[j])) for j in range(n)]).T,
    }
    for key in want:
        g, w = np.asarray(got[key], float).reshape(want[key].shape), want[key]
        assert np.allclose(g, w, rtol=1e-4, atol=1e-4 * np.abs(w).max()), (key, np.abs(g - w).max())


def test_lamp_spectrum_in_the_sensor_gives_the_same_image(variant):
    """The paper scenes put the lamp's spectrum in the camera's spectral response and make the
    emitters flat: by linearity the same image in expectation as lamp-coloured emitters (every
    source has that spectrum, the floor is grey). Per channel, over 4 seeds each, within 4σ."""
    from layerstack_jax.render._scenes import fig8_scene

    coated = coated_bsdf(_smooth_tables())
    metal = {"type": "roughconductor", "material": "Al", "alpha": 0.2}
    means = {}
    for in_sensor in (True, False):
        scene = mi.load_dict(fig8_scene(coated, metal, width=16, height=12, spp=16, spectrum_in_sensor=in_sensor))
        means[in_sensor] = np.array([np.array(mi.render(scene, seed=s)).mean(axis=(0, 1)) for s in range(4)])
    a, b = means[True], means[False]
    err = np.sqrt(a.var(0, ddof=1) / 4 + b.var(0, ddof=1) / 4)
    assert np.all(np.abs(a.mean(0) - b.mean(0)) < 4 * err + 1e-3 * b.mean(0)), (a.mean(0), b.mean(0), err)


# -- differentiable through the image ---------------------------------------------------------
WL_G = np.linspace(400.0, 700.0, 8)


def _gradient_scene(bsdf):
    T = mi.ScalarTransform4f
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "env": {"type": "constant", "radiance": {"type": "uniform", "value": 0.3}},
        "lamp": {"type": "rectangle", "to_world": T().look_at(origin=[0, -3, 3], target=[0, 0, 0], up=[0, 0, 1]) @ T().scale(1.5),
                 "emitter": {"type": "area", "radiance": {"type": "uniform", "value": 3.0}}},
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "sensor": {"type": "perspective", "fov": 40.0, "to_world": T().look_at(origin=[0, -4, 1], target=[0, 0, 0], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": 24, "height": 18}, "sampler": {"type": "independent", "sample_count": 8}},
    })


@pytest.mark.parametrize("case", ["thickness, smooth film", "sigma0, rough object"])
def test_image_gradient_matches_central_differences(case):
    """∂ℓ/∂θ of ℓ = Σ w·I (fixed random weights) by Mitsuba's reverse mode through the tables and
    JAX's VJP of the tables (render_vjp), against central differences of rendered images with the
    same seed. With the same seed the paths do not move (the sampling densities are fixed), so
    the difference quotient is the derivative of the same Monte-Carlo estimate: what separates
    them is the quotient's truncation (O(h²), h = 0.5 nm) and float32 rounding, far below the
    gradient's own Monte-Carlo error — the spread between two seeds, asserted to be larger than
    the tolerance (3e-3) so that the comparison is not vacuous."""
    from layerstack_jax._appearance.render_tables import angle_grid
    from layerstack_jax.render import coating_table_values, render_vjp

    _use("llvm_ad_spectral")
    try:
        cos = angle_grid(10)
        rough = case.startswith("sigma0")
        cos_o, phi = (angle_grid(6), np.linspace(0.0, np.pi, 5)) if rough else (None, None)

        def tables_fn(theta):
            stack = ls.Stack(1.0, [ls.Layer(1.45, theta["d"])], ls.Substrate(complex(0.25, 3.2)))
            return coating_table_values(stack, WL_G, cos, cos_o, phi, sigma_nm=theta["sigma"], tau_nm=300.0, n_terms=30)

        theta0 = {"d": jnp_scalar(320.0), "sigma": jnp_scalar(30.0 if rough else 0.0)}
        t0 = tables_fn(theta0)
        k_r = np.asarray(t0["k_r"])
        k_d = np.asarray(t0["k_d"]) if rough else np.zeros((cos.size, 0, 0, WL_G.size))
        tables = CoatingTables(WL_G, cos, k_r, np.zeros_like(k_r), phi if rough else np.zeros(0),
                               cos_o if rough else np.zeros(0), k_d)
        bsdf = coated_bsdf(tables)
        scene = _gradient_scene(bsdf)
        w = np.random.default_rng(0).random((18, 24, 3))
        name = "sigma" if rough else "d"

        def gradient(seed):
            img, vjp = render_vjp(scene, bsdf, tables_fn, theta0, seed=seed)
            return float(vjp(w)[name]), img

        g, img = gradient(3)
        g_other, _ = gradient(4)
        h = 0.5

        def loss(delta):
            theta = dict(theta0, **{name: theta0[name] + delta})
            image, _ = render_vjp(scene, bsdf, tables_fn, theta, seed=3)
            return float(np.sum(image.astype(np.float64) * w))

        fd = (loss(h) - loss(-h)) / (2 * h)
    finally:
        mi.set_variant("scalar_spectral")
    assert np.all(np.isfinite(img)) and img.mean() > 0
    tol = 3e-3 * abs(fd)  # measured: 1.2e-4 (thickness), 5e-5 (σ0); seeds differ by 10 % and 2 %
    assert abs(g - fd) < tol, (g, fd)
    assert abs(g - g_other) > tol, (g, g_other)  # the Monte-Carlo error of the gradient exceeds the tolerance


def jnp_scalar(x):
    import jax.numpy as jnp

    return jnp.asarray(x, dtype=jnp.float64)
