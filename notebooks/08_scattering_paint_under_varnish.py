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
# # 8 · Scattering paint under varnish: drawdowns, pigment maps, virtual varnish removal
#
# Notebooks 1 and 4 put the varnish over a Lambertian paint of given reflectance ρg(λ). A
# conservator has no measurement of the bare paint under an old varnish; what she has is a
# hyperspectral image of the varnished picture. Here the paint is a Kubelka–Munk body
# (`ls.KubelkaMunk`: absorption K(λ) and scattering S(λ) per nm, Kubelka 1948) of pigments mixed
# by Duncan's rule (K = Σ cᵢKᵢ, S = Σ cᵢSᵢ), under its binder interface (index 1.5) and a varnish
# with its own index and absorption — the exact machinery of the Simonot model above the body
# (docs/physics.md, "Scattering bodies"). Three steps:
#
# 1. **drawdown calibration** — a pigment's K(λ), S(λ) from drawdowns of its masstone and of its
#    tints with white over a black and a white ground (`fitting.drawdown_calibration`), with
#    standard errors;
# 2. **pigment maps** — a 24 × 24-pixel cube of a varnished painting fitted pixel by pixel
#    (`fitting.fit_cube`) into maps of two pigment concentrations and the varnish thickness;
# 3. **virtual varnish removal** — each pixel's fitted paint predicted without its varnish
#    (`fitting.varnish_removal`), as spectra and as an sRGB image.
#
# **Everything here is SYNTHETIC**: the pigments' K and S are chosen curves (a white, a red and a
# blue with plausible shapes and magnitudes), not measured data, and every "measurement" is
# computed from chosen true values plus Gaussian noise of known σ. That is what lets each
# `assert` compare a fitted value with the truth in units of the uncertainty the fit states.
#
# Units: nm for wavelengths and thicknesses, 1/nm for K, S and α, degrees in geometries.

# %%
import time

import jax

jax.config.update("jax_enable_x64", True)  # user code chooses the precision, never the library

import matplotlib.pyplot as plt
import numpy as np

import fitting
import layerstack_jax as ls

from _figures import save  # figures: notebooks/figures/ (tests: NOTEBOOK_FIGURES)

wl = np.arange(380.0, 781.0, 10.0)  # nm: 41 wavelengths over the visible
N_BINDER = 1.5
SIGMA = 0.002  # noise of one reading (reflectance-factor units), known


def band(mu, width):
    return np.exp(-0.5 * ((wl - mu) / width) ** 2)


# three SYNTHETIC pigments: K and S in 1/nm (1/µm × 1e-3)
white = ls.Paint(2e-6 + 4e-5 * band(380.0, 15.0), 3e-3 * (550.0 / wl), name="white")  # TiO2-like: absorbs in the UV edge
red = ls.Paint(4e-4 * (band(470.0, 45.0) + 0.8 * band(530.0, 35.0)) + 2e-6, 2e-4 * (550.0 / wl), name="red")
blue = ls.Paint(3e-4 * band(610.0, 55.0) + 2e-5 * band(420.0, 30.0) + 2e-6, 1.5e-4 * (550.0 / wl), name="blue")
pigments = [white, red, blue]
print(f"{wl.size} wavelengths; K/S of the white at 550 nm: {float(np.interp(550, wl, white.absorption / white.scattering)):.4f}")

# %% [markdown]
# ## 1 · Drawdown calibration of the red
#
# The red is drawn down at a known dry thickness (15 µm) over a black and a white card, and a
# sphere (8°, specular included) reads each drawdown; the ground reflectances under the paint are
# known. Each drawdown is a `KubelkaMunk` body under its binder interface, so the surface
# reflection and the internal reflection at the binder–air interface (Saunderson's k₁, k₂) are the
# library's exact ones rather than the customary constants.
#
# A strong absorber drawn down alone (masstone) is nearly black in its absorption band: there the
# readings are little more than the surface reflection, and the fit says that K and S are not
# determined (huge standard errors). Paint makers therefore also draw down *tints*, the pigment
# mixed with a white of known K, S (here 10 % red, 90 % white, by Duncan's rule), which stay
# bright enough to read (with 90 % white they hide their ground: they read the same over black
# and over white). The white's own K, S come from its masstone drawdowns the same way.

# %%
sphere = ls.Sphere(8.0, "included")
black = 0.03 + 0.01 * (wl - 380.0) / 400.0
whitecard = 0.86 - 0.04 * ((wl - 580.0) / 200.0) ** 2
grounds = [black, whitecard, black, whitecard]
fractions = np.array([1.0, 1.0, 0.1, 0.1])  # masstone over black and white, then the 10 % tint
X = 15_000.0
rng = np.random.default_rng(1948)


def drawdown(f, ground):
    return ls.Stack(1.0, [], ls.KubelkaMunk(N_BINDER, ls.Mixture(np.array([f, 1.0 - f]), [red, white]), X, ground))


clean = np.stack([np.asarray(ls.reflectance(drawdown(f, g), wl, sphere)) for f, g in zip(fractions, grounds)])
readings = clean + SIGMA * rng.standard_normal(clean.shape)
masstone = fitting.fit(fitting.drawdown_calibration(wl, sphere, readings[:2], grounds[:2], X, sigma=SIGMA))
t0 = time.perf_counter()
calibration = fitting.fit(fitting.drawdown_calibration(wl, sphere, readings, grounds, X, white=white,
                                                       fractions=fractions, sigma=SIGMA))
print(f"masstone only: relative σ of K from {np.nanmin(masstone.stderr['K'] / red.absorption):.2g} to "
      f"{np.nanmax(masstone.stderr['K'] / red.absorption):.2g} (in the absorption band: not determined)")
print(f"masstone + tints: {time.perf_counter() - t0:.1f} s, {calibration.reason}, "
      f"reduced chi2 {calibration.reduced_chi2:.2f} (nu = {calibration.dof}); relative σ of K "
      f"{np.min(calibration.stderr['K'] / red.absorption):.3f}–{np.max(calibration.stderr['K'] / red.absorption):.3f}")
K_fit, S_fit = calibration.values["K"], calibration.values["S"]
K_err, S_err = calibration.stderr["K"], calibration.stderr["S"]
within = np.concatenate([np.abs(K_fit - red.absorption) <= 2 * K_err, np.abs(S_fit - red.scattering) <= 2 * S_err])
print(f"truth within ±2σ at {100 * within.mean():.0f} % of the {within.size} values of K and S")
assert calibration.converged and 0.6 < calibration.reduced_chi2 < 1.5
assert within.mean() >= 0.85 and np.max(calibration.stderr["K"] / red.absorption) < 0.2
assert np.nanmax(masstone.stderr["K"] / red.absorption) > 1.0 or not masstone.identifiable

fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
for r, f, g, c in zip(readings, fractions, grounds, ("k", "0.55", "C3", "salmon")):
    axes[0].plot(wl, r, ".", color=c, ms=4,
                 label=f"{'masstone' if f == 1 else f'{100 * f:.0f} % tint'} over {'black' if g is black else 'white'}")
axes[0].set(xlabel="wavelength (nm)", ylabel="sphere reading (SCI)", title="drawdowns of the red (synthetic)")
axes[0].legend(fontsize=8)
for ax, fit_, err, true, name in ((axes[1], K_fit, K_err, red.absorption, "K"), (axes[2], S_fit, S_err, red.scattering, "S")):
    ax.fill_between(wl, 1e3 * (fit_ - 2 * err), 1e3 * (fit_ + 2 * err), color="C1", alpha=0.3, label="fit ± 2σ")
    ax.plot(wl, 1e3 * true, "k-", lw=1, label="truth")
    ax.plot(wl, 1e3 * fit_, "C1.", ms=4, label="fit")
    ax.set(xlabel="wavelength (nm)", ylabel=f"{name} (1/µm)", title=f"{name}(λ) of the red, masstone + tints")
    ax.legend(fontsize=8)
fig.tight_layout()
save(fig, "08_drawdown_calibration")

# %% [markdown]
# ## 2 · A varnished painting, fitted into pigment maps
#
# A 24 × 24-pixel panel: the white everywhere at concentration 0.6, the red and the blue varying
# across it (a red field, a blue field and a purple band where they mix), all opaque, under a
# yellowed varnish whose thickness grows from 10 to 40 µm across the panel; α(λ) of the varnish
# (rising towards the blue, as an aged natural resin) is taken as known — from a calibration
# series as in notebook 4. A 45°/0° camera reads 41 bands with noise σ = 0.002.
#
# An opaque body fixes only the *ratios* of its concentrations (scaling all of them leaves K/S
# unchanged), so the white is held at its value and the red, the blue and the varnish thickness
# are fitted in every pixel: `fit_cube` writes their maps and standard errors to a zarr store,
# region by region (resumable, see notebook 4 and `examples/cube`).

# %%
camera = ls.Directional(45.0, 0.0)
alpha_varnish = 4e-6 * (420.0 / wl) ** 4 + 5e-7  # 1/nm
NY = NX = 24
yy, xx = np.mgrid[0:NY, 0:NX] / (NY - 1)
c_red = 0.05 + 0.35 * np.clip(1.6 - 2.2 * xx, 0, 1)
c_blue = 0.05 + 0.35 * np.clip(2.2 * xx - 0.6, 0, 1)
h_true = 10_000.0 + 30_000.0 * yy
C_true = np.stack([np.full((NY, NX), 0.6), c_red, c_blue], axis=-1)


def painting(c, h):
    return ls.Stack(1.0, [ls.Layer(1.52, h, coherent=False, alpha=alpha_varnish, name="varnish")],
                    ls.KubelkaMunk(N_BINDER, ls.Mixture(c, pigments)))


cube = np.asarray(ls.predict(painting(C_true, h_true[..., None]), wl, camera))
cube = cube + SIGMA * rng.standard_normal(cube.shape)
objective = fitting.Objective(
    painting(np.array([0.6, 0.2, 0.2]), 25_000.0), wl, fitting.Dataset(camera, cube[0, 0], sigma=SIGMA),
    [fitting.Parameter(("exit", "paint", "concentrations"), kind="thickness", name="c",
                       fixed=np.array([True, False, False]), lower=0.0, upper=1.0),
     fitting.thickness("varnish", value=25_000.0, lower=1_000.0, upper=100_000.0)])
import tempfile  # noqa: E402

store = tempfile.mkdtemp() + "/painting_maps.zarr"
t0 = time.perf_counter()
maps = fitting.fit_cube(objective, cube, wavelength_nm=wl, out=store, progress=False).load()
print(f"fit_cube: {NY * NX} pixels in {time.perf_counter() - t0:.1f} s; status counts "
      f"{ {int(k): int(v) for k, v in zip(*np.unique(maps['status'].values, return_counts=True))} }")
z = {name: (maps[name].values - truth) / maps[f"{name}_stderr"].values
     for name, truth in (("c_1", c_red), ("c_2", c_blue), ("thickness_varnish", h_true))}
for name, zz in z.items():
    print(f"{name:18s} (fit - truth)/σ: mean {zz.mean():+.2f}, sd {zz.std():.2f}, |z| <= 3 at {100 * np.mean(np.abs(zz) <= 3):.1f} %")
assert np.all(maps["status"].values == 0)
assert all(np.mean(np.abs(zz) <= 3) >= 0.97 and 0.7 < zz.std() < 1.4 for zz in z.values())

fig, axes = plt.subplots(2, 3, figsize=(12, 7.2))
for col, (name, truth, label, scale) in enumerate((("c_1", c_red, "red concentration", 1.0),
                                                   ("c_2", c_blue, "blue concentration", 1.0),
                                                   ("thickness_varnish", h_true, "varnish thickness (µm)", 1e-3))):
    lo, hi = scale * truth.min(), scale * truth.max()
    for row, (img, what) in enumerate(((scale * truth, "truth"), (scale * maps[name].values, "fitted"))):
        im = axes[row, col].imshow(img, vmin=lo, vmax=hi, cmap="viridis")
        axes[row, col].set_title(f"{label}: {what}", fontsize=9)
        axes[row, col].axis("off")
        fig.colorbar(im, ax=axes[row, col], fraction=0.046)
fig.tight_layout()
save(fig, "08_pigment_maps")

# %% [markdown]
# ## 3 · Virtual varnish removal
#
# With the body and the varnish fitted together, the painting without its varnish is a
# prediction: each pixel's fitted body read through its own air–binder interface. Beside it, the
# truth (the bare bodies the cube was made from) and the varnished picture as the camera saw it;
# the colour difference between the predicted and the true bare paint (CIEDE2000, D65) says how
# well the fit sees under the varnish.

# %%
colours = ls.ColourSpace(wl)
removal = fitting.varnish_removal(objective, fitting.cube_parameters(objective, maps), layer="varnish",
                                  colour_space=colours)
bare_true = np.asarray(ls.predict(ls.Stack(1.0, [], ls.KubelkaMunk(N_BINDER, ls.Mixture(C_true, pigments))), wl, camera))
lab = lambda r: np.asarray(colours.Lab(r))  # noqa: E731
dE = np.asarray(ls.delta_e_2000(lab(removal.removed), lab(bare_true)))
dE_varnish = np.asarray(ls.delta_e_2000(lab(cube), lab(bare_true)))
print(f"ΔE2000, predicted bare vs true bare: median {np.median(dE):.2f}, 95th percentile {np.percentile(dE, 95):.2f}; "
      f"varnished vs true bare: median {np.median(dE_varnish):.1f}")
assert np.median(dE) < 0.5 and np.median(dE_varnish) > 5.0

fig, axes = plt.subplots(1, 4, figsize=(13, 3.6))
srgb = lambda r: np.asarray(colours.sRGB(r, clip=True))  # noqa: E731
for ax, img, title in ((axes[0], srgb(cube), "varnished (camera)"), (axes[1], removal.srgb_removed, "varnish removed (fit)"),
                       (axes[2], srgb(bare_true), "bare paint (truth)")):
    ax.imshow(img)
    ax.set_title(title, fontsize=9)
    ax.axis("off")
im = axes[3].imshow(dE, cmap="magma", vmin=0)
axes[3].set_title("ΔE2000, removed vs truth", fontsize=9)
axes[3].axis("off")
fig.colorbar(im, ax=axes[3], fraction=0.046)
fig.tight_layout()
save(fig, "08_varnish_removal")
print("notebook 8: all checks passed")
