# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 7 · Rendering coated objects with Mitsuba 3 (Hirayama et al. §5–6, Figs. 8–9)
#
# *H. Hirayama, K. Kaneda, H. Yamashita and Y. Monden, "An accurate illumination model for
# objects coated with multilayer films".*
#
# Hirayama et al. pre-compute the reflectance of a coating "for each sampled incident angle and
# wave length of light", store it in tables and interpolate them linearly in their ray tracer
# (§5). Their illumination model (eq. 8) has two terms: a specular reflectance $k_r(\theta_i,
# \lambda)$ in the mirror direction, and a diffuse BRDF $k_d(\omega_l, \omega_i, \lambda)$ of
# the rough object under smooth films (He–Torrance roughness: rms height σ0, autocorrelation
# length τ). Here:
#
# 1. `coating_tables` (`layerstack_jax._render_tables`) computes those tables;
# 2. `layerstack_jax.render.coated_bsdf` turns them into a **Mitsuba 3 BSDF** (a Python
#    plugin of the `scalar_spectral` variant: it reads the wavelengths Mitsuba draws for each
#    ray, interpolates the tables and importance-samples them);
# 3. we render the scenes of Fig. 8 (aluminium spheres coated with dielectric A 1000 nm /
#    silver 5 nm / dielectric A 1000 nm beside bare ones, σ0 = 0, 25, 50 nm, τ = 300 nm) and
#    Fig. 9 (Table 1: teapot, cylinder, sphere; smooth and rough), under a fluorescent lamp;
# 4. we **measure** the paper's claim of §6 — iridescent colours "appear more clearly" on the
#    rough spheres — as the saturation of the coated sphere's pixels.
#
# The plugin's radiometry is tested in `tests/test_render_mitsuba.py` (a plane under a
# directional light reads the library's BRDF × cos × irradiance; a white furnace reads 1).
# Mitsuba is an optional extra (`pip install 'layerstack-jax[render]'`): without it this
# notebook computes and plots the tables and skips the renders.

# %%
import jax

jax.config.update("jax_enable_x64", True)  # user code chooses the precision, never the library

import time

import colour
import matplotlib.pyplot as plt
import numpy as np

import layerstack_jax as ls
from layerstack_jax._render_tables import coating_tables

from _figures import save  # figures: notebooks/figures/ (tests: NOTEBOOK_FIGURES)

try:
    import mitsuba as mi

    mi.set_variant("scalar_spectral")
    HAVE_MITSUBA = True
except ImportError:
    HAVE_MITSUBA = False
print(f"Mitsuba: {mi.__version__ + ', scalar_spectral' if HAVE_MITSUBA else 'not installed, renders skipped'}")

T_START = time.perf_counter()
wl = np.arange(380.0, 781.0, 10.0)  # the 1 µm dielectric layers give fringes ~110 nm apart


def on_grid(book, source):
    n = np.asarray(ls.material(book, source)(wl))
    return ls.Index(n.real, n.imag)


silver, gold = on_grid("Ag", "Johnson"), on_grid("Au", "Johnson")
aluminium, copper, silicon = on_grid("Al", "Rakic"), on_grid("Cu", "Johnson"), on_grid("Si", "Aspnes")


def stack(layers, substrate):
    return ls.Stack(1.0, [ls.Layer(n, d) for n, d in layers], ls.Substrate(substrate))


A, B = 1.4, 2.0
ag_coating = [(A, 1000.0), (silver, 5.0), (A, 1000.0)]
stacks = {
    "Al + A/Ag/A": stack(ag_coating, aluminium),  # Fig. 8 (d)–(f); the teapot of Table 1
    "bare Al": stack([(A, 0.0), (silver, 0.0), (A, 0.0)], aluminium),  # same structure, zero thickness
    "Si + B/A/B/A": stack([(B, 1000.0), (A, 1000.0), (B, 1000.0), (A, 1000.0)], silicon),  # cylinder
    "Cu + A/Au/A": stack([(A, 1000.0), (gold, 5.0), (A, 1000.0)], copper),  # sphere
}

# %% [markdown]
# ## 1 · The tables
#
# For each coating and roughness: $k_r$ over 31 incidence angles (3° steps) × 41 wavelengths,
# and for σ0 > 0 the diffuse $k_d$ over 31 × 10 outgoing angles × 7 azimuths × 41 wavelengths.
# Table 1 of the paper gives no roughness values that survive in our copy; we take σ0 = 25 nm,
# τ = 300 nm for the rough objects of Fig. 9.

# %%
SIGMAS = (0.0, 25.0, 50.0)
table_options = dict(n_angles=31, n_angles_out=10, n_phi=7, tau_nm=300.0, estimate_error=False)


def tables_for(name, sigma):
    return coating_tables(stacks[name], wl, sigma_nm=sigma, include_diffuse=sigma > 0, **table_options)


t0 = time.perf_counter()
tables = {(name, s): tables_for(name, s) for name in ("Al + A/Ag/A", "bare Al") for s in SIGMAS}
tables.update({(name, s): tables_for(name, s) for name in ("Si + B/A/B/A", "Cu + A/Au/A") for s in (0.0, 25.0)})
print(f"{len(tables)} tables in {time.perf_counter() - t0:.0f} s")


def albedo(t):
    """Directional albedo of k_d at each incidence node and wavelength (trapezoid in cos θo and φ)."""
    if t.k_d.size == 0:
        return np.zeros_like(t.k_r)
    over_phi = 2.0 * np.trapezoid(t.k_d, t.phi_out, axis=2)  # both signs of the azimuth
    return np.trapezoid(over_phi * t.cos_theta_out[None, :, None], t.cos_theta_out, axis=1)


fig, axes = plt.subplots(1, 2, figsize=(11, 3.6), sharey=True)
for ax, name in zip(axes, ("Al + A/Ag/A", "bare Al")):
    for k, s in enumerate(SIGMAS):
        t = tables[(name, s)]
        ax.plot(wl, t.k_r[-1], color=f"C{k}", label=f"k_r, σ0 = {s:.0f} nm")
        if s > 0:
            ax.plot(wl, albedo(t)[-1], "--", color=f"C{k}", label=f"albedo of k_d, σ0 = {s:.0f} nm")
    ax.set(title=f"{name}, normal incidence", xlabel="wavelength (nm)", ylim=(0, 1))
axes[0].set_ylabel("reflectance")
axes[1].legend(fontsize=7)
save(fig, "07_tables")
for s in SIGMAS[1:]:
    t = tables[("Al + A/Ag/A", s)]
    total = t.k_r + albedo(t)
    print(f"A/Ag/A on Al, σ0 = {s:.0f} nm: k_r(0°) = {t.k_r[-1].min():.2f}…{t.k_r[-1].max():.2f}, "
          f"albedo of k_d (0°) = {albedo(t)[-1].min():.2f}…{albedo(t)[-1].max():.2f}, k_r + albedo ≤ {total.max():.3f}")
    assert total.max() <= 1.0 + 2e-2  # no energy created (trapezoid rule on the table grid)

# %% [markdown]
# As σ0 grows the specular reflectance falls — by the He–Torrance factor, strongest in the blue
# (σ0/λ larger) — and the diffuse lobe takes up part of it.
#
# ## 2 · Fig. 8: coated and bare aluminium spheres, σ0 = 0, 25, 50 nm
#
# Left sphere coated, right sphere bare, under a rectangular fluorescent lamp (CIE FL8, 5000 K,
# the "neutral white" N of the paper) and a dim surround of the same spectrum, on a grey floor.
# 16 samples per pixel: the noise that remains is Monte-Carlo noise, not a bias.

# %%
from layerstack_jax.render import coated_bsdf  # noqa: E402  (needs mitsuba only when called)
from layerstack_jax.render._scenes import LAMP, fig8_scene, fig9_scene  # noqa: E402

SIZE8, SPP = (128, 80), 16


def to_srgb(img):
    """Linear sRGB (Mitsuba's hdrfilm) → display sRGB in [0, 1], a fixed exposure for all renders."""
    return np.clip(colour.cctf_encoding(np.clip(np.asarray(img) * EXPOSURE, 0, None)), 0, 1)


def shape_mask(scene_dict, name):
    """Pixels whose centre ray hits the shape ``name`` first (Mitsuba's own ray casting)."""
    scene = mi.load_dict(scene_dict)
    sensor = scene.sensors()[0]
    w, h = sensor.film().crop_size()
    mask = np.zeros((h, w), bool)
    for y in range(h):
        for x in range(w):
            ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((x + 0.5) / w, (y + 0.5) / h), mi.Point2f(0.5, 0.5))
            si = scene.ray_intersect(ray)
            mask[y, x] = si.is_valid() and si.shape.id() == name
    return mask


lamp_xy = colour.XYZ_to_xy(colour.sd_to_XYZ(colour.SDS_ILLUMINANTS[LAMP]))
lamp_uv = colour.xy_to_Luv_uv(lamp_xy)


def xyz(img_linear):
    """Linear sRGB (Mitsuba's hdrfilm output) → CIE XYZ (relative)."""
    return colour.RGB_to_XYZ(np.asarray(img_linear, float), colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False)


def saturation(XYZ):
    """CIE 1976 saturation s_uv = 13 |(u', v') − (u', v')_lamp| (independent of exposure)."""
    uv = colour.xy_to_Luv_uv(colour.XYZ_to_xy(np.maximum(XYZ, 1e-12)))
    return 13.0 * np.linalg.norm(uv - lamp_uv, axis=-1)


def block_saturation(img_linear, mask, block=8):
    """s_uv of the mean XYZ of each block × block tile lying wholly inside ``mask``, and the tile's
    mean Y. Averaging tiles first removes most of the colour noise of spectral Monte Carlo (four
    wavelengths per sample, drawn from the eye's sensitivity while the lamp's spectrum has
    mercury lines), which would otherwise read as saturation."""
    h, w = (s // block * block for s in mask.shape)
    tiles = lambda a: a[:h, :w].reshape(h // block, block, w // block, block, *a.shape[2:])  # noqa: E731
    inside = tiles(mask).all(axis=(1, 3))
    XYZ = tiles(xyz(img_linear)).mean(axis=(1, 3))[inside]
    return saturation(XYZ), XYZ[:, 1]


EXPOSURE = 1.0
renders8, stats8 = {}, {}
if HAVE_MITSUBA:
    t0 = time.perf_counter()
    masks = None
    for s in SIGMAS:
        scene = fig8_scene(coated_bsdf(tables[("Al + A/Ag/A", s)]), coated_bsdf(tables[("bare Al", s)]),
                           width=SIZE8[0], height=SIZE8[1], spp=SPP)
        if masks is None:
            masks = {k: shape_mask(scene, k) for k in ("coated", "bare")}
        renders8[s] = np.array(mi.render(mi.load_dict(scene), seed=0))
    # one exposure for every render: the smooth pair's mean luminance at 0.45 (highlights clip)
    EXPOSURE = 0.45 / np.mean(xyz(renders8[0.0])[..., 1][masks["coated"] | masks["bare"]])
    for s, img in renders8.items():
        stats8[s] = {}
        for k, m in masks.items():
            sat, Y = block_saturation(img, m)
            stats8[s][k] = (np.mean(sat), np.percentile(sat, 90), np.mean(Y))
    print(f"Fig. 8: 3 renders of {SIZE8[0]}×{SIZE8[1]} px at {SPP} spp in {time.perf_counter() - t0:.0f} s")

    fig, axes = plt.subplots(1, 3, figsize=(12, 2.9))
    for ax, s in zip(axes, SIGMAS):
        ax.imshow(to_srgb(renders8[s]))
        ax.set_title(f"σ0 = {s:.0f} nm (left: A/Ag/A on Al; right: bare Al)", fontsize=8)
        ax.axis("off")
    save(fig, "07_fig8_spheres")

    print("8×8-pixel tiles inside each sphere: CIE 1976 saturation s_uv against the lamp's white, and luminance Y")
    print("sphere        σ0 (nm)   mean s_uv   90th pct s_uv   mean Y (exposed)")
    for s in SIGMAS:
        for k in ("coated", "bare"):
            m, p90, Y = stats8[s][k]
            print(f"{k:12s}  {s:5.0f}      {m:6.3f}      {p90:6.3f}         {Y * EXPOSURE:6.3f}")
    # the coating colours the sphere, at every roughness: far more saturated than bare aluminium
    assert all(stats8[s]["coated"][0] > stats8[s]["bare"][0] for s in SIGMAS)

# %% [markdown]
# **The claim of §6, measured.** The paper says that the iridescent colours on the rough
# spheres "appear more clearly" than on the smooth ones, "because reflected light from the rough
# surfaces is weaker than that of the ideally smooth surfaces due to the roughness, and the
# iridescent colors are emphasized". The table above puts numbers on it: the mean CIE 1976
# saturation $s_{uv}$ of the coated sphere's pixels and their mean luminance, smooth against
# rough, with the bare sphere (neutral aluminium: its $s_{uv}$ is pure Monte-Carlo colour noise)
# as the noise floor. The printout of the cell below states what the measurement says.

# %%
if HAVE_MITSUBA:
    excess = {s: stats8[s]["coated"][0] - stats8[s]["bare"][0] for s in SIGMAS}
    y_smooth, y25, y50 = (stats8[s]["coated"][2] for s in SIGMAS)
    print("coated sphere, mean s_uv: " + ", ".join(f"{stats8[s]['coated'][0]:.3f} (σ0 = {s:.0f} nm)" for s in SIGMAS))
    print("excess over the bare sphere (its s_uv is the noise floor: bare Al under this lamp is neutral): "
          + ", ".join(f"{excess[s]:+.3f} (σ0 = {s:.0f} nm)" for s in SIGMAS))
    print(f"mean luminance of the coated sphere: ×{y25 / y_smooth:.2f} (25 nm) and ×{y50 / y_smooth:.2f} (50 nm) of the smooth one's")
    coated_gain = max(stats8[25.0]["coated"][0], stats8[50.0]["coated"][0]) / stats8[0.0]["coated"][0]
    bare_gain = max(stats8[25.0]["bare"][0], stats8[50.0]["bare"][0]) / stats8[0.0]["bare"][0]
    print(f"rough vs smooth: the coated sphere's saturation ×{coated_gain:.1f}, the bare sphere's ×{bare_gain:.1f}")
    assert coated_gain > 1.0  # the rough coated spheres are more saturated than the smooth one (the paper's observation)

# %% [markdown]
# **What the numbers say** (the run rendered in `07_rendering_coated_objects.md`): the rough
# coated spheres are about twice as saturated as the smooth coated sphere, as the paper
# observes — but the bare aluminium spheres gain nearly as much. In the He–Torrance model the
# split between the specular and the diffuse light depends on σ0/λ (the coherent specular part
# falls as $e^{-g}$ with $g \propto (\sigma_0\cos\theta/\lambda)^2$), so roughness alone
# sends more blue into the diffuse lobe and keeps more red in the specular one: it colours even
# bare aluminium. The coating's own contribution, the excess of the coated sphere over the bare
# one, stays at 0.01–0.02 in $s_{uv}$ at every roughness, at the level of the Monte-Carlo colour
# noise of these small renders. So the measurement supports the observation (rough coated
# objects look more colourful), and attributes most of it to the wavelength dependence of the
# roughness rather than to a dimming of the specular light that would "emphasize" the film's
# iridescence; a larger render (more samples, or a lamp without mercury lines) would be needed
# to resolve the coating's excess further.
#
# ## 3 · Fig. 9: teapot (Al), cylinder (Si), sphere (Cu), smooth and rough
#
# The coatings of Table 1 (teapot: A/Ag/A on Al; cylinder: B/A/B/A on Si; sphere: A/Au/A on
# Cu). The teapot is generated in code (`teapot_mesh`: a surface of revolution with a swept
# spout and handle), so no mesh file needs a licence.

# %%
SIZE9, SPP9 = (176, 112), 8
if HAVE_MITSUBA:
    t0 = time.perf_counter()
    renders9 = {}
    for s in (0.0, 25.0):
        scene = fig9_scene(coated_bsdf(tables[("Al + A/Ag/A", s)]), coated_bsdf(tables[("Si + B/A/B/A", s)]),
                           coated_bsdf(tables[("Cu + A/Au/A", s)]), width=SIZE9[0], height=SIZE9[1], spp=SPP9)
        renders9[s] = np.array(mi.render(mi.load_dict(scene), seed=0))
    print(f"Fig. 9: 2 renders of {SIZE9[0]}×{SIZE9[1]} px at {SPP9} spp in {time.perf_counter() - t0:.0f} s")
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    for ax, (s, img) in zip(axes, renders9.items()):
        ax.imshow(to_srgb(img))
        ax.set_title("(a) smooth" if s == 0 else f"(b) rough, σ0 = {s:.0f} nm, τ = 300 nm", fontsize=9)
        ax.axis("off")
    save(fig, "07_fig9_objects")
    every = np.ones(renders9[0.0].shape[:2], bool)
    sat0, sat1 = (block_saturation(renders9[s], every)[0] for s in (0.0, 25.0))
    print(f"mean s_uv of 8×8 tiles over the whole image: smooth {sat0.mean():.3f}, rough {sat1.mean():.3f}")

# %%
print(f"notebook 7: done in {time.perf_counter() - T_START:.0f} s")
