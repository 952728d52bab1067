r"""Colour of a spectrum: CIE XYZ, xyY, CIELAB, sRGB and colour differences ΔE*ab, ΔE00 (in jnp).

Conventions and method
----------------------
* **Tables.** The colour-matching functions (CIE 1931 2° and CIE 1964 10° standard observers,
  1 nm, 360–830 nm) and the illuminant spectral power distributions (D65, D50, A, FL1–FL12, …)
  are colour-science's own tables (``colour.MSDS_CMFS``, ``colour.SDS_ILLUMINANTS``). They are
  read **once**, in numpy, when a :class:`ColourSpace` is built (outside jit): the module holds the
  weighting table ``W`` of shape ``(wl, 3)`` for the model's wavelength grid, so a call is one
  matrix product and every function below is jit-, vmap- and grad-compatible.

* **Integration (CIE 15:2004 §7.1, the "Integration" method of colour-science).** The tables are
  resampled **onto the data grid** (never the data onto the tables) with colour-science's own
  interpolators — Sprague (1880) for the 1 nm CMFs, linear for the illuminants, as in
  ``colour.SpectralDistribution.align`` — and the tristimulus values are the sums

  .. math::  X = k \sum_i R(\lambda_i) S(\lambda_i) \bar x(\lambda_i) \Delta\lambda_i, \qquad
             k = 100 / \sum_i S(\lambda_i) \bar y(\lambda_i) \Delta\lambda_i

  (so a perfect white has Y = 100). On a uniform grid :math:`\Delta\lambda_i` is the grid step
  (colour-science's rectangle rule); on a non-uniform grid it is the width of the cell around
  each node, :math:`(\lambda_{i+1} - \lambda_{i-1})/2`, with the end cells one interval wide.
  On a uniform grid this is *exactly* ``colour.sd_to_XYZ(R, cmfs, illuminant,
  method="Integration", shape=grid)`` (tests agree to 1e-12); colour-science's default method
  ("ASTM E308") uses ASTM E2022 weighting factors instead and differs from it by ~1e-3 in XYZ
  at 5 nm (the tests measure it).

  Beyond a table's own range: an illuminant is held at its end value (colour-science's constant
  extrapolation — D65 stops at 780 nm); the CMFs are taken as zero outside 360–830 nm.

* **Range.** The data grid must cover the visible range 380–780 nm (CIE 15:2004 §7.2). A grid
  that does not (e.g. 400–700 nm) raises :class:`LayerstackError` unless
  ``extrapolate="constant"`` is asked for: the grid is then extended, at its own end
  intervals, until it reaches 380 nm and 780 nm (the last added node may lie just beyond), and
  the spectrum is **held at its end values**
  there (the recommendation of CIE 15:2004 §7.2.2 and ASTM E308 §7.3.2); the extended nodes'
  weights are folded onto the end nodes, so the call is still one matrix product. This equals
  colour-science's integration of a spectrum that it extrapolates (constantly) onto the extended
  grid.

* **CIELAB** (CIE 15:2004 eq. 8.3–8.5, CIE 1976): relative to the white of the same illuminant and
  observer (the XYZ of a perfect reflector, Y_n = 100), with the linear segment below
  :math:`(6/29)^3`.

* **sRGB** (IEC 61966-2-1): XYZ/100 → (chromatic adaptation from the illuminant's white to D65,
  CAT02 by default, as colour-science's ``XYZ_to_sRGB``) → linear RGB with colour-science's
  sRGB matrix → optionally clipped to [0, 1] → optionally encoded with the sRGB transfer
  function (12.92 L below 0.0031308, 1.055 L^{1/2.4} − 0.055 above).

* **ΔE00** (CIE 142-2001; the equations as numbered by Sharma, Wu & Dalal, Color Res. Appl. 30,
  21–30 (2005), eqs. 1–22), with k_L = k_C = k_H = 1 by default.

Gradients: the square roots and atan2 of the CIELAB/ΔE formulas are non-differentiable at zero
chroma (neutral greys) and at zero colour difference. They are guarded
(:func:`~layerstack_jax._base.numerics.safe_sqrt`, :func:`~layerstack_jax._base.numerics.safe_atan2`) so
that gradients there are finite (the zero sub-gradient of the cone) instead of NaN; away from
those points the gradients are exact.
"""

from __future__ import annotations

import difflib
from typing import Optional

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._base.numerics import safe_atan2, safe_sqrt
from .._base.programs import public_program
from .._base.validate import LayerstackError, is_concrete

__all__ = [
    "ColourSpace",
    "OBSERVERS",
    "VISIBLE_RANGE_NM",
    "xyz_to_xyy",
    "xyz_to_lab",
    "delta_e_ab",
    "delta_e_2000",
    "srgb_encode",
]

#: The visible range the data grid must cover (CIE 15:2004 §7.2): two scalars ``(min, max)`` in nm.
VISIBLE_RANGE_NM = (380.0, 780.0)

#: Observer names accepted by :class:`ColourSpace` → colour-science's table name.
OBSERVERS = {
    "CIE 1931 2 Degree Standard Observer": "CIE 1931 2 Degree Standard Observer",
    "CIE 1964 10 Degree Standard Observer": "CIE 1964 10 Degree Standard Observer",
    "2": "CIE 1931 2 Degree Standard Observer",
    "2°": "CIE 1931 2 Degree Standard Observer",
    "1931": "CIE 1931 2 Degree Standard Observer",
    "10": "CIE 1964 10 Degree Standard Observer",
    "10°": "CIE 1964 10 Degree Standard Observer",
    "1964": "CIE 1964 10 Degree Standard Observer",
}

_EPSILON_LAB = (6.0 / 29.0) ** 3  # = 216/24389, CIE 15:2004 eq. 8.5
_SRGB_BREAK = 0.0031308  # IEC 61966-2-1 linear-segment limit


# ------------------------------------------------------------------ numpy, at construction
def _observer_table(observer: str):
    import colour

    name = OBSERVERS.get(str(observer).strip())
    if name is None:
        raise LayerstackError(
            f"unknown observer {observer!r}: use one of {sorted(set(OBSERVERS.values()))} "
            "(or the short names '2' / '10')"
        )
    return name, colour.MSDS_CMFS[name]


def _illuminant_table(illuminant):
    import colour

    if isinstance(illuminant, colour.SpectralDistribution):
        return illuminant.name, illuminant
    name = str(illuminant).strip()
    names = list(colour.SDS_ILLUMINANTS)
    if name in colour.SDS_ILLUMINANTS:
        return name, colour.SDS_ILLUMINANTS[name]
    alias = "FL" + name[1:] if name[:1].upper() == "F" and name[1:2].isdigit() else name.upper()
    if alias in colour.SDS_ILLUMINANTS:  # "F2" (CIE's name) → colour-science's "FL2"; "d65" → "D65"
        return alias, colour.SDS_ILLUMINANTS[alias]
    close = difflib.get_close_matches(name, names, n=4)
    hint = f" (did you mean {', '.join(map(repr, close))}?)" if close else ""
    raise LayerstackError(f"unknown illuminant {illuminant!r}{hint}; known: {', '.join(names[:20])}, …")


def _cell_widths(wl: np.ndarray) -> np.ndarray:
    """Δλ_i: the step on a uniform grid; (λ_{i+1} − λ_{i−1})/2 inside a non-uniform one, the
    end intervals at the ends (equal to the step when uniform: colour-science's rectangle rule)."""
    d = np.diff(wl)
    w = np.empty_like(wl)
    w[0], w[-1] = d[0], d[-1]
    w[1:-1] = 0.5 * (d[:-1] + d[1:])
    if np.allclose(d, d[0], rtol=1e-9, atol=0.0):
        w[:] = d[0]
    return w


def _extend(wl: np.ndarray, lo: float, hi: float):
    """Nodes below ``wl[0]`` (down to ``lo``) and above ``wl[-1]`` (up to ``hi``) at the grid's
    end intervals; returns (extended grid, number of nodes added below, above)."""
    tol = 1e-9
    d0, d1 = wl[1] - wl[0], wl[-1] - wl[-2]
    n_lo = int(np.ceil((wl[0] - lo) / d0 - tol)) if wl[0] > lo + tol else 0
    n_hi = int(np.ceil((hi - wl[-1]) / d1 - tol)) if wl[-1] < hi - tol else 0
    below = wl[0] - d0 * np.arange(n_lo, 0, -1)
    above = wl[-1] + d1 * np.arange(1, n_hi + 1)
    return np.concatenate([below, wl, above]), n_lo, n_hi


def _weighting_table(wl: np.ndarray, cmfs, illuminant) -> np.ndarray:
    """k S(λ_i) x̄(λ_i) Δλ_i on the grid ``wl``, shape (wl, 3), normalised so Σ W[:, 1] = 100."""
    lo, hi = cmfs.shape.start, cmfs.shape.end
    cmf = np.asarray(cmfs.copy()[wl], dtype=float)
    cmf[(wl < lo - 1e-9) | (wl > hi + 1e-9)] = 0.0
    S = np.asarray(illuminant.copy()[wl], dtype=float)
    w = S[:, None] * cmf * _cell_widths(wl)[:, None]
    return w * (100.0 / np.sum(w[:, 1]))


def _srgb_matrix(white_XYZ: np.ndarray, adaptation: Optional[str]) -> np.ndarray:
    """XYZ (Y of white = 1) → linear sRGB, chromatic adaptation from ``white_XYZ`` to sRGB's D65."""
    import colour

    space = colour.RGB_COLOURSPACES["sRGB"]
    M = np.asarray(space.matrix_XYZ_to_RGB, dtype=float)
    if adaptation is None:
        return M
    XYZ_w = white_XYZ / white_XYZ[1]
    XYZ_wr = colour.xy_to_XYZ(space.whitepoint)
    try:
        A = colour.adaptation.matrix_chromatic_adaptation_VonKries(XYZ_w, XYZ_wr, transform=adaptation)
    except (KeyError, ValueError) as e:
        raise LayerstackError(f"unknown chromatic adaptation {adaptation!r} ({e})") from None
    return M @ np.asarray(A, dtype=float)


# ----------------------------------------------------------------------------- the module
class ColourSpace(eqx.Module):
    """Colorimetry on a fixed wavelength grid: spectrum → XYZ → xyY / CIELAB / sRGB.

    Build once per grid (numpy, outside jit); call its methods inside jit/vmap/grad.

    Args:
        wavelength_nm: the data grid, nm, strictly increasing (uniform or not); must cover
            380–780 nm unless ``extrapolate="constant"``.
        observer: ``"CIE 1931 2 Degree Standard Observer"`` (default, also ``"2"``) or
            ``"CIE 1964 10 Degree Standard Observer"`` (``"10"``).
        illuminant: a colour-science illuminant name (``"D65"`` default, ``"D50"``, ``"A"``,
            ``"FL2"`` or CIE's ``"F2"``, …) or a ``colour.SpectralDistribution``.
        extrapolate: ``"error"`` (default): a grid not covering 380–780 nm raises;
            ``"constant"``: the spectrum is held at its end values down to 380 / up to 780 nm.
        adaptation: chromatic-adaptation transform to sRGB's D65 white for :meth:`sRGB`
            (colour-science name: ``"CAT02"`` default, ``"Bradford"``, ``"Von Kries"`` …) or
            ``None`` for none.

    Attributes:
        weights: ``(wl, 3)`` weighting table: ``XYZ = R @ weights``.
        white_XYZ: ``(3,)`` XYZ of the perfect reflecting diffuser (Y = 100).
        rgb_matrix: ``(3, 3)`` XYZ/100 → linear sRGB (adaptation included).
    """

    wavelength_nm: tuple = eqx.field(static=True)
    observer: str = eqx.field(static=True)
    illuminant: str = eqx.field(static=True)
    weights: Float[Array, "wl 3"]
    white_XYZ: Float[Array, "3"]
    rgb_matrix: Float[Array, "3 3"]

    def __init__(self, wavelength_nm, observer: str = "CIE 1931 2 Degree Standard Observer",
                 illuminant="D65", *, extrapolate: str = "error", adaptation: Optional[str] = "CAT02"):
        if not is_concrete(wavelength_nm):
            raise LayerstackError("ColourSpace: build it outside jit (its wavelength grid must be concrete)")
        wl = np.asarray(wavelength_nm, dtype=float)
        if wl.ndim != 1 or wl.size < 2 or not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0):
            raise LayerstackError("ColourSpace: wavelength_nm must be a strictly increasing 1-D grid (>= 2 points)")
        if extrapolate not in ("error", "constant"):
            raise LayerstackError(f"ColourSpace: extrapolate must be 'error' or 'constant', got {extrapolate!r}")
        lo, hi = VISIBLE_RANGE_NM
        if extrapolate == "error" and (wl[0] > lo + 1e-9 or wl[-1] < hi - 1e-9):
            raise LayerstackError(
                f"ColourSpace: wavelength_nm covers {wl[0]:g}–{wl[-1]:g} nm but colorimetry needs the visible "
                f"range {lo:g}–{hi:g} nm (CIE 15): extend the grid, or pass extrapolate='constant' to hold "
                "the spectrum at its end values outside the data"
            )
        obs_name, cmfs = _observer_table(observer)
        ill_name, sd = _illuminant_table(illuminant)
        grid, n_lo, n_hi = _extend(wl, lo, hi) if extrapolate == "constant" else (wl, 0, 0)
        W = _weighting_table(grid, cmfs, sd)
        # fold the extended nodes onto the end nodes (the spectrum is constant there)
        W_data = W[n_lo:n_lo + wl.size].copy()
        W_data[0] += W[:n_lo].sum(axis=0)
        W_data[-1] += W[n_lo + wl.size:].sum(axis=0)
        white = W_data.sum(axis=0)
        self.wavelength_nm = tuple(wl.tolist())
        self.observer = obs_name
        self.illuminant = ill_name
        self.weights = jnp.asarray(W_data)
        self.white_XYZ = jnp.asarray(white)
        self.rgb_matrix = jnp.asarray(_srgb_matrix(white, adaptation))

    @public_program
    def XYZ(self, reflectance: Float[ArrayLike, "*batch wl"]) -> Float[Array, "*batch 3"]:
        """Tristimulus values (Y = 100 for a perfect reflector) of reflectance/transmittance
        spectra sampled on the grid (last axis)."""
        R = jnp.asarray(reflectance)
        if R.shape[-1] != len(self.wavelength_nm):
            raise LayerstackError(
                f"ColourSpace.XYZ: spectra have {R.shape[-1]} wavelengths, the grid has {len(self.wavelength_nm)}"
            )
        return R @ self.weights

    @public_program
    def xyY(self, reflectance) -> Float[Array, "*batch 3"]:
        """Chromaticity x, y and luminance Y (black → the white's chromaticity)."""
        return xyz_to_xyy(self.XYZ(reflectance), self.white_XYZ)

    @public_program
    def Lab(self, reflectance) -> Float[Array, "*batch 3"]:
        """CIELAB L*, a*, b* relative to this illuminant's white."""
        return xyz_to_lab(self.XYZ(reflectance), self.white_XYZ)

    @public_program
    def sRGB(self, reflectance, *, encode: bool = True, clip: bool = False) -> Float[Array, "*batch 3"]:
        """sRGB in [0, 1]: linear (``encode=False``) or gamma-encoded (default); ``clip=True``
        clips the linear values to [0, 1] first (out-of-gamut colours)."""
        return self.XYZ_to_sRGB(self.XYZ(reflectance), encode=encode, clip=clip)

    @public_program
    def XYZ_to_sRGB(self, XYZ, *, encode: bool = True, clip: bool = False) -> Float[Array, "*batch 3"]:
        """sRGB from XYZ on the Y = 100 scale (see :meth:`sRGB`)."""
        rgb = (jnp.asarray(XYZ) / 100.0) @ self.rgb_matrix.T
        if clip:
            rgb = jnp.clip(rgb, 0.0, 1.0)
        return srgb_encode(rgb) if encode else rgb


# ------------------------------------------------------------------------- pure functions
@public_program
def xyz_to_xyy(XYZ: Float[ArrayLike, "*batch 3"], white_XYZ: Optional[ArrayLike] = None) -> Float[Array, "*batch 3"]:
    """x = X/(X+Y+Z), y = Y/(X+Y+Z), Y. For black (X+Y+Z = 0) x, y are those of ``white_XYZ``
    (colour-science's convention), or 0 if no white is given.

    ``XYZ``: ``(*batch, 3)`` on any scale; ``white_XYZ``: ``(3,)`` or None. Returns (x, y, Y)
    ``(*batch, 3)``: x, y dimensionless chromaticities, Y on the scale of the input.
    """
    XYZ = jnp.asarray(XYZ)
    s = jnp.sum(XYZ, axis=-1, keepdims=True)
    black = s == 0
    xy = XYZ[..., :2] / jnp.where(black, 1.0, s)
    if white_XYZ is not None:
        w = jnp.asarray(white_XYZ)
        xy = jnp.where(black, w[:2] / jnp.sum(w), xy)
    return jnp.concatenate([xy, XYZ[..., 1:2]], axis=-1)


def _lab_f(t):
    """CIE 1976 f(t): cube root above (6/29)^3, linear below (CIE 15:2004 eq. 8.5)."""
    cube = jnp.cbrt(jnp.maximum(t, _EPSILON_LAB))  # argument kept off the linear branch's t
    return jnp.where(t > _EPSILON_LAB, cube, t / (3.0 * (6.0 / 29.0) ** 2) + 4.0 / 29.0)


@public_program
def xyz_to_lab(XYZ: Float[ArrayLike, "*batch 3"], white_XYZ: Float[ArrayLike, "3"]) -> Float[Array, "*batch 3"]:
    """CIELAB (CIE 15:2004 eqs. 8.3–8.5): L* = 116 f(Y/Yn) − 16, a* = 500 [f(X/Xn) − f(Y/Yn)],
    b* = 200 [f(Y/Yn) − f(Z/Zn)]; XYZ and the white on the same scale (Y = 100 or Y = 1 for
    the white: only the ratios enter).

    ``XYZ``: ``(*batch, 3)``; ``white_XYZ``: ``(3,)``. Returns (L*, a*, b*) ``(*batch, 3)``,
    dimensionless (L* = 100 for the white).
    """
    f = _lab_f(jnp.asarray(XYZ) / jnp.asarray(white_XYZ))
    L = 116.0 * (f[..., 1] - 4.0 / 29.0)  # = 116 f - 16, and exactly 0 for black however products fuse
    a = 500.0 * (f[..., 0] - f[..., 1])
    b = 200.0 * (f[..., 1] - f[..., 2])
    return jnp.stack([L, a, b], axis=-1)


@public_program
def srgb_encode(rgb_linear):
    """sRGB transfer function (IEC 61966-2-1): 12.92 L for L <= 0.0031308, else
    1.055 L^(1/2.4) − 0.055 (negative values stay on the linear segment).

    ``rgb_linear``: linear sRGB, any shape (e.g. ``(*batch, 3)``), on the scale where white
    is 1 (dimensionless; values outside [0, 1] are not clipped). Returns the encoded values,
    same shape, same scale.
    """
    L = jnp.asarray(rgb_linear)
    power = 1.055 * jnp.power(jnp.maximum(L, _SRGB_BREAK), 1.0 / 2.4) - 0.055
    return jnp.where(L <= _SRGB_BREAK, 12.92 * L, power)


@public_program
def delta_e_ab(lab1: Float[ArrayLike, "*batch 3"], lab2: Float[ArrayLike, "*batch 3"]) -> Float[Array, "*batch"]:
    """CIE 1976 ΔE*ab: the Euclidean distance in CIELAB (zero gradient at ΔE = 0).

    ``lab1``, ``lab2``: CIELAB ``(*batch, 3)`` (broadcast against each other); returns
    ``(*batch)`` in CIELAB units (dimensionless).
    """
    d = jnp.asarray(lab1) - jnp.asarray(lab2)
    return safe_sqrt(jnp.sum(d * d, axis=-1))


@public_program
def delta_e_2000(lab1: Float[ArrayLike, "*batch 3"], lab2: Float[ArrayLike, "*batch 3"], *,
                 k_L: float = 1.0, k_C: float = 1.0, k_H: float = 1.0) -> Float[Array, "*batch"]:
    """CIEDE2000 colour difference ΔE00 (CIE 142-2001; eqs. 1–22 of Sharma, Wu & Dalal 2005).

    Hue angles in degrees in [0, 360); h' = 0 for a'=b=0 (eq. 7); Δh' = 0 and h̄' = h'1 + h'2
    when C'1 C'2 = 0 (eqs. 10, 14). Gradients are finite everywhere (neutral greys, identical
    colours), see the module notes.

    ``lab1``, ``lab2``: CIELAB ``(*batch, 3)`` (L*, a*, b*, broadcast against each other);
    returns ΔE00 shaped ``(*batch)``, in CIELAB units (dimensionless, ~1 = just noticeable).
    """
    lab1, lab2 = jnp.asarray(lab1), jnp.asarray(lab2)
    L1, a1, b1 = lab1[..., 0], lab1[..., 1], lab1[..., 2]
    L2, a2, b2 = lab2[..., 0], lab2[..., 1], lab2[..., 2]
    deg = jnp.pi / 180.0

    # eqs. 2–5: a' rescaled around the neutral axis, C', h'
    C_ab_mean = 0.5 * (safe_sqrt(a1**2 + b1**2) + safe_sqrt(a2**2 + b2**2))
    C7 = C_ab_mean**7
    G = 0.5 * (1.0 - safe_sqrt(C7 / (C7 + 25.0**7)))
    a1p, a2p = (1.0 + G) * a1, (1.0 + G) * a2
    C1p, C2p = safe_sqrt(a1p**2 + b1**2), safe_sqrt(a2p**2 + b2**2)
    h1p = jnp.mod(safe_atan2(b1, a1p) / deg, 360.0)
    h2p = jnp.mod(safe_atan2(b2, a2p) / deg, 360.0)

    # eqs. 8–12: differences
    chromatic = (C1p * C2p) != 0
    dLp = L2 - L1
    dCp = C2p - C1p
    dh = h2p - h1p
    dhp = jnp.where(dh > 180.0, dh - 360.0, jnp.where(dh < -180.0, dh + 360.0, dh))
    dhp = jnp.where(chromatic, dhp, 0.0)
    dHp = 2.0 * safe_sqrt(C1p * C2p) * jnp.sin(0.5 * dhp * deg)

    # eqs. 13–14: means
    Lp_mean = 0.5 * (L1 + L2)
    Cp_mean = 0.5 * (C1p + C2p)
    h_sum = h1p + h2p
    far = jnp.abs(h1p - h2p) > 180.0
    hp_mean = jnp.where(far, jnp.where(h_sum < 360.0, 0.5 * (h_sum + 360.0), 0.5 * (h_sum - 360.0)), 0.5 * h_sum)
    hp_mean = jnp.where(chromatic, hp_mean, h_sum)

    # eqs. 15–21: weighting functions and rotation term
    T = (1.0 - 0.17 * jnp.cos((hp_mean - 30.0) * deg) + 0.24 * jnp.cos(2.0 * hp_mean * deg)
         + 0.32 * jnp.cos((3.0 * hp_mean + 6.0) * deg) - 0.20 * jnp.cos((4.0 * hp_mean - 63.0) * deg))
    d_theta = 30.0 * jnp.exp(-(((hp_mean - 275.0) / 25.0) ** 2))
    Cp7 = Cp_mean**7
    R_C = 2.0 * safe_sqrt(Cp7 / (Cp7 + 25.0**7))
    L50 = (Lp_mean - 50.0) ** 2
    S_L = 1.0 + 0.015 * L50 / jnp.sqrt(20.0 + L50)
    S_C = 1.0 + 0.045 * Cp_mean
    S_H = 1.0 + 0.015 * Cp_mean * T
    R_T = -jnp.sin(2.0 * d_theta * deg) * R_C

    # eq. 22
    tL, tC, tH = dLp / (k_L * S_L), dCp / (k_C * S_C), dHp / (k_H * S_H)
    return safe_sqrt(tL**2 + tC**2 + tH**2 + R_T * tC * tH)
