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
# # 1 · Stacked nonscattering layers over a diffusing background
#
# *Simonot, Hébert & Hersch, "Extension of the Williams–Clapper model to stacked nondiffusing
# colored coatings with different refractive indices", JOSA A 23 (2006) 1432.*
#
# A painted or printed surface is often a diffusing (Lambertian) body — paint, paper — under
# one or more clear or coloured layers that do not scatter: a varnish, the gelatin of a
# photographic print, ink films. Light in those layers follows straight lines, is attenuated by
# Beer's law, and is reflected and refracted at every interface by Fresnel's formulas; the
# background sends back a fraction ρg of what reaches it as Lambertian light. Simonot et al.
# compose all of that exactly, **per polarization**, for any number of layers of different
# refractive indices, and show that the classic models (Saunderson, Williams–Clapper,
# Shore–Spoonhower) are special cases.
#
# This notebook uses `layerstack_jax` to
#
# 1. read the intrinsic reflectance ρg of paints from measured spectra (Saunderson, eqs. 84–87),
# 2. varnish a painting (air / varnish / paint, eqs. 77–79),
# 3. reproduce the Williams–Clapper photographic print (eqs. 80–82) and the Shore–Spoonhower
#    sphere formula (eq. 83) **from closed forms written here from the paper**, not by the library,
# 4. stack two coloured layers of different indices,
# 5. see how the reflectance depends on the index mismatch,
# 6. compare integrating-sphere (SCE/SCI) and 45°/0° readings, and
# 7. invert a measurement over a varnished painting for ρg and check the round trip.
#
# Every key number is `assert`ed, so this file is also a test (`tests/test_notebooks.py`).
#
# **Units and conventions.** Wavelengths and thicknesses in nm, absorption coefficients α in
# 1/nm, angles in degrees in geometry objects (`ls.Sphere`, `ls.Directional`) and radians in
# functions; natural (unpolarized) light is the mean of s and p, taken after the whole
# recursion. See `docs/physics.md`.

# %%
import functools
import math
import warnings

import jax

jax.config.update("jax_enable_x64", True)  # user code chooses the precision, never the library

import colour
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
from scipy import integrate

import layerstack_jax as ls

from _figures import ROOT, save  # figures: notebooks/figures/ (tests: NOTEBOOK_FIGURES)


wl = np.arange(380.0, 781.0, 5.0)  # nm, the grid of the ColorChecker data below
# Gauss–Legendre nodes per critical-angle segment of the hemispherical integrals. A thick
# absorbing layer sharpens the integrand near grazing incidence; 64 nodes converge it to ~1e-12
# (layerstack_jax/_kernels/quadrature.py documents the accuracy of the default, ls.DEFAULT_NODES).
# One node count and one wavelength grid throughout also keep the array shapes, hence JAX's
# compiled kernels, the same from call to call.
NODES = 64
print(wl.shape)

# %% [markdown]
# ## The paper's formulas, written out independently
#
# To check the library we need the paper's special cases in closed form. They are written here
# with numpy and `scipy.integrate.quad` only, straight from the equations, and never call
# `layerstack_jax`.
#
# * Fresnel reflectance of an interface between real indices for natural light, eqs. 1–3, 6:
#   the tan/sin forms of eqs. 2–3 are 0/0 at normal incidence, so we use the equivalent
#   amplitude forms $r_s = (n_j\cos\theta_j - n_k\cos\theta_k)/(n_j\cos\theta_j + n_k\cos\theta_k)$,
#   $r_p = (n_k\cos\theta_j - n_j\cos\theta_k)/(n_k\cos\theta_j + n_j\cos\theta_k)$; beyond the
#   critical angle $R = 1$.
# * Diffuse reflectance of an interface, eq. 18: $r_{jk} = \int_0^{\pi/2} R_{jk}(\theta)\sin 2\theta\,d\theta$,
#   and $t_{jk} = 1 - r_{jk}$ (eq. 19).
# * Williams–Clapper integrals, eqs. 80–81, with the Beer factor $t_1(\theta) = e^{-\alpha h/\cos\theta}$ (eq. 23):
#   $r_{110} = \int R_{10}\,t_1^2 \sin 2\theta\,d\theta$, $t_{110} = \int T_{10}\,t_1 \sin 2\theta\,d\theta$.

# %%
QUAD = dict(epsabs=1e-14, epsrel=1e-13, limit=200)


def fresnel_R(nj, nk, theta_j):
    """Natural-light Fresnel reflectance from medium j into medium k (eqs. 1-3, 6), real indices,
    one angle theta_j (radians, in medium j)."""
    s = nj * math.sin(theta_j)
    cj = math.cos(theta_j)
    ck2 = 1.0 - (s / nk) ** 2
    if ck2 <= 0.0:
        return 1.0  # total internal reflection
    ck = math.sqrt(ck2)
    rs = (nj * cj - nk * ck) / (nj * cj + nk * ck)
    rp = (nk * cj - nj * ck) / (nk * cj + nj * ck)
    return 0.5 * (rs * rs + rp * rp)


def hemisphere(f, nj, nk, extra=()):
    """int_0^{pi/2} f(theta) sin(2 theta) d theta, split at the critical angle of j -> k
    (and at the angles in `extra`)."""
    points = {0.0, math.pi / 2, *extra}
    if nk < nj:
        points.add(math.asin(nk / nj))
    points = sorted(points)
    with warnings.catch_warnings():  # quad warns that 1e-13 is near round-off; it is reached
        warnings.simplefilter("ignore", integrate.IntegrationWarning)
        return sum(
            integrate.quad(lambda th: f(th) * math.sin(2 * th), a, b, **QUAD)[0] for a, b in zip(points[:-1], points[1:])
        )


def r_interface(nj, nk):
    """Diffuse reflectance of the interface j -> k, eq. 18."""
    return hemisphere(lambda th: fresnel_R(nj, nk, th), nj, nk)


def beer(alpha_h, theta):
    """t(theta) = exp(-alpha h / cos theta), eq. 23 (0 at grazing incidence)."""
    c = math.cos(theta)
    return math.exp(-alpha_h / c) if c > 1e-300 else 0.0


@functools.lru_cache(maxsize=None)
def wc_integrals(n0, n1, alpha_h):
    """r_110 (eq. 80) and t_110 (eq. 81); theta is the angle in the layer of index n1."""
    # a weak absorption cuts the integrand off sharply near grazing incidence, at cos θ ≈ αh
    knee = (math.acos(alpha_h),) if 0.0 < alpha_h < 1.0 else ()
    r110 = hemisphere(lambda th: fresnel_R(n1, n0, th) * beer(alpha_h, th) ** 2, n1, n0, knee)
    t110 = hemisphere(lambda th: (1 - fresnel_R(n1, n0, th)) * beer(alpha_h, th), n1, n0, knee)
    return r110, t110


def refracted(n0, n1, theta0):
    """Snell's law, eq. 1."""
    return math.asin(n0 * math.sin(theta0) / n1)


# %% [markdown]
# A sanity check of these helpers: the internal diffuse reflectance of an n = 1.5 interface
# (light inside the paint, hitting air) is 0.5963 (Judd 1942), and external and internal
# diffuse reflectances obey $1 - r_{20} = (1 - r_{02})/n^2$.

# %%
r20 = r_interface(1.5, 1.0)
r02 = r_interface(1.0, 1.5)
print(f"r_20 = {r20:.12f}   r_02 = {r02:.12f}")
assert abs(r20 - 0.596345759708) < 1e-11
assert abs((1 - r20) - (1 - r02) / 1.5**2) < 1e-13

# %% [markdown]
# ## 1 · The bare paint: Saunderson, and ρg from a measurement (eqs. 84–87)
#
# With no layer, a Lambertian background of index $n_2$ and intrinsic reflectance ρg reads, in an
# integrating sphere (specular component excluded, SCE) and with a radiance detector at
# $(\theta_0, \theta_0')$ against a perfect white diffuser,
#
# $$\rho = t_{20}\,\frac{\rho_g T_{02}(\theta_0)}{1-\rho_g r_{20}}\quad(84),\qquad
#   R(\theta_0,\theta_0') = \Big(\frac{n_0}{n_2}\Big)^2 T_{02}(\theta_0)T_{02}(\theta_0')\frac{\rho_g}{1-\rho_g r_{20}}\quad(85).$$
#
# Adding the specular reflection $R_{02}(\theta_0)$ (SCI) gives Saunderson's (1942) correction in
# its usual form, $R = k_1 + (1-k_1)(1-k_2)\rho_g/(1-k_2\rho_g)$ with $k_1 = R_{02}(\theta_0)$ and
# $k_2 = r_{20}$. In `layerstack_jax` a bare background is a stack without layers.

# %%
n_paint = 1.5
rho_grid = np.linspace(0.0, 1.0, wl.size)  # one ρg per wavelength: nothing else depends on λ here
bare = ls.Stack(ambient=1.0, layers=[], exit=ls.LambertianBackground(n_paint, jnp.asarray(rho_grid)))

th0, th0p = np.radians(8.0), np.radians(0.0)
T02_8 = 1 - fresnel_R(1.0, n_paint, th0)
sce = np.asarray(ls.reflectance(bare, wl, ls.Sphere(8.0, "excluded"), nodes=NODES))
sci = np.asarray(ls.reflectance(bare, wl, ls.Sphere(8.0, "included"), nodes=NODES))
sce_84 = (1 - r20) * rho_grid * T02_8 / (1 - rho_grid * r20)
k1, k2 = fresnel_R(1.0, n_paint, th0), r20
sci_saunderson = k1 + (1 - k1) * (1 - k2) * rho_grid / (1 - k2 * rho_grid)

th45 = np.radians(45.0)
R450 = np.asarray(ls.reflectance(bare, wl, ls.Directional(45.0, 0.0), nodes=NODES))
R450_85 = (1 / n_paint) ** 2 * (1 - fresnel_R(1.0, n_paint, th45)) * (1 - fresnel_R(1.0, n_paint, 0.0)) * rho_grid / (
    1 - rho_grid * r20
)
err_saunderson = max(np.abs(sce - sce_84).max(), np.abs(sci - sci_saunderson).max(), np.abs(R450 - R450_85).max())
print(f"library vs eqs. 84, 85 and Saunderson's form: max |Δ| = {err_saunderson:.1e}")
assert err_saunderson <= 1e-10

# %% [markdown]
# **Real spectra.** The 24 patches of the X-Rite ColorChecker are painted surfaces; colour-science
# ships their spectral reflectances (`colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]`, 380–780 nm
# in 5 nm steps). We *read them as if* they were integrating-sphere measurements (8°, SCE) of
# bare paints of binder index 1.5 — an illustration, not a claim about how Ohta measured them —
# and recover each paint's intrinsic reflectance ρg by eq. 86,
# $\rho_g = \rho / (t_{20}T_{02}(\theta_0) + r_{20}\rho)$, in closed form and with
# `ls.invert_background`.

# %%
checker = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
patches = ["red", "yellow", "blue", "green", "dark skin", "white 9.5 (.05 D)"]
measured = np.stack([checker[p].values for p in patches])  # (patch, wl)
assert np.allclose(checker["red"].wavelengths, wl)

rho_g_86 = measured / ((1 - r20) * T02_8 + r20 * measured)  # eq. 86, closed form
bare0 = ls.Stack(1.0, [], ls.LambertianBackground(n_paint, 0.0))  # the stack's own ρg is ignored
rho_g = np.asarray(ls.invert_background(bare0, wl, jnp.asarray(measured), ls.Sphere(8.0), nodes=NODES))
err_86 = np.abs(rho_g - rho_g_86).max()
# round trip: predict the sphere reading from the recovered ρg
back = np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.LambertianBackground(n_paint, jnp.asarray(rho_g))), wl, ls.Sphere(8.0), nodes=NODES))
err_trip = np.abs(back - measured).max()
print(f"eq. 86 vs library: {err_86:.1e};  round trip ρ -> ρg -> ρ: {err_trip:.1e}")
assert err_86 <= 1e-10 and err_trip <= 1e-12
assert rho_g.max() < 1.0

fig, ax = plt.subplots(figsize=(7, 4))
for p, m, g in zip(patches, measured, rho_g):
    (line,) = ax.plot(wl, g, label=p)
    ax.plot(wl, m, "--", color=line.get_color(), lw=1)
ax.set(xlabel="wavelength (nm)", ylabel="reflectance",
       title="ColorChecker patches: measured ρ (dashed) and intrinsic ρg (eq. 86, n = 1.5)")
ax.legend(fontsize=8, ncol=2)
save(fig, "01_rho_g_from_colorchecker")

# %% [markdown]
# The intrinsic reflectance is always higher than the measured one: light sent back by the paint
# is trapped by total internal reflection at the paint/air interface ($r_{20} \approx 0.60$) and
# absorbed on its next visits to the pigment. The darker the paint, the larger the relative gap.

# %% [markdown]
# ## 2 · A varnished painting (air / varnish / paint, eqs. 77–79)
#
# Now coat the blue patch (a sky, say) with a 30 µm natural-resin varnish: Cauchy index (n ≈ 1.54 at 550 nm) and
# the absorption of an aged, yellowed resin from `examples/varnish_alpha.csv` (a *synthetic*
# spectrum, stated in the file). The varnish is much thicker than the coherence length of
# daylight: `coherent=False`, intensities add. The radiance-detector reading at 45°/0° is eq. 79,
#
# $$R(\theta_0,\theta_0') = (n_0/n_2)^2\,T_{0..k+1}(\theta_0)\,T_{0..k+1}(\theta_0')\,\frac{\rho_g}{1-\rho_g r_{k+1..0}},$$
#
# with the collimated transmittances $T$ of the stack (eq. 58) and its diffuse reflectance $r$ seen
# from the paint (eq. 62).

# %%
table = ls.read_csv_columns(ROOT / "examples" / "varnish_alpha.csv", ["wavelength_nm", "alpha_per_nm"])
alpha_aged = np.interp(wl, table["wavelength_nm"], table["alpha_per_nm"])  # 1/nm
varnish_n = ls.Cauchy(1.525, 0.0045)  # A, B (µm²)


def varnished(rho, alpha, n_varnish=varnish_n, thickness=30_000.0, n_g=n_paint):
    layer = ls.Layer(n_varnish, thickness, coherent=False, alpha=alpha, name="varnish")
    return ls.Stack(1.0, [layer], ls.LambertianBackground(n_g, rho))


rho_blue = jnp.asarray(rho_g[patches.index("blue")])
geo = ls.Directional(45.0, 0.0)
R_bare = np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.LambertianBackground(n_paint, rho_blue)), wl, geo, nodes=NODES))
R_fresh = np.asarray(ls.reflectance(varnished(rho_blue, 0.0), wl, geo, nodes=NODES))
R_aged = np.asarray(ls.reflectance(varnished(rho_blue, jnp.asarray(alpha_aged)), wl, geo, nodes=NODES))


def lab(R):
    """CIELAB (D65, CIE 1931 2°) of a reflectance spectrum on `wl`."""
    sd = colour.SpectralDistribution(dict(zip(wl, np.asarray(R))))
    xyz = colour.sd_to_XYZ(sd, illuminant=colour.SDS_ILLUMINANTS["D65"]) / 100
    return colour.XYZ_to_Lab(xyz, colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"])


dE_fresh = colour.delta_E(lab(R_bare), lab(R_fresh), method="CIE 2000")
dE_aged = colour.delta_E(lab(R_fresh), lab(R_aged), method="CIE 2000")
print(f"45°/0°: varnishing changes the blue by ΔE00 = {dE_fresh:.2f}; yellowing of the varnish by a further {dE_aged:.2f}")
# A clear varnish (n ≈ n_g) changes little; the aged one removes blue light
assert np.all(R_aged <= R_fresh + 1e-15)
assert (R_fresh[wl == 380.0] - R_aged[wl == 380.0])[0] > 0.2 * R_fresh[wl == 380.0][0]

fig, ax = plt.subplots(figsize=(7, 4))
ax.plot(wl, R_bare, label="bare blue paint")
ax.plot(wl, R_fresh, label="+ clear varnish (α = 0)")
ax.plot(wl, R_aged, label="+ aged varnish (synthetic α)")
ax.set(xlabel="wavelength (nm)", ylabel="45°/0° reflectance factor", title="A varnished painting (ColorChecker blue, n_g = 1.5)")
ax2 = ax.twinx()
ax2.plot(wl, np.exp(-alpha_aged * 30_000.0), ":", color="gray")
ax2.set_ylabel("single-pass normal transmittance of the aged varnish (dotted)", color="gray", fontsize=8)
ax.legend(loc="center right", fontsize=8)
save(fig, "01_varnished_painting")

# %% [markdown]
# ## 3 · The Williams–Clapper photographic print (eqs. 80–82)
#
# Williams and Clapper (1953) modelled a colour print: dyes in a gelatin layer (n₁ ≈ 1.5) on a
# white baryta paper of the **same** index, so that the layer/paper interface disappears
# ($R_{12} = 0$, $T_{12} = 1$). The general model then reduces to
#
# $$R(\theta_0,\theta_0') = \Big(\frac{n_0}{n_1}\Big)^2\,
#   \frac{\rho_g T_{01}(\theta_0)T_{01}(\theta_0')\,t_1(\theta_1)t_1(\theta_1')}{1-\rho_g r_{110}}\qquad(82)$$
#
# with $r_{110}$ from eq. 80. We build the print in the library as *any* stack — one incoherent
# layer over a background that happens to have the same index — and compare with eq. 82 evaluated
# from the helpers above. The dyes are synthetic Gaussian absorption bands (cyan, magenta,
# yellow); the print paper's ρg is that of the white patch, from section 1.

# %%
def band(center, width, peak_alpha_h):
    return peak_alpha_h * np.exp(-0.5 * ((wl - center) / width) ** 2)


h_gel = 10_000.0  # nm
alpha_h_dye = band(630, 45, 0.9) + band(540, 35, 0.7) + band(440, 30, 0.8)  # a dark neutral-ish grey
alpha_dye = alpha_h_dye / h_gel  # 1/nm
rho_paper = rho_g[patches.index("white 9.5 (.05 D)")]
n1 = 1.5


def print_stack(alpha):
    gelatin = ls.Layer(n1, h_gel, coherent=False, alpha=jnp.asarray(alpha), name="gelatin")
    return ls.Stack(1.0, [gelatin], ls.LambertianBackground(n1, jnp.asarray(rho_paper)))


R_print = np.asarray(ls.reflectance(print_stack(alpha_dye), wl, ls.Directional(45.0, 0.0), nodes=NODES))


def williams_clapper(alpha_h, rho, theta0, theta0p, n0=1.0, n1=1.5):
    """Eq. 82, one wavelength."""
    r110, _ = wc_integrals(n0, n1, alpha_h)
    T01 = lambda th: 1 - fresnel_R(n0, n1, th)  # noqa: E731
    t1 = lambda th: beer(alpha_h, refracted(n0, n1, th))  # noqa: E731
    return (n0 / n1) ** 2 * rho * T01(theta0) * T01(theta0p) * t1(theta0) * t1(theta0p) / (1 - rho * r110)


R_82 = np.array([williams_clapper(a, r, th45, 0.0) for a, r in zip(alpha_h_dye, rho_paper)])
err_wc = np.abs(R_print - R_82).max()
print(f"Williams–Clapper print, 45°/0°: library vs eq. 82, max |Δ| = {err_wc:.1e} over {wl.size} wavelengths")
assert err_wc <= 1e-10
brdf = np.asarray(ls.reflectance(print_stack(alpha_dye), wl, ls.BRDF(45.0, 0.0), nodes=NODES))
assert np.abs(brdf - R_82 / np.pi).max() <= 1e-10  # eq. 76: BRDF = reflectance factor / π

# %% [markdown]
# Williams and Clapper's point was the **density** of a print. A naive model multiplies the
# paper by the dye's transmittance along the two paths, $D_\text{naive} = D_\text{paper} + \alpha h\,\log_{10}e\,(1/\cos\theta_1 + 1/\cos\theta_1')$;
# the internal reflections at the gelatin/air interface send light back through the dye again
# and again, so the print is denser than that. The gap opens at small dye amounts — light that
# would have come back after several trips is the first to be absorbed — and then stays nearly
# constant: at high densities only the direct path is left.

# %%
amounts = np.linspace(0.0, 2.0, wl.size)  # αh of a neutral dye, one amount per wavelength
grey = ls.Stack(
    1.0,
    [ls.Layer(n1, h_gel, coherent=False, alpha=jnp.asarray(amounts / h_gel))],
    ls.LambertianBackground(n1, 0.9),
)
R_grey = np.asarray(ls.reflectance(grey, wl, ls.Directional(45.0, 0.0), nodes=NODES))
D_print = -np.log10(R_grey / R_grey[0])
paths = 1 / np.cos(refracted(1.0, n1, th45)) + 1.0
D_naive = amounts * np.log10(np.e) * paths
R_grey_82 = np.array([williams_clapper(a, 0.9, th45, 0.0) for a in amounts])
assert np.abs(R_grey - R_grey_82).max() <= 1e-10
assert np.all(D_print[1:] > D_naive[1:])

fig, ax = plt.subplots(figsize=(5.5, 4))
ax.plot(D_naive, D_print, label="Williams–Clapper (library = eq. 82)")
ax.plot(D_naive, D_naive, "--", color="gray", label="Beer along the two paths only")
ax.set(xlabel="naive density (dye only)", ylabel="print reflection density, 45°/0°",
       title="Internal reflections deepen a print (ρg = 0.9, n = 1.5)")
ax.legend(fontsize=8)
save(fig, "01_williams_clapper_density")

# %% [markdown]
# ## 4 · Shore–Spoonhower (eq. 83) and Saunderson as special cases
#
# In an integrating sphere (SCE), the same print reads (eq. 83)
#
# $$R = t_{110}\,\frac{\rho_g T_{01}(\theta_0)\,t_1(\theta_1)}{1-\rho_g r_{110}},$$
#
# the Shore–Spoonhower generalisation of Williams–Clapper. With αh = 0 the index-matched layer
# disappears and what is left is the bare paint of section 1 (Saunderson): checked below too.

# %%
def shore_spoonhower(alpha_h, rho, theta0, n0=1.0, n1=1.5):
    """Eq. 83, one wavelength."""
    r110, t110 = wc_integrals(n0, n1, alpha_h)
    return t110 * rho * (1 - fresnel_R(n0, n1, theta0)) * beer(alpha_h, refracted(n0, n1, theta0)) / (1 - rho * r110)


R_sphere = np.asarray(ls.reflectance(print_stack(alpha_dye), wl, ls.Sphere(8.0), nodes=NODES))
R_83 = np.array([shore_spoonhower(a, r, th0) for a, r in zip(alpha_h_dye, rho_paper)])
err_ss = np.abs(R_sphere - R_83).max()
print(f"Shore–Spoonhower, sphere 8° SCE: library vs eq. 83, max |Δ| = {err_ss:.1e}")
assert err_ss <= 1e-10

# A layer of zero absorption and the paint's own index is no layer at all: Saunderson again.
clear = ls.Stack(1.0, [ls.Layer(n_paint, 5e4, coherent=False, alpha=0.0)], ls.LambertianBackground(n_paint, jnp.asarray(rho_grid)))
err_sd = np.abs(np.asarray(ls.reflectance(clear, wl, ls.Sphere(8.0), nodes=NODES)) - sce_84).max()
print(f"index-matched clear layer vs Saunderson (eq. 84): {err_sd:.1e}")
assert err_sd <= 1e-10

# %% [markdown]
# ## 5 · Two coloured layers of different indices (eqs. 50–61)
#
# Beyond Williams–Clapper: a yellow film of index 1.40 and a magenta film of index 1.65 (15 µm
# each, synthetic absorption bands) on the white paper of index 1.5. Every interface now
# reflects; the library composes the layers per polarization with eqs. 59–60 and averages s and
# p only at the end (eqs. 57–58). Swapping the two layers changes the reflectance, although the
# same dyes are crossed: the interfaces see different index steps.
#
# A check with a closed form: when all indices are equal the interfaces between the layers vanish
# and the two layers act as one of optical depth $\alpha_1h_1 + \alpha_2h_2$ — Williams–Clapper,
# eq. 82 again.

# %%
h = 15_000.0
alpha_yellow = band(440, 35, 1.2) / h
alpha_magenta = band(545, 40, 1.0) / h


def two_layers(n_top, a_top, n_bottom, a_bottom):
    return ls.Stack(
        1.0,
        [
            ls.Layer(n_top, h, coherent=False, alpha=jnp.asarray(a_top), name="top"),
            ls.Layer(n_bottom, h, coherent=False, alpha=jnp.asarray(a_bottom), name="bottom"),
        ],
        ls.LambertianBackground(1.5, jnp.asarray(rho_paper)),
    )


R_ym = np.asarray(ls.reflectance(two_layers(1.40, alpha_yellow, 1.65, alpha_magenta), wl, geo, nodes=NODES))
R_my = np.asarray(ls.reflectance(two_layers(1.65, alpha_magenta, 1.40, alpha_yellow), wl, geo, nodes=NODES))
R_same = np.asarray(ls.reflectance(two_layers(1.5, alpha_yellow, 1.5, alpha_magenta), wl, geo, nodes=NODES))
R_same_82 = np.array(
    [williams_clapper((ay + am) * h, r, th45, 0.0) for ay, am, r in zip(alpha_yellow, alpha_magenta, rho_paper)]
)
err_two = np.abs(R_same - R_same_82).max()
print(f"two index-matched layers vs eq. 82 with summed optical depth: {err_two:.1e}")
print(f"order matters: max |R(yellow on magenta) − R(magenta on yellow)| = {np.abs(R_ym - R_my).max():.4f}, "
      f"ΔE00 = {colour.delta_E(lab(R_ym), lab(R_my), method='CIE 2000'):.2f}")
assert err_two <= 1e-10
assert np.abs(R_ym - R_my).max() > 1e-3

fig, ax = plt.subplots(figsize=(7, 4))
ax.plot(wl, R_same, label="both n = 1.5 (= Williams–Clapper)")
ax.plot(wl, R_ym, label="yellow n = 1.40 on magenta n = 1.65")
ax.plot(wl, R_my, "--", label="magenta n = 1.65 on yellow n = 1.40")
ax.set(xlabel="wavelength (nm)", ylabel="45°/0° reflectance factor", title="Two coloured layers on paper (n_g = 1.5)")
ax.legend(fontsize=8)
save(fig, "01_two_layers")

# %% [markdown]
# ## 6 · How the reflectance depends on the index mismatch
#
# Take a clear layer (α = 0, 30 µm) of index $n_1$ over a paint of index $n_g$ with ρg = 0.5. If
# $n_1 = n_g$ the layer is invisible. The curves are not symmetric about that point: a layer of
# lower index reflects less at the air interface, both the incident beam and the diffuse light
# leaving the paint, and raises the reading; a layer of higher index lowers it.
# Nothing depends on the wavelength here, so we sweep $n_1$ along the wavelength axis: an index
# given as an array on the grid (`ls.Index(n1_sweep)`) is a per-wavelength index. (Indices are
# ordinary pytree leaves: `jax.vmap` over them and `jax.grad` with respect to them work too.)

# %%
n1_sweep = np.round(np.linspace(1.2, 2.0, wl.size), 12)  # steps of 0.01: hits 1.4, 1.5, 1.6 exactly


def clear_layer(n_1, n_g):
    layer = ls.Layer(ls.Index(n_1), 30_000.0, coherent=False, alpha=0.0, name="clear")
    return ls.Stack(1.0, [layer], ls.LambertianBackground(n_g, 0.5))


fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharex=True)
mismatch = {}
for n_g in (1.4, 1.5, 1.6):
    for ax, geometry, title in zip(axes, (ls.Directional(45.0, 0.0), ls.Sphere(8.0)), ("45°/0°", "sphere 8°, SCE")):
        R = np.asarray(ls.reflectance(clear_layer(n1_sweep, n_g), wl, geometry, nodes=NODES))
        bare_value = np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.LambertianBackground(n_g, 0.5)), wl, geometry, nodes=NODES))[0]
        i = int(np.argmin(np.abs(n1_sweep - n_g)))
        assert abs(n1_sweep[i] - n_g) < 1e-12 and abs(R[i] - bare_value) <= 1e-10  # n1 = n_g: no layer
        assert R[-1] < bare_value < R[0]  # n1 = 2.0 reads lower, n1 = 1.2 higher than the bare paint
        mismatch[n_g, title] = R
        (line,) = ax.plot(n1_sweep, R, label=f"n_g = {n_g}")
        ax.plot([n_g], [bare_value], "o", color=line.get_color())
        ax.set(title=title, xlabel="index of the clear layer n₁")
axes[0].set_ylabel("reflectance (ρg = 0.5)")
axes[0].legend(fontsize=8)
fig.suptitle("A clear layer over paint: reflectance vs the layer's index (dots: n₁ = n_g, no interface)")
save(fig, "01_index_mismatch")
R = mismatch[1.5, "45°/0°"]
print(f"n_g = 1.5, 45°/0°: R = {R.min():.4f} … {R.max():.4f} for n₁ in [1.2, 2.0]; bare paint {R[np.argmin(np.abs(n1_sweep - 1.5))]:.4f}")

# %% [markdown]
# ## 7 · Integrating sphere (SCE / SCI) vs 45°/0°
#
# The same varnished painting reads differently in different instruments:
#
# * sphere, specular excluded (eq. 78): $R = t_{k+1..0}\,\rho_g T(\theta_0)/(1-\rho_g r_{k+1..0})$;
# * sphere, specular included: the same plus the front reflectance $R_{0..k+1}(\theta_0)$ of the stack;
# * radiance detector 45°/0° (eq. 79): $(n_0/n_g)^2 T(45°)T(0°)\rho_g/(1-\rho_g r_{k+1..0})$.
#
# The diffuse parts share the factor $\rho_g/(1-\rho_g r)$: their ratio,
# $(n_0/n_g)^2\,T(45°)T(0°)/(t\,T(8°))$, depends on the stack but **not on the paint**. We check it
# on six ColorChecker paints at once (ρg shaped `(patch, wl)`).

# %%
aged = varnished(jnp.asarray(rho_g), jnp.asarray(alpha_aged))  # six paints under the same varnish
R_sce = np.asarray(ls.reflectance(aged, wl, ls.Sphere(8.0, "excluded"), nodes=NODES))
R_sci = np.asarray(ls.reflectance(aged, wl, ls.Sphere(8.0, "included"), nodes=NODES))
R_450 = np.asarray(ls.reflectance(aged, wl, ls.Directional(45.0, 0.0), nodes=NODES))
assert R_sce.shape == (len(patches), wl.size)
ratio = R_450 / R_sce
spread = np.abs(ratio - ratio[0]).max()
print(f"45°/0° ÷ SCE over six paints: {ratio[0].min():.4f} … {ratio[0].max():.4f} across λ; spread between paints {spread:.1e}")
assert spread <= 1e-12
spec = np.asarray(ls.reflectance(aged, wl, ls.Specular(8.0, "R")))
assert np.abs((R_sci - R_sce) - spec).max() <= 1e-14
print(f"SCI − SCE = front reflectance of the varnished paint at 8°: {spec.min():.4f} … {spec.max():.4f}")

fig, ax = plt.subplots(figsize=(7, 4))
for k, p in enumerate(patches[:3]):
    (line,) = ax.plot(wl, R_sce[k], label=f"{p}: sphere SCE")
    ax.plot(wl, R_sci[k], ":", color=line.get_color(), label=f"{p}: sphere SCI")
    ax.plot(wl, R_450[k], "--", color=line.get_color(), label=f"{p}: 45°/0°")
ax.set(xlabel="wavelength (nm)", ylabel="reflectance", title="Varnished paints in three instruments", ylim=(0, 1.12))
ax.legend(fontsize=7, ncol=3, loc="upper left")
save(fig, "01_geometries")

# %% [markdown]
# ## 8 · ρg from a measurement over a varnished painting, and the round trip
#
# Eqs. 86–87 invert a bare-paint measurement. `ls.invert_background` does the same for any stack:
# with the model $R = A\rho_g/(1-\rho_g r)$ of each geometry, $\rho_g = R/(A + rR)$. We "measure"
# the varnished paints of section 7 and recover ρg. Ignoring the varnish — inverting with the bare
# eq. 86 — gives a biased ρg, most of all in the blue where the varnish absorbs.

# %%
rec_sce = np.asarray(ls.invert_background(aged, wl, jnp.asarray(R_sce), ls.Sphere(8.0), nodes=NODES))
rec_sci = np.asarray(ls.invert_background(aged, wl, jnp.asarray(R_sci), ls.Sphere(8.0, "included"), nodes=NODES))
rec_450 = np.asarray(ls.invert_background(aged, wl, jnp.asarray(R_450), ls.Directional(45.0, 0.0), nodes=NODES))
err_rt = max(np.abs(r - rho_g).max() for r in (rec_sce, rec_sci, rec_450))
print(f"round trip ρg -> measurement -> ρg (SCE, SCI, 45°/0°): max |Δ| = {err_rt:.1e}")
assert err_rt <= 1e-12

# eq. 87 for a bare paint, closed form vs library
R450_bare = np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.LambertianBackground(n_paint, jnp.asarray(rho_g))), wl, geo, nodes=NODES))
A_85 = (1 / n_paint) ** 2 * (1 - fresnel_R(1.0, n_paint, th45)) * (1 - fresnel_R(1.0, n_paint, 0.0))
rho_87 = R450_bare / (A_85 + r20 * R450_bare)
assert np.abs(rho_87 - rho_g).max() <= 1e-10

naive = R_sce / ((1 - r20) * T02_8 + r20 * R_sce)  # eq. 86 as if there were no varnish
fig, ax = plt.subplots(figsize=(7, 4))
for k, p in enumerate(patches[:3]):
    (line,) = ax.plot(wl, rho_g[k], label=f"{p}: true ρg (= recovered, |Δ| ≤ 1e-12)")
    ax.plot(wl, naive[k], "--", color=line.get_color(), label=f"{p}: eq. 86 ignoring the varnish")
ax.set(xlabel="wavelength (nm)", ylabel="intrinsic reflectance ρg", title="Inverting a varnished painting for ρg")
ax.legend(fontsize=7)
save(fig, "01_inversion")
print("notebook 1: all checks passed")
