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
# # 3 · Iridescent multilayer films on metals and silicon
#
# *H. Hirayama, K. Kaneda, H. Yamashita and Y. Monden, "An accurate illumination model for
# objects coated with multilayer films" (Eurographics 2000 short presentations).*
#
# Hirayama et al. render objects coated with stacks of thin films — dielectrics, a few nm of
# silver or gold — on aluminium, copper and silicon. Every film is thin enough for the light
# reflected at its two faces to interfere, so the reflectance is computed from amplitudes with
# their phases (their eqs. 1–6: the Rouard recursion from the substrate back to the air,
# complex indices allowed), per polarization, averaged over s and p at the end (eq. 5). The
# reflectance then depends strongly on wavelength *and* angle: the coated objects are
# **iridescent**, their colour changes from the centre of a sphere to its rim.
#
# This notebook takes the three coatings of their Table 1, with measured optical constants
# of the metals and of silicon from the refractiveindex.info database (`ls.material`), and
#
# 1. computes their reflectance against wavelength and angle (natural light, and s and p),
# 2. checks it against the independent transfer-matrix code `tmm` (Byrnes), energy
#    conservation included,
# 3. turns the spectra into colours (CIE 1931 2°, D65; `ls.ColourSpace`), checked against
#    colour-science, and shows them as swatches against the viewing angle,
# 4. renders a shaded sphere of each, coated and bare, as in their Figs. 8–9.
#
# Every key number is `assert`ed, so this file is also a test (`tests/test_notebooks.py`).
#
# **Units and conventions.** Wavelengths and thicknesses in nm, angles in radians in
# `ls.specular` (degrees in the text); index n + ik with k ≥ 0. `R` and `T` are power
# reflectance and transmittance; `T` is the power that enters the substrate (absorbed there,
# for a metal or silicon). Natural light is the mean of s and p.

# %%

import jax

jax.config.update("jax_enable_x64", True)  # user code chooses the precision, never the library

import colour
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
import tmm

import layerstack_jax as ls

from _figures import save  # figures: notebooks/figures/ (tests: NOTEBOOK_FIGURES)


# 2 nm steps: the thickest coating (6.8 µm of optical path) has fringes ~20 nm apart at 550 nm
wl = np.arange(380.0, 781.0, 2.0)
print(f"{wl.size} wavelengths, {wl[0]:.0f}–{wl[-1]:.0f} nm; refractiveindex.info database {ls.database_version()}")

# %% [markdown]
# ## The coatings of Table 1, with measured optical constants
#
# | object | medium A | layers (thickness) | medium B |
# | --- | --- | --- | --- |
# | teapot | air | dielectric A (1000 nm) · silver (5 nm) · dielectric A (1000 nm) | aluminium |
# | cylinder | air | B (1000 nm) · A (1000 nm) · B (1000 nm) · A (1000 nm) | silicon |
# | sphere | air | dielectric A (1000 nm) · gold (5 nm) · dielectric A (1000 nm) | copper |
#
# Dielectric A has n = 1.4, B has n = 2.0 (the paper's values, without dispersion). The paper
# does not say where its metal constants come from; we take classic measurements from the
# database: Ag, Au and Cu from Johnson & Christy (1972), Al from Rakić (1995), Si from Aspnes &
# Studna (1983). A 5 nm metal film is described by bulk constants here, as in the paper (real
# films that thin are often islands, with other constants).
#
# Each material is evaluated once on the wavelength grid, and given to the stacks as an array
# (`ls.Index(n, k)` on the grid): then the six stacks below — the three coatings and the three
# bare substrates (the same layers with zero thickness, which are invisible) — have the same
# structure, and one compiled function computes all of them at once (`jax.vmap` over the
# stacks). The teapot and sphere coatings get a fourth, empty layer for that purpose.

# %%
def on_grid(book, source):
    """A database material evaluated on the grid, as an ls.Index of arrays (n, k)."""
    n = np.asarray(ls.material(book, source)(wl))
    return ls.Index(n.real, n.imag)


def constant(n):
    return ls.Index(np.full(wl.size, n), np.zeros(wl.size))


silver, gold = on_grid("Ag", "Johnson"), on_grid("Au", "Johnson")
aluminium, copper, silicon = on_grid("Al", "Rakic"), on_grid("Cu", "Johnson"), on_grid("Si", "Aspnes")
A, B = constant(1.4), constant(2.0)
coatings = {
    "teapot: A / Ag 5 nm / A on Al": ([(A, 1000.0), (silver, 5.0), (A, 1000.0), (A, 0.0)], aluminium),
    "cylinder: B / A / B / A on Si": ([(B, 1000.0), (A, 1000.0), (B, 1000.0), (A, 1000.0)], silicon),
    "sphere: A / Au 5 nm / A on Cu": ([(A, 1000.0), (gold, 5.0), (A, 1000.0), (A, 0.0)], copper),
}
bare_names = ["bare Al", "bare Si", "bare Cu"]


def make_stack(layers, substrate, bare=False):
    films = [ls.Layer(index, 0.0 if bare else d) for index, d in layers]  # coherent films
    return ls.Stack(constant(1.0), films, ls.Substrate(substrate))


stacks = [make_stack(*c) for c in coatings.values()] + [make_stack(*c, bare=True) for c in coatings.values()]
names = list(coatings) + bare_names
# one Stack whose array leaves have a leading axis of 6
batch = jax.tree.map(lambda *leaves: np.stack([np.asarray(x) for x in leaves]), *stacks)
assert jax.tree.structure(batch) == jax.tree.structure(stacks[0])

# %% [markdown]
# ## 1 · Reflectance against wavelength and angle
#
# One call of `ls.specular` per stack, vmapped over the six stacks, on a table of 360 angles
# (0° to 89.75° by 0.25°) × 201 wavelengths × 2 polarizations. This is also how Hirayama et al.
# render (their §5): reflectances pre-computed per sampled angle and wavelength, interpolated
# at each ray.

# %%
theta_deg = np.arange(0.0, 90.0, 0.25)
theta = np.radians(theta_deg)


@jax.jit
def reflect(batch, angle_rad):
    """R and T (into the substrate) of every stack, shaped (stack, angle, 2 (s, p), wl)."""
    response = jax.vmap(lambda stack: ls.specular(stack, wl, angle_rad=angle_rad, both_sides=False))(batch)
    return response.R_front, response.T_front


R_sp, T_sp = (np.asarray(x) for x in reflect(batch, theta))
R = R_sp.mean(axis=-2)  # natural light, (stack, angle, wl)
print(f"R, T: {R_sp.shape} (stack, angle, polarization, wavelength)")
for name, r in zip(names, R):
    print(f"  {name:32s} R(0°) = {r[0].min():.3f} … {r[0].max():.3f}   R(60°) = {r[240].min():.3f} … {r[240].max():.3f}")

fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
for k, ax in enumerate(axes):
    for a in (0.0, 30.0, 60.0, 75.0):
        ax.plot(wl, R[k, theta_deg == a][0], lw=1.2, label=f"{a:.0f}°")
    ax.plot(wl, R[k + 3, 0], "k--", lw=1, label=f"{bare_names[k]}, 0°")
    ax.plot(wl, R_sp[k, theta_deg == 60.0][0, 0], ":", color="C2", lw=1, label="60°, s")
    ax.plot(wl, R_sp[k, theta_deg == 60.0][0, 1], "-.", color="C2", lw=1, label="60°, p")
    ax.set(title=names[k], xlabel="wavelength (nm)", ylim=(0, 1))
axes[0].set_ylabel("reflectance (natural light unless s/p)")
axes[2].legend(fontsize=7, ncol=2, loc="lower right")
save(fig, "03_reflectance_spectra")

fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), sharey=True)
for k, ax in enumerate(axes):
    im = ax.imshow(R[k].T, origin="lower", aspect="auto", extent=(0, 90, wl[0], wl[-1]), vmin=0, vmax=1, cmap="magma")
    ax.set(title=names[k], xlabel="angle of incidence (degrees)")
axes[0].set_ylabel("wavelength (nm)")
fig.colorbar(im, ax=axes, label="reflectance (natural light)", shrink=0.9)
save(fig, "03_reflectance_maps")

# %% [markdown]
# The dielectric layers are 1 µm thick. On the teapot and sphere coatings the 5 nm metal film is
# a partial mirror over 1 µm of dielectric A and a thick metal: a weak Fabry–Perot cavity, whose
# absorption dips are ~110 nm apart near 550 nm ($\lambda^2/(2 n_A d)$ for one A layer); the
# four-layer coating on silicon, 6.8 µm of optical path in all, has fringes ~20–30 nm apart. All
# move to shorter wavelengths as the angle grows — the phase $4\pi n d\cos\theta_j/\lambda$ falls
# with $\cos\theta_j$ — which is the iridescence. At 60° the coatings reflect s light more than p
# at most wavelengths (69–91 % of the grid), the bare substrates at all of them.
#
# ## 2 · Check against `tmm`, and energy conservation
#
# `tmm.coh_tmm` (S. J. Byrnes) computes the same quantities with transfer matrices, an
# independent code. We compare R and T for s and p at four angles and three wavelengths for each
# coating. Energy: `tmm.absorp_in_each_layer` gives, from the Poynting vector at each interface,
# the fraction of the power absorbed in each film; R + T + (absorption in the films) must be 1.
# For the lossless cylinder coating there is no film absorption, so the library's own
# R + T must be 1 at every angle and wavelength.

# %%
check_angles = (0.0, 30.0, 60.0, 80.0)
check_wl = (400.0, 550.0, 700.0)
err_tmm = err_energy = 0.0
for k, (layers, substrate) in enumerate(coatings.values()):
    for lam in check_wl:
        j = int(np.flatnonzero(wl == lam)[0])
        n_list = [1.0] + [complex(np.asarray(index.n)[j], np.asarray(index.k)[j]) for index, _ in layers]
        n_list.append(complex(np.asarray(substrate.n)[j], np.asarray(substrate.k)[j]))
        d_list = [np.inf] + [d for _, d in layers] + [np.inf]
        for a in check_angles:
            i = int(np.flatnonzero(theta_deg == a)[0])
            for p, pol in enumerate("sp"):
                ref = tmm.coh_tmm(pol, n_list, d_list, np.radians(a), lam)
                err_tmm = max(err_tmm, abs(ref["R"] - R_sp[k, i, p, j]), abs(ref["T"] - T_sp[k, i, p, j]))
                absorbed = tmm.absorp_in_each_layer(ref)[1:-1].sum()  # in the films
                err_energy = max(err_energy, abs(R_sp[k, i, p, j] + T_sp[k, i, p, j] + absorbed - 1.0))
lossless = np.abs(R_sp[1] + T_sp[1] - 1.0).max()
print(f"library vs tmm (R and T, s and p, 3 coatings × 4 angles × 3 wavelengths): max |Δ| = {err_tmm:.1e}")
print(f"R + T + film absorption (tmm) − 1: {err_energy:.1e};  lossless cylinder coating, R + T − 1: {lossless:.1e}")
assert err_tmm <= 1e-10 and err_energy <= 1e-10 and lossless <= 1e-12
film_absorption = 1 - R_sp[0, 0].mean(0) - T_sp[0, 0].mean(0)
print(f"the 5 nm silver film of the teapot absorbs {film_absorption.min():.2%} … {film_absorption.max():.2%} at normal incidence")

# %% [markdown]
# ## 3 · Colour, and the swatches against the viewing angle
#
# `ls.ColourSpace(wl)` integrates a spectrum against the CIE 1931 2° colour-matching functions
# and the D65 illuminant on our grid (CIE 15 §7.1; colour-science's tables and its "Integration"
# method), then converts to CIELAB and sRGB. The reflectance of a smooth surface, seen in the
# mirror direction of a white D65 source, has that colour. First the check against
# colour-science's own functions on one spectrum, then swatches every 10°.

# %%
cs = ls.ColourSpace(wl)  # CIE 1931 2°, D65
# compiled once (eager JAX dispatches op by op); spectra (..., wl) -> XYZ, L*a*b*, sRGB (..., 3)
colour_of = jax.jit(lambda spectra: (cs.XYZ(spectra), cs.Lab(spectra), cs.sRGB(spectra)))
delta_e_2000 = jax.jit(ls.delta_e_2000)

XYZ_all, lab_all, rgb_all = (np.asarray(x) for x in colour_of(R))  # every stack and angle: (stack, angle, 3)
XYZ, Lab, sRGB = XYZ_all[2, 0], lab_all[2, 0], rgb_all[2, 0]  # the gold/copper sphere coating at normal incidence
spectrum = R[2, 0]
shape = colour.SpectralShape(wl[0], wl[-1], wl[1] - wl[0])
XYZ_cs = colour.sd_to_XYZ(colour.SpectralDistribution(spectrum, wl), colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"],
                          colour.SDS_ILLUMINANTS["D65"], method="Integration", shape=shape)
white_xy = colour.XYZ_to_xy(np.asarray(cs.white_XYZ) / 100)
Lab_cs = colour.XYZ_to_Lab(XYZ_cs / 100, white_xy)
sRGB_cs = colour.XYZ_to_sRGB(XYZ_cs / 100, white_xy)
err_colour = max(np.abs(XYZ - XYZ_cs).max(), np.abs(Lab - Lab_cs).max(), np.abs(sRGB - sRGB_cs).max())
print(f"XYZ = {np.round(XYZ, 3)}, L*a*b* = {np.round(Lab, 2)}; vs colour-science: max |Δ| = {err_colour:.1e}")
assert err_colour <= 1e-10

swatch_deg = np.arange(0.0, 81.0, 10.0)
at = np.searchsorted(theta_deg, swatch_deg)
rgb_swatch = np.clip(rgb_all[:, at], 0.0, 1.0)  # out-of-gamut colours clipped (= clipping the linear values)
de00 = np.asarray(delta_e_2000(lab_all[:, :1], lab_all))[:, at]  # ΔE00 from the 0° colour
for name, row in zip(names, de00):
    print(f"  {name:32s} ΔE00 from 0° at 10°, 20°, …, 80°: {' '.join(f'{v:4.1f}' for v in row[1:])}")
# the coatings are iridescent, the bare metals are not
# the coatings are iridescent, the bare substrates are not: the largest ΔE00 from the 0° colour
# up to 60° (beyond, the bare metals change too, as their reflectance rises towards grazing incidence)
change = de00[:, swatch_deg <= 60].max(axis=1)
assert np.all(change[:3] > 5) and np.all(change[3:] < 1)

fig, ax = plt.subplots(figsize=(9, 3.8))
ax.imshow(rgb_swatch, aspect="auto", extent=(-5, 85, len(names) - 0.5, -0.5))
ax.set(xticks=swatch_deg, yticks=range(len(names)), yticklabels=names, xlabel="viewing angle = angle of incidence (degrees)",
       title="Colour of the specular reflection under D65 (sRGB, CIE 1931 2°)")
for k in range(len(names)):
    for c, a in enumerate(swatch_deg):
        L = lab_all[k, at[c], 0]
        ax.text(a, k, f"{L:.0f}", ha="center", va="center", fontsize=7, color="white" if L < 50 else "black")
save(fig, "03_swatches")
print("(numbers on the swatches: L*)")

# %% [markdown]
# ## 4 · Shaded spheres
#
# A smooth sphere seen from far away, in a uniformly white D65 surround (a light box, an
# overcast sky all around): the pixel at distance ρ from the centre of the disc (radius 1) sees
# the surround mirrored by a surface whose normal makes the angle $\theta = \arcsin\rho$ with
# the line of sight, so its colour is that of the specular reflectance $R(\theta)$. As in the
# paper (§5), each pixel's colour is interpolated in the 0.25° table of section 1 — linearly
# in XYZ, which is linear in R, i.e. the colour of the interpolated spectrum. The whole image is
# a few array operations on all pixels and stacks at once; below we check the interpolation
# against a direct computation of `ls.specular` at the exact angles of 360 pixels.

# %%
size = 160
y, x = (np.mgrid[0:size, 0:size] + 0.5) / size * 2 - 1  # pixel centres in [-1, 1]
rho = np.hypot(x, y)
disc = rho < 1
pixel_theta = np.arcsin(np.minimum(rho, 1.0))  # (size, size), radians



def interpolate_xyz(table, angle):
    """XYZ at each pixel angle (any shape), linear in the 0.25° angle table, for one stack."""
    return jnp.stack([jnp.interp(angle, theta, table[:, c]) for c in range(3)], axis=-1)


@jax.jit
def render_spheres(XYZ_table, angle):
    """Per pixel of every stack: XYZ, L*a*b* and (clipped) sRGB, shaped (stack, *angle.shape, 3)."""
    xyz = jax.vmap(interpolate_xyz, in_axes=(0, None))(XYZ_table, angle)
    return xyz, ls.xyz_to_lab(xyz, cs.white_XYZ), cs.XYZ_to_sRGB(xyz, clip=True)


pixel_XYZ, pixel_lab, image = (np.array(x) for x in render_spheres(XYZ_all, pixel_theta))  # (stack, size, size, 3)
image[:, ~disc] = 0.0  # black background

# the interpolation checked at 360 pixels computed exactly, in the same compiled function as section 1
rng = np.random.default_rng(0)
sample = rng.choice(np.flatnonzero(disc & (rho < 0.999)), size=theta.size, replace=False)
R_direct = np.asarray(reflect(batch, pixel_theta.ravel()[sample])[0]).mean(axis=-2)  # (stack, 360, wl)
lab_direct = colour_of(R_direct)[1]
lab_interp = pixel_lab.reshape(len(names), -1, 3)[:, sample]
de_interp = float(jnp.max(delta_e_2000(lab_direct, lab_interp)))
print(f"sphere pixels, interpolated in the 0.25° table vs computed at their own angle: max ΔE00 = {de_interp:.3f}")
assert de_interp < 0.5  # below what the eye can tell

fig, axes = plt.subplots(2, 3, figsize=(10, 6.8))
for k, ax in enumerate(axes.ravel()):
    ax.imshow(image[k], extent=(-1, 1, -1, 1))
    ax.set_title(names[k], fontsize=9)
    ax.axis("off")
fig.suptitle("Smooth spheres in a white D65 surround: coated (top) and bare (bottom), cf. Hirayama et al. Figs. 8–9")
save(fig, "03_spheres")

# %% [markdown]
# **A cross-check of the metals' colours.** Renderers tabulate the colour of bare metals at
# normal incidence ("F0"); Adobe's *Substance 3D metal material references* list 8-bit sRGB
# (245, 246, 246) for aluminium and (255, 211, 192) for copper, from spectral data of their own.
# Our bare aluminium and copper at 0°, from the Rakić and Johnson & Christy constants, come out
# within a few units of those (the copper is a little darker, as the two data sets differ):

# %%
srgb_bare = np.round(255 * np.clip(rgb_all[[3, 5], 0], 0.0, 1.0))
print(f"bare Al at 0°: sRGB {srgb_bare[0]}  (Adobe: [245 246 246]);  bare Cu: {srgb_bare[1]}  (Adobe: [255 211 192])")
assert np.abs(srgb_bare - [[245, 246, 246], [255, 211, 192]]).max() <= 10

# %% [markdown]
# **Compared with the paper.** Hirayama et al. render these coatings on a teapot, a cylinder and
# a sphere (Fig. 9, Table 1) and the silver- and gold-coated spheres next to bare ones (Fig. 8),
# with a raytracer, the same Rouard recursion and a fluorescent lamp; the paper's text reports no
# colour values, only that iridescent colours appear on the coated objects, changing with the
# viewing direction, and that they show more clearly on rough surfaces than on smooth ones,
# whose strong specular reflection dilutes them. Our smooth spheres agree qualitatively: each
# coated sphere shows rings of colour from its centre to its rim (its colour moves by ΔE00 > 5
# between 0° and 60°, by 20 for the four-layer coating on silicon), while the bare spheres keep
# one colour (ΔE00 < 1 up to 60°) — aluminium nearly white, silicon grey, copper salmon — and
# change only near the rim, where the substrate's reflectance rises (ΔE00 up to 6 at 80°). The
# coatings' colours are pale, as the paper says of smooth surfaces: the metal underneath returns
# much of the light at every wavelength.

# %%
print("notebook 3: all checks passed")
