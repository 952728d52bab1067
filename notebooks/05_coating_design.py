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
# # 5 · Coating design: antireflection, needles, a colour, and the yield
#
# The same Rouard recursion that predicts a coating (Hirayama et al., notebook 3) is
# differentiable, so the thicknesses of a design can be optimised by gradient: `fitting` minimises
# a merit function — the mean squared, tolerance-scaled distance of the reflectance (or of its
# CIELAB colour) to a target — within thickness bounds with L-BFGS-B, gradients by automatic
# differentiation. This notebook
#
# 1. rediscovers the **quarter-wave antireflection layer** and checks it against its closed form;
# 2. grows a **broadband antireflection coating** (450–650 nm) from two real materials by the
#    **needle method** (Tikhonravov, Trubetskov & DeBell, Appl. Opt. 35 (1996) 5493);
# 3. designs a **dielectric / metal / dielectric** stack on aluminium to a given **CIELAB colour**;
# 4. estimates the **yield** of the antireflection design under random thickness errors.
#
# Every design is checked with code that is not the library: the closed forms of thin-film optics
# (Macleod, *Thin-Film Optical Filters*, ch. 2–4), Macleod's characteristic matrices written out in
# numpy below (cross-checked with Byrnes' `tmm`), and colour-science for the colours.
#
# Units: nm for wavelengths and thicknesses; normal incidence throughout.

# %%

import jax

jax.config.update("jax_enable_x64", True)  # user code chooses the precision, never the library

import colour
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
import tmm

import fitting
import layerstack_jax as ls

from _figures import save  # figures: notebooks/figures/ (tests: NOTEBOOK_FIGURES)


# SciPy's L-BFGS-B on the host (method="scipy") starts in a second: only the merit and its
# gradient are compiled. The default, jaxopt's L-BFGS-B (all starts in one vmapped solve), spends
# ~10 s compiling for every new design shape — worth it for many starts or on an accelerator.
SOLVER = {"method": "scipy"}

# %% [markdown]
# ## An independent reference: characteristic matrices
#
# At normal incidence a film of index $n$ (complex for a metal, $n + ik$) and thickness $d$ has the
# characteristic matrix $\begin{pmatrix}\cos\delta & i\sin\delta/N\\ i N\sin\delta & \cos\delta\end{pmatrix}$,
# $\delta = 2\pi N d/\lambda$, in Macleod's convention $N = n - ik$ (the library writes $n + ik$).
# Multiplying them from the top and applying the product to
# $(1, n_s)^\top$ gives $(B, C)$, and $R = |(n_0B - C)/(n_0B + C)|^2$ (Macleod, ch. 2).
# Vectorised over wavelengths and over many designs at once, it is the reference for every check
# below; first it is itself checked against `tmm.coh_tmm`.

# %%
def reflectance_cm(indices, thicknesses, n_substrate, wavelength_nm, n0=1.0):
    """Normal-incidence R of a stack, top layer first. indices: list of (..., wl) arrays (or
    scalars); thicknesses: list of arrays broadcasting against them (nm)."""
    B = np.ones(np.shape(wavelength_nm), complex)
    C = B * np.conj(n_substrate)  # Macleod writes N = n − ik; the library and tmm write n + ik
    for n, d in zip(reversed(indices), reversed(thicknesses)):
        n = np.conj(n)
        delta = 2 * np.pi * n * d / wavelength_nm
        B, C = np.cos(delta) * B + 1j * np.sin(delta) / n * C, 1j * n * np.sin(delta) * B + np.cos(delta) * C
    return np.abs((n0 * B - C) / (n0 * B + C)) ** 2


def reflectance_tmm(indices, thicknesses, n_substrate, wavelength_nm):
    """Same with tmm.coh_tmm, one wavelength at a time (indices as (wl,) arrays)."""
    return np.array([
        tmm.coh_tmm("s", [1.0, *[complex(np.broadcast_to(n, wavelength_nm.shape)[j]) for n in indices],
                          complex(np.broadcast_to(n_substrate, wavelength_nm.shape)[j])],
                    [np.inf, *thicknesses, np.inf], 0.0, lam)["R"]
        for j, lam in enumerate(wavelength_nm)
    ])


# the materials, from the refractiveindex.info database (ls.material), tabulated once on a 1 nm
# grid for the references (Devore's TiO2 data start at 430 nm)
materials = {"MgF2": ls.material("MgF2", "Li-o"), "SiO2": ls.material("SiO2", "Malitson"),
             "TiO2": ls.material("TiO2", "Devore-o"), "Ag": ls.material("Ag", "Johnson"), "Al": ls.material("Al", "Rakic")}
GRID = np.arange(380.0, 781.0, 1.0)
TABLES = {}
for name, material in materials.items():
    TABLES[name] = np.full(GRID.shape, np.nan + 0j)
    inside = GRID >= (430.0 if name == "TiO2" else 380.0)
    TABLES[name][inside] = np.asarray(material(GRID[inside]))


def n_of(name, wavelength_nm):
    """n + ik of a material at wavelengths on the 1 nm grid."""
    return TABLES[name][np.rint(np.asarray(wavelength_nm, float) - GRID[0]).astype(int)]


def design_indices(stack, wavelength_nm, names, substrate):
    """Indices (each layer's material found among `names` by its index at 550 nm), thicknesses
    (nm) and substrate index of a layerstack design, for the references."""
    indices = []
    for layer in stack.layers:
        n550 = complex(np.asarray(layer.index(np.array([550.0])))[0])
        indices.append(n_of(min(names, key=lambda name: abs(n_of(name, 550.0) - n550)), wavelength_nm))
    return indices, [float(layer.thickness) for layer in stack.layers], substrate


probe = np.array([400.0, 550.0, 700.0])
check = ([np.full(3, 1.46), n_of("Ag", probe), np.full(3, 2.3)], [120.0, 12.0, 80.0], n_of("Al", probe))
err_cm = np.abs(reflectance_cm(*check, probe) - reflectance_tmm(*check, probe)).max()
print(f"characteristic matrices vs tmm (dielectric / 12 nm Ag / dielectric on Al): {err_cm:.1e}")
assert err_cm < 1e-12

# %% [markdown]
# ## 1 · The quarter-wave antireflection layer
#
# One layer of MgF2 (Li 1980, from the refractiveindex.info database via `ls.material`) on glass
# ($n_s = 1.52$), reflectance minimised at $\lambda_0 = 550$ nm. Theory: the reflections at the two
# interfaces cancel best when they return half a wave apart, $d = \lambda_0/(4n_1)$, leaving
#
# $$R_\text{min} = \Big(\frac{n_0 n_s - n_1^2}{n_0 n_s + n_1^2}\Big)^2 \qquad\text{(Macleod, ch. 4)},$$
#
# zero only if $n_1 = \sqrt{n_0 n_s} = 1.233$; MgF2's 1.378 leaves 1.3 %, against 4.3 % for bare
# glass. The optimiser starts from 80 nm and knows none of this.

# %%
mgf2 = materials["MgF2"]
lam0, n_s = 550.0, 1.52
n1 = float(np.real(n_of("MgF2", lam0)))
single = ls.Stack(1.0, [ls.Layer(mgf2, 80.0, name="MgF2")], ls.Substrate(n_s))
at_lam0 = fitting.SpectralTarget(jnp.array([lam0]), 0.0, 0.01)  # R(550 nm) = 0, tolerance 1 %
qw = fitting.optimize_thicknesses(single, [at_lam0], bounds_nm=(0.0, 180.0), **SOLVER)
print(qw.message)

d_closed = lam0 / (4 * n1)
R_min_closed = ((1.0 * n_s - n1**2) / (1.0 * n_s + n1**2)) ** 2
d_opt = float(qw.thickness_nm[0])
R_opt = float(reflectance_cm([n1], [d_opt], n_s, np.array([lam0]))[0])
print(f"n1(550 nm) = {n1:.5f}: d = {d_opt:.4f} nm (λ0/4n1 = {d_closed:.4f}); "
      f"R = {R_opt:.6%} (closed form {R_min_closed:.6%})")
assert qw.converged
assert abs(d_opt - d_closed) < 0.05
assert abs(R_opt - R_min_closed) < 1e-9

wl_plot = np.arange(400.0, 701.0, 2.0)
n_mgf2 = np.real(n_of("MgF2", wl_plot))
fig, ax = plt.subplots(figsize=(7, 4))
ax.plot(wl_plot, 100 * reflectance_cm([], [], n_s, wl_plot), label="bare glass, n = 1.52")
ax.plot(wl_plot, 100 * reflectance_cm([n_mgf2], [d_opt], n_s, wl_plot), label=f"+ {d_opt:.1f} nm MgF2 (optimised)")
ax.axhline(100 * R_min_closed, color="gray", ls=":", lw=1, label="closed-form minimum")
ax.axvline(lam0, color="gray", lw=0.6)
ax.set(xlabel="wavelength (nm)", ylabel="reflectance (%)", ylim=(0, 5), title="Quarter-wave MgF2 antireflection layer")
ax.legend(fontsize=8)
save(fig, "05_quarter_wave")

# %% [markdown]
# ## 2 · A broadband antireflection coating by the needle method
#
# Target: R = 0 from 450 to 650 nm (21 wavelengths, tolerance 0.5 %), with SiO2 (Malitson) and
# TiO2 (Devore, ordinary ray) from the database, on the same glass. The start: two layers of
# 100 nm, refined. The needle method then computes, exactly by automatic differentiation, the
# derivative $P(z)$ of the merit with respect to the thickness of an infinitely thin layer of
# either material inserted at depth z — the *needle function* — inserts a needle where $P$ is most
# negative, and refines all thicknesses again.

# %%
sio2, tio2 = materials["SiO2"], materials["TiO2"]
AR = (("SiO2", "TiO2"), n_s)  # candidate materials and substrate of the AR designs, for design_indices
band = jnp.linspace(450.0, 650.0, 21)
no_reflection = fitting.SpectralTarget(band, 0.0, 0.005)
start = ls.Stack(1.0, [ls.Layer(sio2, 100.0, name="SiO2"), ls.Layer(tio2, 100.0, name="TiO2")], ls.Substrate(n_s))
two_layers = fitting.optimize_thicknesses(start, [no_reflection], bounds_nm=(0.0, 400.0), **SOLVER)
broadband, history = fitting.needle_design(start, [no_reflection], [sio2, tio2], iterations=1, max_layers=4,
                                           bounds_nm=(0.0, 400.0), points_per_layer=16, **SOLVER)
for step in history:
    print(f"{step['layers']} layers: merit {step['merit']:.4g}" + (
        f"   (after a needle of {['SiO2', 'TiO2'][step['needle'][0]]} inside layer {step['needle'][1]} (0 = top) "
        f"at {step['needle'][2]:.0%} of its depth, where dM/dt = {step['needle'][3]:.3g} /nm)" if step["needle"] else ""))

wl_fine = np.arange(450.0, 651.0, 1.0)
R_two = reflectance_cm(*design_indices(two_layers.stack, wl_fine, *AR), wl_fine)
R_ar = reflectance_cm(*design_indices(broadband.stack, wl_fine, *AR), wl_fine)
n_ar, d_ar, _ = design_indices(broadband.stack, np.array([550.0]), *AR)
print("design (top first): " + ", ".join(f"{'TiO2' if n.real > 2 else 'SiO2'} {d:.1f} nm" for n, d in zip(n_ar, d_ar)))
print(f"mean R over 450–650 nm (1 nm steps, characteristic matrices): 2 layers {R_two.mean():.3%}, "
      f"needle design {R_ar.mean():.3%} (max {R_ar.max():.3%})")
some = np.array([450.0, 512.0, 650.0])
assert np.abs(reflectance_cm(*design_indices(broadband.stack, some, *AR), some)
              - reflectance_tmm(*design_indices(broadband.stack, some, *AR), some)).max() < 1e-12
assert R_ar.mean() < 0.005
assert R_ar.mean() < 0.5 * R_two.mean()  # the needle helped

fig, (ax, axn) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [3, 2]})
wl_wide = np.arange(430.0, 701.0, 2.0)  # Devore's TiO2 data start at 430 nm
ax.plot(wl_wide, 100 * reflectance_cm([], [], n_s, wl_wide), color="gray", lw=1, label="bare glass")
ax.plot(wl_wide, 100 * reflectance_cm(*design_indices(two_layers.stack, wl_wide, *AR), wl_wide),
        label=f"before: 2 layers, refined (mean {R_two.mean():.2%})")
ax.plot(wl_wide, 100 * reflectance_cm(*design_indices(broadband.stack, wl_wide, *AR), wl_wide),
        label=f"after: {len(broadband.stack.layers)} layers, needle (mean {R_ar.mean():.2%})")
ax.axvspan(450, 650, color="C2", alpha=0.08)
ax.set(xlabel="wavelength (nm)", ylabel="reflectance (%)", ylim=(0, 8), title="Broadband AR, SiO2 / TiO2 on glass")
ax.legend(fontsize=8, loc="upper center")
depth, n_profile = [0.0], [n_s]
for n, d in zip(reversed(n_ar), reversed(d_ar)):  # from the substrate up
    n_profile.append(float(n[0].real))
    depth.append(depth[-1] + d)
depth.append(depth[-1] + 40.0)
n_profile.append(1.0)
axn.stairs(n_profile, np.concatenate([[-40.0], depth]), baseline=None, color="k")
axn.text(-20.0, n_s + 0.04, "glass", ha="center", fontsize=8)
axn.text(depth[-2] + 20.0, 1.04, "air", ha="center", fontsize=8)
axn.set(xlabel="height above the glass (nm)", ylabel="n at 550 nm", title="index profile of the needle design")
save(fig, "05_broadband_ar")

# %% [markdown]
# ## 3 · A colour target: dielectric / metal / dielectric on aluminium
#
# Hirayama et al.'s teapot coating is a thin silver film between two dielectric films on
# aluminium: interference colours over a mirror. Here SiO2 / Ag (Johnson & Christy) / SiO2 on Al
# (Rakić), all three thicknesses free, designed so that the specular reflectance at normal
# incidence, seen under D65 by the CIE 1931 observer, has the lilac CIELAB colour
# L* = 90, a* = 15, b* = −15, within ΔE2000 < 0.5 (`fitting.ColourTarget`), from the start below
# and fifteen random ones within the bounds.

# %%
wl_vis = np.arange(380.0, 781.0, 5.0)
target_lab = np.array([90.0, 15.0, -15.0])
lilac = fitting.ColourTarget(ls.ColourSpace(wl_vis), target_lab, 0.0, tolerance=0.5)
ag, al = materials["Ag"], materials["Al"]
dmd = ls.Stack(1.0, [ls.Layer(sio2, 150.0, name="SiO2"), ls.Layer(ag, 15.0, name="Ag"), ls.Layer(sio2, 150.0, name="SiO2")],
               ls.Substrate(al))
coloured = fitting.optimize_thicknesses(dmd, [lilac], bounds_nm=([30.0, 5.0, 30.0], [400.0, 40.0, 400.0]),
                                        n_starts=16, seed=1, **SOLVER)
print(coloured.message)
print("design: " + ", ".join(f"{layer.name} {float(layer.thickness):.1f} nm" for layer in coloured.stack.layers))


def lab_colour_science(R):
    """CIELAB (D65, CIE 1931 2°) of a reflectance spectrum on wl_vis, by colour-science."""
    d65 = colour.SDS_ILLUMINANTS["D65"]
    XYZ = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(wl_vis, R))), illuminant=d65, method="Integration")
    white = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(wl_vis, np.ones_like(wl_vis)))), illuminant=d65,
                             method="Integration")
    return colour.XYZ_to_Lab(XYZ / 100, colour.XYZ_to_xy(white / 100))


R_start = reflectance_cm(*design_indices(dmd, wl_vis, ("SiO2", "Ag"), n_of("Al", wl_vis)), wl_vis)
R_coloured = reflectance_cm(*design_indices(coloured.stack, wl_vis, ("SiO2", "Ag"), n_of("Al", wl_vis)), wl_vis)
lab_start, lab_coloured = lab_colour_science(R_start), lab_colour_science(R_coloured)
dE_start = float(colour.delta_E(lab_start, target_lab, method="CIE 2000"))
dE = float(colour.delta_E(lab_coloured, target_lab, method="CIE 2000"))
print(f"start  Lab = {np.round(lab_start, 2)}   ΔE2000 = {dE_start:.2f}")
print(f"design Lab = {np.round(lab_coloured, 2)}   ΔE2000 = {dE:.3f} (colour-science, characteristic matrices)")
assert dE < 0.5


def srgb(lab):
    return np.clip(colour.XYZ_to_sRGB(colour.Lab_to_XYZ(lab)), 0, 1)


fig, (ax, axs) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [3, 2]})
wl_1nm = GRID  # the spectra on a 1 nm grid for the plot (the colours use the 5 nm grid)
for stack, label in [(dmd, "start: 150 / 15 / 150 nm"),
                     (coloured.stack, "designed: " + " / ".join(f"{d:.0f}" for d in coloured.thickness_nm) + " nm")]:
    ax.plot(wl_1nm, reflectance_cm(*design_indices(stack, wl_1nm, ("SiO2", "Ag"), n_of("Al", wl_1nm)), wl_1nm), label=label)
ax.plot(wl_1nm, reflectance_cm([], [], n_of("Al", wl_1nm), wl_1nm), color="gray", lw=1, label="bare Al")
ax.set(xlabel="wavelength (nm)", ylabel="reflectance", ylim=(0, 1), title="SiO2 / Ag / SiO2 on Al")
ax.legend(fontsize=8)
for k, (lab, title) in enumerate([(lab_start, f"start\nΔE00 {dE_start:.1f}"), (target_lab, "target\nL* 90, a* 15, b* −15"),
                                  (lab_coloured, f"designed\nΔE00 {dE:.2f}")]):
    axs.add_patch(plt.Rectangle((k, 0), 0.9, 1, color=srgb(lab)))
    axs.text(k + 0.45, -0.08, title, ha="center", va="top", fontsize=8)
axs.set(xlim=(-0.1, 3), ylim=(-0.45, 1.05), xticks=[], yticks=[], title="sRGB swatches (D65)")
axs.set_frame_on(False)
save(fig, "05_colour_target")

# %% [markdown]
# ## 4 · Yield under thickness errors
#
# A deposition plant misses every thickness by a random error. With Gaussian errors of standard
# deviation σ on each layer of the needle design, what fraction of coatings keeps R ≤ 1 % at every
# wavelength of the band? `fitting.thickness_yield` draws the errors and evaluates all perturbed
# designs in one vmapped call. The check: an independent Monte-Carlo of the same specification
# with our own draws and the characteristic matrices; two estimates from N draws each agree
# within a few binomial standard errors $\sqrt{p(1-p)\,(2/N)}$.

# %%
spec = fitting.SpectralTarget(band, 0.01, 1e-9, kind="below")  # R <= 1 % on the 21 band points
thickness = np.array([float(layer.thickness) for layer in broadband.stack.layers])
n_band, _, _ = design_indices(broadband.stack, np.asarray(band), *AR)
rng = np.random.default_rng(5493)
N = 2000


def yield_reference(sigma_nm, draws=N):
    """Fraction of draws with max R <= 1 % over the band (independent Monte-Carlo)."""
    d = np.maximum(thickness + sigma_nm * rng.standard_normal((draws, thickness.size)), 0.0)
    R = reflectance_cm(n_band, [d[:, k : k + 1] for k in range(thickness.size)], n_s, np.asarray(band))
    return float(np.mean(R.max(axis=-1) <= 0.01))


sigmas = np.array([0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0])
reference = np.array([yield_reference(s) for s in sigmas])
library = {}
for s in (1.0, 2.0):
    library[s] = fitting.thickness_yield(broadband.stack, [spec], fitting.RobustSpec(sigma_nm=s, samples=N, seed=7)).fraction
    p = reference[sigmas == s][0]
    se = np.sqrt(max(p * (1 - p), 1 / N) * 2 / N)
    print(f"σ = {s:.1f} nm: yield {library[s]:.3f} (library), {p:.3f} (independent); difference {abs(library[s] - p) / se:.1f} s.e.")
    assert abs(library[s] - p) < 4 * se
nominal_ok = reflectance_cm(n_band, thickness, n_s, np.asarray(band)).max() <= 0.01
assert nominal_ok and np.all(np.diff(reference) <= 0.02)  # in spec without errors; yield falls with σ

fig, ax = plt.subplots(figsize=(7, 4))
err = np.sqrt(reference * (1 - reference) / N)
ax.errorbar(sigmas, 100 * reference, yerr=200 * err, fmt="o-", ms=4, capsize=3, label="independent Monte-Carlo (±2 s.e.)")
ax.plot(list(library), [100 * v for v in library.values()], "s", ms=9, mfc="none", mew=2, label="fitting.thickness_yield")
ax.set(xlabel="thickness error σ per layer (nm)", ylabel="yield: max R ≤ 1 % over 450–650 nm (%)", ylim=(0, 102),
       title=f"Yield of the {len(thickness)}-layer AR design ({N} draws per point)")
ax.legend(fontsize=8)
save(fig, "05_yield")
print("notebook 5: all checks passed")
