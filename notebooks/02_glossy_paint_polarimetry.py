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
# # 2 · The polarimetric BRDF of a glossy paint
#
# *D. B. Ellis, "Polarimetric bidirectional reflectance distribution function of glossy
# coatings", JOSA A 13 (1996) 1758.*
#
# A glossy paint is modelled as a Lambertian reflector of albedo ρ0 (the pigmented body) under a
# smooth dielectric surface of index n (the binder). The surface reflects a specular part,
# polarized by Fresnel's formulas; the rest enters, is scattered by the pigment, and bounces
# between the pigment and the underside of the surface — total internal reflection sends most of
# it back — before it leaves. The pigment re-emits **unpolarized** light, yet the light that
# comes out is **not** unpolarized: it has crossed the surface once more, and the surface
# transmits p better than s. Ellis derives the four polarized BRDFs $f_{ab}$ (illumination
# polarization a, analyser b) in closed form and draws two conclusions that this notebook
# checks:
#
# * multiple scattering in the pigment seldom depolarizes the reflected light completely, and
# * even when it does, first-surface and volume scattering cannot be separated by polarization
#   alone.
#
# With `layerstack_jax` the glossy paint is a stack without layers over a
# `LambertianBackground(n, ρ0)`. We
#
# 1. write Ellis's formulas independently (numpy and `scipy.integrate.quad` only),
# 2. reproduce his Fig. 2, the zero-bistatic (retro-reflection) BRDFs for n = 1.55, ρ0 = 0.75,
# 3. compute the degree of polarization of the diffuse light,
# 4. evaluate Ellis's combination $f_{pp} + f_{ss} - f_{ps} - f_{sp}$, and
# 5. look at the Mueller matrices of the diffuse and the specular parts and check that they are
#    physically realizable.
#
# Every key number is `assert`ed, so this file is also a test (`tests/test_notebooks.py`).
#
# **Units and conventions.** Angles in degrees at the library's polarimetry functions, radians
# in the closed forms below; BRDFs in 1/sr. The polarimetry module's Stokes basis is (p, s):
# $Q = I_p - I_s$ (`layerstack_jax/_instruments/polarimetry.py`). `ls.polarized_brdf` returns
# `f[..., a, b, wl]` with a the illumination and b the analyser, each ordered (s, p): `f[..., 1, 0, :]`
# is Ellis's $f_{ps}$ (p in, s out).

# %%
import math
import warnings

import jax

jax.config.update("jax_enable_x64", True)  # user code chooses the precision, never the library

import matplotlib.pyplot as plt
import numpy as np
from scipy import integrate

import layerstack_jax as ls

from _figures import save  # figures: notebooks/figures/ (tests: NOTEBOOK_FIGURES)


N_PAINT, RHO_0 = 1.55, 0.75  # Ellis's Fig. 2
paint = ls.Stack(ambient=1.0, layers=[], exit=ls.LambertianBackground(N_PAINT, RHO_0))
wl = np.array([550.0])  # nothing depends on the wavelength here: one wavelength, nm

# The library's polarimetry functions, compiled once each (the first call of an uncompiled JAX
# function dispatches op by op, which is slow); every call below reuses one array shape.
polarized_brdf = jax.jit(ls.polarized_brdf)
diffuse_mueller = jax.jit(ls.diffuse_mueller)
specular_mueller = jax.jit(ls.specular_mueller)
reflectance = jax.jit(ls.reflectance)
cloude_eigenvalues = jax.jit(ls.cloude_eigenvalues)
is_physical = jax.jit(ls.is_physical)

theta_deg = np.round(np.arange(0.0, 89.95, 0.1), 10)  # 0°, 0.1°, …, 89.9°: the angle grid
theta = np.radians(theta_deg)
print(f"{theta_deg.size} angles, step 0.1°")

# %% [markdown]
# ## The paper's formulas, written out independently
#
# Ellis's displayed equations are numbered here 1–28 in the order of the paper (our copy of
# the paper does not print the numbers).
#
# * Fresnel reflectances of the surface for light from air, eqs. 1–3, with the refraction angle
#   $\theta^*$ from Snell's law, eq. 6 ($\sin\theta = n\sin\theta^*$):
#   $R_s = \sin^2(\theta-\theta^*)/\sin^2(\theta+\theta^*)$,
#   $R_p = \tan^2(\theta-\theta^*)/\tan^2(\theta+\theta^*)$, $T = 1 - R$; at normal incidence
#   both are $((n-1)/(n+1))^2$.
# * Inside the paint, eqs. 4–5 (reciprocity): $R^*(\theta^*) = R(\theta)$ for the same ray; past
#   the critical angle $\arcsin(1/n)$, $R^* = 1$.
# * The pigment's light is unpolarized, so the surface reflects it back with the natural-light
#   reflectance $R^*_{s+p} = (R^*_s + R^*_p)/2$ (eq. 13). The integral of eqs. 14 and 20,
#   $\int R^*_{s+p}(\theta_d)\cos\theta_d\,d\Omega_d$ over the hemisphere, is
#   $\pi\, r_i$ with $r_i = \int_0^{\pi/2} R^*_{s+p}(\theta)\sin 2\theta\,d\theta$ the internal
#   diffuse reflectance. (With the *sum* $R^*_s + R^*_p$ instead of the mean, the series of
#   eqs. 19–21 would diverge for a white pigment, ρ0 = 1, since $2r_i > 1$.)
# * The diffuse part of the polarized BRDFs, eqs. 25–26:
#
# $$f_{ab}(\theta_i, \theta_r) = \frac{T_a(\theta_i)\,T_b(\theta_r)}
#   {2n^2\left[\pi/\rho_0 - \int R^*_{s+p}(\theta_d)\cos\theta_d\,d\Omega_d\right]}
#   = \frac{\rho_0\,T_a(\theta_i)\,T_b(\theta_r)}{2\pi n^2\,(1-\rho_0 r_i)},\qquad a, b \in \{s, p\}.$$
#
#   (Eq. 25 adds the specular term $R_p(\theta_i)\,\delta(\theta_r-\theta_i)\,\delta(\phi_r-\phi_i+\pi)/(\cos\theta_r\sin\theta_r)$
#   to $f_{pp}$, and $R_s\,\delta\ldots$ to $f_{ss}$; it is zero away from the mirror direction, in
#   particular in retro-reflection at oblique incidence.)

# %%
QUAD = dict(epsabs=1e-14, epsrel=1e-13, limit=200)


def fresnel_ellis(th, n=N_PAINT):
    """(R_s, R_p) of the air/paint surface at incidence th (radians, numpy array), eqs. 1, 2, 6;
    the normal-incidence limit where th = 0."""
    th = np.asarray(th, dtype=float)
    ts = np.arcsin(np.sin(th) / n)  # eq. 6
    normal = th == 0
    safe_plus = np.where(normal, 1.0, th + ts)  # sin, tan of θ + θ* are 0 at θ = 0 only
    R_s = np.where(normal, 0.0, np.sin(th - ts) ** 2 / np.sin(safe_plus) ** 2)
    R_p = np.where(normal, 0.0, np.tan(th - ts) ** 2 / np.tan(safe_plus) ** 2)
    R0 = ((n - 1) / (n + 1)) ** 2
    return np.where(normal, R0, R_s), np.where(normal, R0, R_p)


def internal_natural_R(ts, n=N_PAINT):
    """R*_{s+p}(θ*) inside the paint (eqs. 4, 5, 13): the reflectance of the same ray from air,
    total reflection past the critical angle."""
    s = n * math.sin(ts)
    if s >= 1.0:
        return 1.0
    R_s, R_p = fresnel_ellis(math.asin(s), n)
    return 0.5 * float(R_s + R_p)


def internal_diffuse_reflectance(n=N_PAINT):
    """r_i = int_0^{pi/2} R*_{s+p} sin 2θ dθ, split at the critical angle."""
    crit = math.asin(1.0 / n)
    with warnings.catch_warnings():  # quad warns that 1e-13 is near round-off; it is reached
        warnings.simplefilter("ignore", integrate.IntegrationWarning)
        return sum(
            integrate.quad(lambda t: internal_natural_R(t, n) * math.sin(2 * t), a, b, **QUAD)[0]
            for a, b in ((0.0, crit), (crit, math.pi / 2))
        )


r_i = internal_diffuse_reflectance()


def ellis_f(a, b, th_i, th_r, n=N_PAINT, rho0=RHO_0):
    """Diffuse part of Ellis's f_ab (eqs. 25, 26), a, b in {'s', 'p'}, angles in radians."""
    T = {"s": lambda th: 1 - fresnel_ellis(th, n)[0], "p": lambda th: 1 - fresnel_ellis(th, n)[1]}
    return T[a](th_i) * T[b](th_r) / (2 * n**2 * (math.pi / rho0 - math.pi * r_i))


print(f"internal diffuse reflectance of the n = {N_PAINT} surface: r_i = {r_i:.12f}")
print(f"effective albedo of the pigment under the surface, ρ0/(1 − ρ0 r_i) (eq. 27) = {RHO_0 / (1 - RHO_0 * r_i):.6f}")

# %% [markdown]
# A sanity check of these helpers: for n = 1.5 the internal diffuse reflectance is 0.596346
# (Judd 1942), and energy conservation at the surface gives $1 - r_i = (1 - r_e)/n^2$ with the
# external diffuse reflectance $r_e = \int_0^{\pi/2} \bar R(\theta)\sin 2\theta\,d\theta$.

# %%
r_e = integrate.quad(lambda t: float(np.mean(fresnel_ellis(t))) * math.sin(2 * t), 0, math.pi / 2, **QUAD)[0]
print(f"r_i(1.5) = {internal_diffuse_reflectance(1.5):.12f};  1 − r_i − (1 − r_e)/n² = {(1 - r_i) - (1 - r_e) / N_PAINT**2:.1e}")
assert abs(internal_diffuse_reflectance(1.5) - 0.596345759708) < 1e-11
assert abs((1 - r_i) - (1 - r_e) / N_PAINT**2) < 1e-13

# %% [markdown]
# ## 1 · Zero-bistatic BRDF: Ellis's Fig. 2
#
# In retro-reflection the source and the detector look along the same direction:
# $\theta_r = \theta_i = \theta$, $\phi_r = \phi_i$ — never the mirror direction except at
# normal incidence, so only the diffuse part is seen. Then
# $f_{ab} \propto T_a(\theta)\,T_b(\theta)$, and because $T_p \ge T_s$ (equal only at normal
# incidence) the curves are ordered $f_{pp} > f_{ps} = f_{sp} > f_{ss}$ at every oblique angle.
# $T_p = 1$ at Brewster's angle $\arctan n$ = 57.17°, where $f_{pp}$ peaks at its largest possible
# value $\rho_0/(2\pi n^2(1-\rho_0 r_i))$.

# %%
f = np.asarray(polarized_brdf(paint, wl, theta_deg, theta_deg))[..., 0]  # (angle, in, out)
f_ss, f_sp, f_ps, f_pp = f[:, 0, 0], f[:, 0, 1], f[:, 1, 0], f[:, 1, 1]

closed = {ab: ellis_f(ab[0], ab[1], theta, theta) for ab in ("ss", "sp", "ps", "pp")}
err_fig2 = max(np.abs(lib - closed[ab]).max() for ab, lib in zip(("ss", "sp", "ps", "pp"), (f_ss, f_sp, f_ps, f_pp)))
print(f"library vs eqs. 25-26 over the whole curve: max |Δf| = {err_fig2:.1e} 1/sr")
assert err_fig2 <= 1e-10

oblique = theta_deg > 0
assert np.all(f_pp[oblique] > f_ps[oblique]) and np.all(f_ps[oblique] > f_ss[oblique])
assert np.abs(f_ps - f_sp).max() <= 1e-15  # the p,s and s,p curves are identical (Fig. 2 caption)
assert abs(f_pp[0] - f_ss[0]) <= 1e-15 and abs(f_ps[0] - f_pp[0]) <= 1e-15  # normal incidence: all equal

brewster = math.degrees(math.atan(N_PAINT))
peak = theta_deg[np.argmax(f_pp)]
f_max = RHO_0 / (2 * math.pi * N_PAINT**2 * (1 - RHO_0 * r_i))
print(f"f_pp peaks at {peak:.1f}° (Brewster: {brewster:.2f}°), value {f_pp.max():.6f} 1/sr (T_p = 1: {f_max:.6f})")
print(f"at normal incidence f_pp = f_ss = f_ps = {f_pp[0]:.6f} 1/sr")
assert abs(peak - brewster) <= 0.05  # half the grid step
assert abs(f_pp.max() - f_max) <= 1e-6  # within the grid: f_pp is flat at its maximum

# one bistatic point, θi = 30°, θr = 60°, of all four f_ab: the closed form again
f_3060 = np.asarray(polarized_brdf(paint, wl, np.full_like(theta_deg, 30.0), np.full_like(theta_deg, 60.0)))[0, ..., 0]
err_point = max(abs(f_3060[i, j] - ellis_f(a, b, math.radians(30), math.radians(60)))
                for i, a in enumerate("sp") for j, b in enumerate("sp"))
print(f"θi = 30°, θr = 60°: f_pp = {f_3060[1, 1]:.12f} 1/sr; library vs eq. 25-26: {err_point:.1e}")
assert err_point <= 1e-10

fig, ax = plt.subplots(figsize=(7, 4))
ax.plot(theta_deg, f_pp, label="$f_{pp}$")
ax.plot(theta_deg, f_ps, label="$f_{ps} = f_{sp}$")
ax.plot(theta_deg, f_ss, label="$f_{ss}$")
ax.axvline(brewster, color="gray", ls=":", lw=1)
ax.text(brewster + 1, 0.01, "Brewster\n57.17°", color="gray", fontsize=8)
ax.set(xlabel="angle of incidence = angle of viewing (degrees)", ylabel="BRDF (1/sr)", xlim=(0, 90), ylim=(0, None),
       title=f"Zero-bistatic polarized BRDF of a glossy paint (n = {N_PAINT}, ρ0 = {RHO_0}), cf. Ellis Fig. 2")
ax.legend()
save(fig, "02_zero_bistatic_brdf")

# %% [markdown]
# The three curves start together at 0.0850 1/sr; $f_{pp}$ rises to its Brewster maximum and
# all fall to zero at grazing incidence, where the surface reflects everything. Summed over the
# analyser and averaged over the two illuminations, the four curves give the natural-light BRDF
# of `ls.reflectance(paint, wl, ls.BRDF(θ, θ))` (Simonot et al. eq. 76) — one more check, of
# the library against itself.

# %%
natural = np.asarray(reflectance(paint, wl, ls.BRDF(30.0, 60.0)))[0]
assert abs(0.5 * f_3060.sum() - natural) <= 1e-15
print(f"natural-light BRDF at 30°/60°: {natural:.12f} 1/sr = ½ Σ f_ab")

# %% [markdown]
# ## 2 · The diffuse light is partially polarized
#
# Under unpolarized illumination the diffuse light leaving at $\theta_r$ has the Stokes vector
# $\propto (\bar T, (T_p - T_s)/2, 0, 0)$ of the surface's transmission at $\theta_r$: its degree of
# polarization, $(T_p - T_s)/(T_p + T_s) = (R_s - R_p)/(2 - R_s - R_p)$, depends on the viewing angle
# only, not on the illumination, and grows towards grazing viewing. This is Ellis's first
# conclusion: the pigment depolarizes, the surface re-polarizes. For contrast, the specular
# reflection is polarized by $(R_s - R_p)/(R_s + R_p)$, fully at Brewster's angle.
#
# The library computes it from the diffuse Mueller matrix (`ls.diffuse_mueller`), applied to
# unpolarized light (`ls.stokes("unpolarized")`), and `ls.degree_of_polarization`.

# %%


@jax.jit
def diffuse_light(incidence_deg, viewing_deg):
    """Stokes vector (angle, 4, wl) and degree of polarization (angle, wl) of the diffuse light
    under unpolarized illumination."""
    M = ls.diffuse_mueller(paint, wl, incidence_deg, viewing_deg)  # (angle, 4, 4, wl)
    S_out = ls.apply_mueller(M, ls.stokes("unpolarized"))
    return S_out, ls.degree_of_polarization(S_out)


dop = {}
for th_i in (0.0, 60.0):
    S_out, d = diffuse_light(np.full_like(theta_deg, th_i), theta_deg)
    dop[th_i] = np.asarray(d)[:, 0]
    assert np.all(np.asarray(S_out)[:, 1, 0] >= -1e-15)  # Q ≥ 0: the excess is p-polarized
R_s, R_p = fresnel_ellis(theta)
dop_closed = (R_s - R_p) / (2 - R_s - R_p)
dop_specular = (R_s - R_p) / (R_s + R_p)
err_dop = max(np.abs(d - dop_closed).max() for d in dop.values())
print(f"degree of polarization of the diffuse light vs (R_s − R_p)/(2 − R_s − R_p): {err_dop:.1e}; "
      f"independent of θi: {np.abs(dop[0.0] - dop[60.0]).max():.1e}")
for a in (30, 60, 80, 89.9):
    k = int(np.argmin(np.abs(theta_deg - a)))
    print(f"  viewed at {theta_deg[k]:4.1f}°: diffuse {dop[0.0][k]:.4f}   specular {dop_specular[k]:.4f}")
assert err_dop <= 1e-12 and np.abs(dop[0.0] - dop[60.0]).max() <= 1e-12
k80 = int(np.argmin(np.abs(theta_deg - 80.0)))
assert 0.2 < dop[0.0][k80] < 0.5  # far from depolarized at 80°

fig, ax = plt.subplots(figsize=(7, 4))
ax.plot(theta_deg, dop[0.0], label="diffuse light (any illumination angle)")
ax.plot(theta_deg, dop_specular, "--", label="specular reflection")
ax.axvline(brewster, color="gray", ls=":", lw=1)
ax.set(xlabel="viewing angle (degrees)", ylabel="degree of polarization", xlim=(0, 90), ylim=(0, 1.02),
       title=f"Glossy paint under unpolarized light (n = {N_PAINT}, ρ0 = {RHO_0})")
ax.legend()
save(fig, "02_degree_of_polarization")

# %% [markdown]
# ## 3 · Polarization does not separate surface from volume (eq. 28)
#
# A polarimetric trick would isolate the first-surface reflection with
# $f_{pp} + f_{ss} - f_{ps} - f_{sp}$: if the volume light were unpolarized the four diffuse terms
# would be equal and cancel. Ellis's eq. 28 shows that they do not: the diffuse part leaves
#
# $$\frac{\rho_0\,[T_p(\theta_i) - T_s(\theta_i)]\,[T_p(\theta_r) - T_s(\theta_r)]}{2\pi n^2(1 - \rho_0 r_i)},$$
#
# plus the specular term $[R_p + R_s]\,\delta(\ldots)$. (Our copy of eq. 28 prints the square
# $[T_p(\theta_r) - T_s(\theta_r)]^2$, which is the product above when $\theta_i = \theta_r$, as in
# retro-reflection.) It is small but nonzero — his second conclusion.

# %%
combo = f_pp + f_ss - f_ps - f_sp
T_s, T_p = 1 - R_s, 1 - R_p
combo_28 = RHO_0 * (T_p - T_s) ** 2 / (2 * math.pi * N_PAINT**2 * (1 - RHO_0 * r_i))
err_28 = np.abs(combo - combo_28).max()
share = combo / (0.5 * (f_pp + f_ss + f_ps + f_sp))
print(f"eq. 28, diffuse part, vs library: {err_28:.1e}; it is {share[k80]:.1%} of the natural-light BRDF at 80°")
assert err_28 <= 1e-12 and combo[k80] > 0

# %% [markdown]
# ## 4 · Mueller matrices, and are they physical?
#
# In Stokes form the diffuse BRDF is the rank-one matrix $K\,v(\theta_r)\,v(\theta_i)^T$ with
# $v = (\bar T, (T_p - T_s)/2, 0, 0)$ (`ls.diffuse_mueller`): a partial polarizer on the way in, the
# pigment's depolarization, a partial polarizer on the way out. The specular part is the Mueller
# matrix of the surface's reflection (`ls.specular_mueller`), written from the Fresnel
# *amplitudes* $r_s = -\sin(\theta-\theta^*)/\sin(\theta+\theta^*)$,
# $r_p = \tan(\theta-\theta^*)/\tan(\theta+\theta^*)$ (Born & Wolf §1.5, Ellis's ref. 9; real below the
# critical angle, so no s–p phase):
#
# $$M_{spec} = \begin{pmatrix} \bar R & (R_p-R_s)/2 & 0 & 0\\ (R_p-R_s)/2 & \bar R & 0 & 0\\
#   0 & 0 & r_pr_s & 0\\ 0 & 0 & 0 & r_pr_s \end{pmatrix}.$$
#
# A 4 × 4 matrix is a physically realizable Mueller matrix iff its Cloude coherency matrix has
# no negative eigenvalue (`ls.is_physical`). The specular matrix has a single nonzero eigenvalue
# (a pure, non-depolarizing system); the diffuse one has four (it depolarizes). A counter-example,
# $\mathrm{diag}(1, 1, 1, -1)$ — a "mirror" that flips circular but not linear polarization — is not
# physical.

# %%
i_deg, r_deg = 30.0, 60.0
M_diff = np.asarray(diffuse_mueller(paint, wl, np.full_like(theta_deg, i_deg), np.full_like(theta_deg, r_deg)))[0]
M_spec_all = specular_mueller(paint, wl, theta_deg)
M_spec = np.asarray(M_spec_all)[int(np.argmin(np.abs(theta_deg - 45.0)))]  # 45°

K = RHO_0 / (math.pi * N_PAINT**2 * (1 - RHO_0 * r_i))
(Rs_i, Rp_i), (Rs_r, Rp_r) = fresnel_ellis(math.radians(i_deg)), fresnel_ellis(math.radians(r_deg))
v_in = np.array([1 - (Rs_i + Rp_i) / 2, (Rs_i - Rp_i) / 2, 0, 0])
v_out = np.array([1 - (Rs_r + Rp_r) / 2, (Rs_r - Rp_r) / 2, 0, 0])
M_diff_closed = K * np.outer(v_out, v_in)

th45 = math.radians(45.0)
ts45 = math.asin(math.sin(th45) / N_PAINT)
r_s = -math.sin(th45 - ts45) / math.sin(th45 + ts45)
r_p = math.tan(th45 - ts45) / math.tan(th45 + ts45)
Rb, Rd = (r_s**2 + r_p**2) / 2, (r_p**2 - r_s**2) / 2
M_spec_closed = np.array([[Rb, Rd, 0, 0], [Rd, Rb, 0, 0], [0, 0, r_p * r_s, 0], [0, 0, 0, r_p * r_s]])

err_mueller = max(np.abs(M_diff[..., 0] - M_diff_closed).max(), np.abs(M_spec[..., 0] - M_spec_closed).max())
print(f"Mueller matrices vs closed forms: {err_mueller:.1e}")
assert err_mueller <= 1e-10

not_a_mueller = np.diag([1.0, 1.0, 1.0, -1.0])[..., None]
# one call for all the matrices: diffuse, specular at 45°, the counter-example, specular at every angle
batch = np.concatenate([np.stack([M_diff, M_spec, not_a_mueller]), np.asarray(M_spec_all)])
eig = np.asarray(cloude_eigenvalues(batch))[..., 0]  # (matrix, 4), ascending
physical = np.asarray(is_physical(batch))[:, 0]
for k, name in enumerate(("diffuse 30°→60°", "specular 45°", "diag(1, 1, 1, −1)")):
    print(f"{name:18s} Cloude eigenvalues {np.array2string(eig[k] / eig[k].max(), precision=4)} (÷ largest)"
          f"  physical: {physical[k]}")
assert physical[0] and physical[1] and not physical[2]
assert np.all(physical[3:])  # the specular reflection at every angle of the grid
assert np.all(np.abs(eig[1, :3]) <= 1e-12 * eig[1, 3])  # specular: pure, rank one
assert eig[0].min() > 0.1 * eig[0].max()  # diffuse: strongly depolarizing

fig, axes = plt.subplots(1, 2, figsize=(9, 4))
for ax, M, title in ((axes[0], M_diff[..., 0], f"diffuse, θi = {i_deg:.0f}°, θr = {r_deg:.0f}° (÷ m00)"),
                     (axes[1], M_spec[..., 0], "specular, 45° (÷ m00)")):
    m = M / M[0, 0]
    ax.imshow(m, cmap="RdBu_r", vmin=-1, vmax=1)
    for (r, c), val in np.ndenumerate(m):
        ax.text(c, r, f"{val:+.3f}", ha="center", va="center", fontsize=9, color="white" if abs(val) > 0.6 else "black")
    ax.set(title=title, xticks=range(4), yticks=range(4), xticklabels=["I", "Q", "U", "V"], yticklabels=["I", "Q", "U", "V"])
fig.suptitle(f"Mueller matrices of the glossy paint (n = {N_PAINT}, ρ0 = {RHO_0}); both physical", y=1.02)
save(fig, "02_mueller_matrices")
print("notebook 2: all checks passed")
