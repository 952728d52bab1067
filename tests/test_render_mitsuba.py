"""The Mitsuba 3 plugin renders what the library predicts (skipped without the `render` extra).

Each scene is rendered in ``scalar_spectral`` with a ``specfilm`` whose channels are 10 nm
boxes (450, 550, 650 nm): a channel reads ∫ L(λ) s(λ) dλ, so channel / 10 nm is the radiance
at that wavelength, and the expected values are written from the library's own physics
evaluated at the exact angles (not from the tables the plugin reads):

* smooth coating, uniform environment of radiance 1: the mirror reflection reads R(θ_v)
  (``ls.specular``, natural light);
* rough coating (``ls.rough_brdf``, GGX), one directional light of irradiance 1: the pixel
  reads f(θ_l, θ_v, Δφ) cos θ_l (the delta lobe cannot reach a directional light);
* white furnace: a sphere of a lossless film over a white (ρg = 1) Lambertian background, in a
  uniform environment: R + diffuse albedo = 1 exactly, so the sphere must read 1 and never more.

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
from layerstack_jax._validate import LayerstackError  # noqa: E402
from layerstack_jax.render import CoatingTables, coated_bsdf  # noqa: E402

BANDS = (450.0, 550.0, 650.0)
HALF = 5.0  # nm, half width of each specfilm channel


@pytest.fixture(scope="module", autouse=True)
def spectral():
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
def test_smooth_mirror_reads_specular_reflectance(theta_v):
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
def test_rough_plane_under_directional_light_reads_brdf_cos_irradiance(rough_tables, theta_l, theta_v, az):
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


def test_white_furnace_does_not_gain_energy():
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
    assert np.all(mean <= 1.0 + 4 * err + 2e-3), (mean, err)
    assert np.all(mean >= 0.97), mean


def test_plugin_rejects_rgb_variant_and_bad_tables():
    mi.set_variant("scalar_rgb")
    try:
        with pytest.raises(LayerstackError, match="scalar spectral variant"):
            coated_bsdf(_smooth_tables())
    finally:
        mi.set_variant("scalar_spectral")
    t = _smooth_tables()
    with pytest.raises(LayerstackError, match="k_r must have shape"):
        coated_bsdf(t._replace(k_r=t.k_r[:, :3]))


def test_polarized_variant_renders_a_depolarizer():
    mi.set_variant("scalar_spectral_polarized")
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


def test_paper_scenes_load_and_render():
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
