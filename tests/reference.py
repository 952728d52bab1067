"""Independent reference implementations for the layerstack tests.

Plain numpy / scipy / ``tmm`` (0.2) only, float64 throughout.  Nothing here imports
``layerstack_jax``: these functions are the yardstick the library is measured against.

Equation numbers refer to L. Simonot, M. Hébert, R. D. Hersch, "Extension of the
Williams-Clapper model to stacked nondiffusing colored coatings with different
refractive indices", JOSA A 23, 1432 (2006) (``seeds/simonot-hebert-hersch-2006-...``).

Conventions
-----------
* Angles in radians, lengths (wavelength ``lam``, thicknesses) in the same unit (nm).
* ``pol`` is ``"s"``, ``"p"`` or ``"u"`` (natural / unpolarised light = mean of s and p of the
  *whole-stack* intensity, eqs. 33, 39, 57, 58 -- never per interface).
* ``n_list, d_list, c_list`` follow the tmm convention: the first and last entries are the
  semi-infinite outer media (``d = inf``, ``c = "i"``); ``c`` is ``"c"`` (coherent thin film)
  or ``"i"`` (incoherent thick layer); complex indices ``n + ik`` with ``k >= 0`` absorb
  (tmm uses the exp(-iwt) convention).
* Hemispherical integrals are written in mu = sin^2(theta) of the integration medium:
  sin(2 theta) d theta = d mu, so eq. 18 reads r = int_0^1 R(mu) d mu.

tmm quirks handled here (see ``inc_stack_R_T``): tmm divides by the interface transmittance
in its incoherent transfer matrix and uses the *growing* arcsin branch in evanescent
incoherent layers, so total internal reflection (TIR) at or inside an incoherent part of the
stack is evaluated here by splitting the stack at the first evanescent incoherent medium.
"""

from __future__ import annotations

import functools
import math
import warnings
from typing import Callable, Sequence

import numpy as np
import tmm
from scipy import integrate

__all__ = [
    "fresnel_natural_R",
    "fresnel_natural_T",
    "diffuse_reflectance_interface",
    "diffuse_reflectance_interface_closed_form",
    "diffuse_interface_closed",
    "hemispherical_integral",
    "critical_mus",
    "coh_stack_R_T",
    "inc_stack_R_T",
    "tmm_is_clamped",
    "first_evanescent_incoherent",
    "diffuse_stack_reference",
    "beer_stack_R_T",
    "diffuse_beer_stack",
    "williams_clapper_integrals",
    "williams_clapper_factor",
    "shore_spoonhower",
    "saunderson_sphere",
    "saunderson_invert",
    "saunderson_radiance",
    "saunderson_radiance_invert",
    "background_sphere",
    "background_radiance_factor",
    "JUDD_R_EXT_15",
    "JUDD_R_INT_15",
    "R_INT_15_EXACT",
    "TMM_P_FLOOR",
    "TMM_DELTA_IMAG_CAP",
]

#: Judd (1942) printed values for n = 1.5 (external / internal diffuse reflectance).
JUDD_R_EXT_15 = 0.0918
JUDD_R_INT_15 = 0.5963
#: PHYSICS.md value of the internal diffuse reflectance of glass, n = 1.5.
R_INT_15_EXACT = 0.596345759708

#: tmm.inc_tmm floors the single-pass intensity attenuation P of every interior incoherent
#: layer at this value (tmm_core.py, ``if P_list[i] < 1e-30: P_list[i] = 1e-30``).
TMM_P_FLOOR = 1e-30
#: tmm.coh_tmm caps Im(delta) (one-pass phase of an interior coherent layer) at 35, i.e. a
#: single-pass intensity transmission floor exp(-70) ~ 4e-31.
TMM_DELTA_IMAG_CAP = 35.0

_QUAD_EPSABS = 1e-15
_QUAD_EPSREL = 1e-14
_QUAD_LIMIT = 500


# --------------------------------------------------------------------------------------
# Fresnel, real indices
# --------------------------------------------------------------------------------------
def _fresnel_R_mu(n_from: float, n_to: float, mu, one_minus_mu=None):
    """R_s, R_p, R_nat for real indices as functions of mu = sin^2(theta) in ``n_from``.

    ``one_minus_mu`` (= cos^2 theta) may be passed to keep accuracy near grazing incidence.
    """
    n1 = float(n_from)
    n2 = float(n_to)
    mu = np.asarray(mu, dtype=float)
    c1sq = 1.0 - mu if one_minus_mu is None else np.asarray(one_minus_mu, dtype=float)
    c1 = np.sqrt(np.clip(c1sq, 0.0, None))
    if n1 == n2:
        z = np.zeros(np.broadcast(mu, c1).shape)
        return z, z.copy(), z.copy()
    m2 = (n1 / n2) ** 2
    c2sq = 1.0 - m2 * mu  # cos^2 of the refracted angle
    tir = c2sq <= 0.0
    c2 = np.sqrt(np.clip(c2sq, 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (n1 * c1 - n2 * c2) / (n1 * c1 + n2 * c2)
        rp = (n2 * c1 - n1 * c2) / (n2 * c1 + n1 * c2)
    Rs = np.where(tir, 1.0, rs * rs)
    Rp = np.where(tir, 1.0, rp * rp)
    return Rs, Rp, 0.5 * (Rs + Rp)


def fresnel_natural_R(n_from: float, n_to: float, theta):
    """Fresnel intensity reflectances of a plane interface between real indices.

    Eqs. (2) (p, parallel) and (3) (s, perpendicular) of Simonot et al., written in the
    equivalent amplitude form r_s = (n1 cos t1 - n2 cos t2)/(n1 cos t1 + n2 cos t2),
    r_p = (n2 cos t1 - n1 cos t2)/(n2 cos t1 + n1 cos t2) (no 0/0 at normal incidence), with
    Snell's law eq. (1); natural light is the mean, eq. (6).  Beyond the critical angle
    (n_from > n_to, sin t1 >= n_to/n_from) the reflectance is exactly 1 (TIR).

    Parameters: ``n_from`` index of the incidence medium, ``n_to`` of the other medium (both
    real), ``theta`` incidence angle(s) in radians in ``n_from`` (array-like, broadcast).

    Returns ``(R_s, R_p, R_nat)`` float64 arrays of the shape of ``theta``.  The transmittance
    is 1 - R for each polarisation (eq. 7); see :func:`fresnel_natural_T`.
    """
    theta = np.asarray(theta, dtype=float)
    s = np.sin(theta)
    c = np.cos(theta)
    return _fresnel_R_mu(n_from, n_to, s * s, c * c)


def fresnel_natural_T(n_from: float, n_to: float, theta):
    """Fresnel intensity transmittances T = 1 - R (eq. 7), returned as (T_s, T_p, T_nat)."""
    Rs, Rp, Rn = fresnel_natural_R(n_from, n_to, theta)
    return 1.0 - Rs, 1.0 - Rp, 1.0 - Rn


# --------------------------------------------------------------------------------------
# Hemispherical integration in mu = sin^2 theta
# --------------------------------------------------------------------------------------
def critical_mus(n_from: float, n_others: Sequence[complex]) -> list[float]:
    """Sorted critical points mu_c = (Re n_j / n_from)^2 in (0, 1) for Re n_j < n_from."""
    n_from = float(np.real(n_from))
    out = set()
    for nj in n_others:
        nr = float(np.real(nj))
        if 0.0 < nr < n_from:
            mc = (nr / n_from) ** 2
            if 0.0 < mc < 1.0:
                out.add(mc)
    return sorted(out)


def hemispherical_integral(
    f: Callable[[float], float],
    breaks: Sequence[float] = (),
    *,
    epsabs: float = _QUAD_EPSABS,
    epsrel: float = _QUAD_EPSREL,
    limit: int = _QUAD_LIMIT,
    return_error: bool = False,
):
    """int_0^1 f(mu) d mu (eqs. 18, 47, 49, 62, 63 in the variable mu = sin^2 theta).

    The interval is split at ``breaks`` (critical points) and each segment [lo, hi] is mapped
    by mu = lo + (hi - lo) sin^2(pi v / 2), v in [0, 1].  Square-root singularities at either
    end of a segment (sqrt(mu_c - mu) below a critical angle, sqrt(1 - mu) at grazing
    incidence, sqrt(mu - mu_c) of frustrated TIR) become analytic in v, so
    ``scipy.integrate.quad`` (Gauss-Kronrod 21, adaptive) reaches ~1e-15.

    ``f`` is called as ``f(mu)`` with a Python float.  Returns the integral (and the summed
    quad error estimate if ``return_error``).
    """
    pts = [0.0] + sorted(b for b in set(float(b) for b in breaks) if 0.0 < b < 1.0) + [1.0]
    total = 0.0
    err = 0.0
    for lo, hi in zip(pts[:-1], pts[1:]):
        w = hi - lo

        def g(v, lo=lo, w=w):
            sv = math.sin(0.5 * math.pi * v)
            mu = lo + w * sv * sv
            return f(mu) * w * 0.5 * math.pi * math.sin(math.pi * v)

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", integrate.IntegrationWarning)
            val, e = integrate.quad(g, 0.0, 1.0, epsabs=epsabs, epsrel=epsrel, limit=limit)
        total += val
        err += e
    return (total, err) if return_error else total


# --------------------------------------------------------------------------------------
# Diffuse reflectance of one interface
# --------------------------------------------------------------------------------------
def diffuse_reflectance_interface(n_from: float, n_to: float, variable: str = "mu") -> float:
    """Diffuse (Lambertian, natural light) reflectance of a plane interface, eq. (18).

    r_{from,to} = int_0^{pi/2} R(theta) sin 2theta d theta, R the natural-light Fresnel
    reflectance (eq. 6) in the incidence medium ``n_from``.  Real indices.

    ``variable="mu"`` (default): integrated in mu = sin^2 theta (d mu = sin 2theta d theta)
    with the critical point mu_c = (n_to/n_from)^2 as a breakpoint and the end-clustering map
    of :func:`hemispherical_integral`; accurate to ~1e-15 (checked against the closed form and
    against ``variable="theta"``).

    ``variable="theta"``: eq. (18) literally, ``quad`` in theta with the critical angle as a
    breakpoint (``points=``), epsabs = epsrel = 1e-14; accurate to ~1e-14.

    The transmittance is t = 1 - r (eq. 19).
    """
    n1 = float(n_from)
    n2 = float(n_to)
    if n1 == n2:
        return 0.0
    if variable == "mu":
        breaks = [(n2 / n1) ** 2] if n2 < n1 else []
        return hemispherical_integral(lambda mu: float(_fresnel_R_mu(n1, n2, mu)[2]), breaks)
    if variable == "theta":

        def g(th):
            return float(fresnel_natural_R(n1, n2, th)[2]) * math.sin(2.0 * th)

        pts = [math.asin(n2 / n1)] if n2 < n1 else None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", integrate.IntegrationWarning)
            val, _ = integrate.quad(
                g, 0.0, 0.5 * math.pi, points=pts, epsabs=1e-14, epsrel=1e-14, limit=_QUAD_LIMIT
            )
        return val
    raise ValueError("variable must be 'mu' or 'theta'")


def diffuse_reflectance_interface_closed_form(m: float) -> tuple[float, float]:
    """Closed-form diffuse reflectances of a dielectric interface of relative index m > 1.

    External (light from the low-index side), Stern (1964) / Walsh / Judd (1942):

        r_e = 1/2 + (m-1)(3m+1) / (6 (m+1)^2)
              + m^2 (m^2-1)^2 / (m^2+1)^3 * ln((m-1)/(m+1))
              - 2 m^3 (m^2+2m-1) / ((m^2+1)(m^4-1))
              + 8 m^4 (m^4+1) / ((m^2+1)(m^4-1)^2) * ln m

    i.e. eq. (18) integrated analytically; internal (light from the high-index side), from
    energy conservation and reciprocity (eqs. 8-10, 19): r_i = 1 - (1 - r_e) / m^2.

    Returns ``(r_e, r_i)``.  m = 1 gives (0, 0).  Agrees with the quad integral of eq. (18)
    to ~1e-15 for m in [1.1, 3] (tests/test_reference.py).  For m = 1.5:
    r_e = 0.091760..., r_i = 0.596345759708... (Judd: 0.0918, 0.5963).
    """
    m = float(m)
    if m == 1.0:
        return 0.0, 0.0
    if m < 1.0:
        raise ValueError("m must be >= 1 (relative index of the denser medium)")
    m2 = m * m
    m4 = m2 * m2
    r_e = (
        0.5
        + (m - 1.0) * (3.0 * m + 1.0) / (6.0 * (m + 1.0) ** 2)
        + m2 * (m2 - 1.0) ** 2 / (m2 + 1.0) ** 3 * math.log((m - 1.0) / (m + 1.0))
        - 2.0 * m * m2 * (m2 + 2.0 * m - 1.0) / ((m2 + 1.0) * (m4 - 1.0))
        + 8.0 * m4 * (m4 + 1.0) / ((m2 + 1.0) * (m4 - 1.0) ** 2) * math.log(m)
    )
    r_i = 1.0 - (1.0 - r_e) / m2
    return r_e, r_i


def diffuse_interface_closed(n_from: float, n_to: float) -> float:
    """Closed-form diffuse reflectance of the interface n_from -> n_to (either direction)."""
    if n_to >= n_from:
        return diffuse_reflectance_interface_closed_form(n_to / n_from)[0]
    return diffuse_reflectance_interface_closed_form(n_from / n_to)[1]


# --------------------------------------------------------------------------------------
# tmm wrappers
# --------------------------------------------------------------------------------------
def _as_lists(n_list, d_list, c_list=None):
    n = np.array(n_list, dtype=complex)
    d = np.array(d_list, dtype=float)
    if n.ndim != 1 or d.shape != n.shape:
        raise ValueError("n_list and d_list must be 1-D of equal length")
    if not (np.isinf(d[0]) and np.isinf(d[-1])):
        raise ValueError("d_list must start and end with inf")
    if c_list is None:
        return n, d
    c = list(c_list)
    if len(c) != n.size or c[0] != "i" or c[-1] != "i":
        raise ValueError("c_list must match n_list and start/end with 'i'")
    return n, d, c


def coh_stack_R_T(pol: str, n_list, d_list, theta0: float, lam: float) -> tuple[float, float]:
    """Fully coherent stack: thin wrapper on ``tmm.coh_tmm`` (Hirayama eqs. 1-6 equivalent).

    ``pol`` in {"s", "p", "u"} ("u": mean of s and p).  ``n_list``/``d_list`` in tmm form
    (outer media semi-infinite, d = inf).  ``theta0`` in the (real) incidence medium,
    ``lam`` vacuum wavelength in the unit of ``d_list``.

    Returns ``(R, T)``: R = |r|^2, T = Re(n_N cos t_N)/Re(n_0 cos t_0) |t|^2 (s; p uses
    conj(cos)) -- the Poynting flux *entering* the exit medium.  tmm reports that flux also
    for an absorbing exit medium (it is not 0 there), and T = ~1e-16 (not exactly 0) when the
    exit medium is evanescent (TIR).  Interior layers with Im(delta) > 35 are silently capped
    (see :func:`tmm_is_clamped`).
    """
    n, d = _as_lists(n_list, d_list)
    if pol == "u":
        Rs, Ts = coh_stack_R_T("s", n, d, theta0, lam)
        Rp, Tp = coh_stack_R_T("p", n, d, theta0, lam)
        return 0.5 * (Rs + Rp), 0.5 * (Ts + Tp)
    out = tmm.coh_tmm(pol, n, d, float(theta0), float(lam))
    return float(out["R"]), float(out["T"])


def first_evanescent_incoherent(n_list, c_list, theta0: float) -> int | None:
    """Index of the first incoherent medium (k >= 1) in which the wave is evanescent.

    That is a medium with a real index n_k <= s = n_0 sin(theta0) (total internal reflection
    at its entrance).  Returns None when every incoherent medium propagates.
    """
    n0 = float(np.real(n_list[0]))
    s = n0 * math.sin(theta0)
    for k in range(1, len(n_list)):
        if c_list[k] != "i":
            continue
        nk = complex(n_list[k])
        if nk.imag == 0.0 and s >= nk.real:
            return k
    return None


def _R_into_evanescent(pol, n, d, c, p, k, th, lam):
    """Reflectance seen from incoherent medium p towards an evanescent incoherent medium k.

    Everything between p and k is coherent (possibly nothing): coh_tmm of that packet with
    medium k as exit handles frustrated TIR.  For a bare interface with real n_p the exact
    result 1 is returned (tmm would give 1 - O(1e-16) through cos(pi/2 + ix) rounding).
    """
    if k == p + 1:
        np_ = complex(n[p])
        if np_.imag == 0.0:
            return 1.0
        s = float(np.real(n[0] * np.sin(th[0])))
        a = np.sqrt(np_ * np_ - s * s + 0j)  # n_p cos t_p, Im >= 0 (principal branch)
        b = 1j * math.sqrt(max(s * s - float(np.real(n[k])) ** 2, 0.0))  # n_k cos t_k
        nk = float(np.real(n[k]))
        if pol == "s":
            r = (a - b) / (a + b)
        else:
            ct_p = a / np_
            ct_k = b / nk
            r = (nk * ct_p - np_ * ct_k) / (nk * ct_p + np_ * ct_k)
        return float(abs(r) ** 2)
    sub_n = n[p : k + 1]
    sub_d = np.concatenate(([np.inf], d[p + 1 : k], [np.inf]))
    return float(tmm.coh_tmm(pol, sub_n, sub_d, th[p], lam)["R"])


def _inc_pol(pol, n, d, c, theta0, lam):
    if theta0 >= 0.5 * math.pi:
        return 1.0, 0.0
    k = first_evanescent_incoherent(n, c, theta0)
    if k is None:
        out = tmm.inc_tmm(pol, n, d, c, float(theta0), float(lam))
        return float(out["R"]), float(out["T"])
    # Split at the first evanescent incoherent medium k: nothing crosses it (T = 0, exactly;
    # tunnelling through a *thick* evanescent layer is exp(-huge) and is dropped).
    th = tmm.list_snell(n, float(theta0))
    p = max(i for i in range(k) if c[i] == "i")  # last incoherent medium before k
    R_last = _R_into_evanescent(pol, n, d, c, p, k, th, lam)
    if p == 0:
        return R_last, 0.0
    return _compose_front(pol, n, d, c, p, R_last, theta0, lam), 0.0


def _compose_front(pol, n, d, c, p, R_last, theta0, lam):
    """R of a stack whose part behind incoherent medium p (1 <= p) reflects R_last.

    Front part 0..p (p as exit medium): forward R_f, T_f and backward R_b, T_b from
    tmm.inc_tmm; one more incoherent round trip in layer p with tmm's single-pass attenuation
    P (same 1e-30 floor):  R = R_f + T_f T_b P^2 R_last / (1 - R_b P^2 R_last)
    -- the algebra of tmm's incoherent L matrices, i.e. Simonot eq. (59).
    """
    th = tmm.list_snell(n, float(theta0))
    fn = n[: p + 1]
    fd = np.concatenate((d[:p], [np.inf]))
    fc = list(c[:p]) + ["i"]
    f = tmm.inc_tmm(pol, fn, fd, fc, float(theta0), float(lam))
    b = tmm.inc_tmm(pol, fn[::-1], fd[::-1], fc[::-1], th[p], float(lam))
    P = math.exp(-4.0 * math.pi * d[p] * float(np.imag(n[p] * np.cos(th[p]))) / lam)
    P = max(P, TMM_P_FLOOR)
    R_f, T_f, R_b, T_b = float(f["R"]), float(f["T"]), float(b["R"]), float(b["T"])
    loop = P * P * R_last
    return R_f + T_f * T_b * loop / (1.0 - R_b * loop)


def inc_stack_R_T(
    pol: str, n_list, d_list, c_list, theta0: float, lam: float
) -> tuple[float, float]:
    """Mixed coherent/incoherent stack: wrapper on ``tmm.inc_tmm``.

    Physics: Simonot eqs. (21)-(44) (one bounded layer) and (50)-(61) (k layers) for the
    incoherent layers, with runs of coherent films acting as one interface with intensity
    R_f, R_b, T (coh_tmm inside inc_tmm).  First and last media incoherent, semi-infinite and
    (for meaningful normalisation) real.

    ``pol`` in {"s", "p", "u"}; "u" (natural light) is the mean of the *whole-stack* s and p
    values (eqs. 33, 39, 57, 58).  Returns ``(R, T)`` floats, T being the flux entering the
    exit medium (see :func:`coh_stack_R_T`).

    TIR: tmm.inc_tmm cannot evaluate a stack in which an incoherent medium k >= 1 is
    evanescent (real n_k <= n_0 sin theta0): at the exit medium it returns T ~ 1e-16 instead
    of 0; inside the stack it uses the growing branch of arcsin, P = exp(+...) > 1 (not caught
    by its 1e-30 floor) and returns negative R/T or NaN.  Here such a stack is split at the
    first evanescent incoherent medium k: T = 0 exactly, and R is composed from tmm.inc_tmm of
    the front part (forward and backward) and the reflectance towards k (coh_tmm for a
    coherent packet before k, so frustrated TIR in thin films is kept; exactly 1 for a bare
    real interface).  theta0 >= pi/2 returns (1, 0).
    """
    n, d, c = _as_lists(n_list, d_list, c_list)
    if pol == "u":
        Rs, Ts = _inc_pol("s", n, d, c, theta0, lam)
        Rp, Tp = _inc_pol("p", n, d, c, theta0, lam)
        return 0.5 * (Rs + Rp), 0.5 * (Ts + Tp)
    if pol not in ("s", "p"):
        raise ValueError("pol must be 's', 'p' or 'u'")
    return _inc_pol(pol, n, d, c, theta0, lam)


def tmm_is_clamped(n_list, d_list, c_list, theta0: float, lam: float) -> bool:
    """True if one of tmm's opacity clamps is active for this stack and angle.

    * inc_tmm: single-pass attenuation of an interior incoherent layer
      P = exp(-4 pi d Im(n cos t)/lam) < 1e-30 is replaced by 1e-30 (silently).
    * coh_tmm: an interior coherent layer with Im(delta) = Im(2 pi n cos t d / lam) > 35 gets
      Im(delta) = 35 (one-pass intensity e^-70 ~ 4e-31; prints a warning once per session).

    Only layers in front of the first evanescent incoherent medium are checked (the ones
    :func:`inc_stack_R_T` hands to tmm).  A clamp changes T (and R at the P^2 level) only where
    the true value is below ~1e-30, but relative comparisons of T (log T, optical density)
    must skip such cases.  ``c_list=None`` means all interior layers coherent (coh_tmm).
    """
    n = np.array(n_list, dtype=complex)
    d = np.array(d_list, dtype=float)
    c = ["i"] + ["c"] * (n.size - 2) + ["i"] if c_list is None else list(c_list)
    th = tmm.list_snell(n, float(theta0))
    k = first_evanescent_incoherent(n, c, theta0) if c_list is not None else None
    stop = n.size - 1 if k is None else k
    for i in range(1, stop):
        ncos = n[i] * np.cos(th[i])
        if c[i] == "i":
            if d[i] > 0 and -4.0 * math.pi * d[i] * float(np.imag(ncos)) / lam < math.log(
                TMM_P_FLOOR
            ):
                return True
        else:
            if 2.0 * math.pi * d[i] * float(np.imag(ncos)) / lam > TMM_DELTA_IMAG_CAP:
                return True
    return False


# --------------------------------------------------------------------------------------
# Hemispherical (diffuse) reflectance / transmittance of a stack
# --------------------------------------------------------------------------------------
def diffuse_stack_reference(
    n_list, d_list, c_list, lam: float, side: str = "front", *, return_error: bool = False
) -> tuple[float, float]:
    """Diffuse reflectance and transmittance of a stack for Lambertian natural light.

    Eqs. (62) r = int_0^{pi/2} R(theta) sin 2theta d theta and (63) (same with T), with
    R, T the natural-light (mean of s and p, eqs. 57-58) full-stack values per angle from
    :func:`inc_stack_R_T` (tmm.inc_tmm; coherent 'c' and incoherent 'i' layers; TIR split).

    Integrated by ``scipy.integrate.quad`` in mu = sin^2 theta of the incidence medium, with
    breakpoints at every critical point mu_c = (Re n_j / n_from)^2 of every medium j with
    Re n_j < n_from (thick and thin) and the end-clustering map of
    :func:`hemispherical_integral` (epsabs 1e-15, epsrel 1e-14).

    ``side="front"``: light from ``n_list[0]``; ``side="back"``: from ``n_list[-1]`` (lists
    reversed), e.g. r_{k+1..0}, t_{k+1..0} of eq. (78).  Outer media must be real.
    Returns ``(r, t)`` (and the summed quad error estimates if ``return_error``).
    """
    n, d, c = _as_lists(n_list, d_list, c_list)
    if side == "back":
        n, d, c = n[::-1].copy(), d[::-1].copy(), c[::-1]
    elif side != "front":
        raise ValueError("side must be 'front' or 'back'")
    if n[0].imag != 0.0 or n[-1].imag != 0.0:
        raise ValueError("outer media must be real")
    n0 = float(n[0].real)
    breaks = critical_mus(n0, n[1:])
    cache: dict[float, tuple[float, float]] = {}

    def RT(mu):
        val = cache.get(mu)
        if val is None:
            th = math.asin(math.sqrt(min(max(mu, 0.0), 1.0)))
            val = inc_stack_R_T("u", n, d, c, th, lam)
            cache[mu] = val
        return val

    r, er = hemispherical_integral(lambda mu: RT(mu)[0], breaks, return_error=True)
    t, et = hemispherical_integral(lambda mu: RT(mu)[1], breaks, return_error=True)
    return (r, t, er, et) if return_error else (r, t)


# --------------------------------------------------------------------------------------
# Independent incoherent (Beer) recursion, real indices -- no tmm
# --------------------------------------------------------------------------------------
def beer_stack_R_T(pol: str, n_list, alpha_h_list, theta0: float, *, reverse: bool = False):
    """Stack of incoherent layers with real indices and Beer attenuation, no tmm.

    Simonot eqs. (30), (37), (40), (42) for one bounded layer and the adding rule (59)-(60)
    for k layers, per polarisation, with the backward reflectance R_{k..0} carried along;
    natural light = mean of the final s and p values (eqs. 57-58).

    ``n_list``: real indices n_0 .. n_{K+1} (outer media included); ``alpha_h_list``: alpha*h
    for each of the K interior layers (so the single-pass transmittance is
    t_k = exp(-alpha_k h_k / cos theta_k), eqs. 23, 56, 61).  ``theta0`` in medium 0;
    ``reverse=True`` illuminates from the last medium (``theta0`` then is in n_{K+1}).

    Returns ``(R, T)`` for pol "s", "p" or "u".  TIR (R = 1, T = 0 at an interface) needs no
    special case: the recursion has no division by T.
    """
    n = [float(x) for x in n_list]
    ah = [float(x) for x in alpha_h_list]
    if len(ah) != len(n) - 2:
        raise ValueError("alpha_h_list needs one entry per interior layer")
    if reverse:
        n = n[::-1]
        ah = ah[::-1]
    if pol == "u":
        Rs, Ts = beer_stack_R_T("s", n, ah, theta0)
        Rp, Tp = beer_stack_R_T("p", n, ah, theta0)
        return 0.5 * (Rs + Rp), 0.5 * (Ts + Tp)
    idx = 0 if pol == "s" else 1
    s = n[0] * math.sin(theta0)
    # interface 0|1
    mu0 = math.sin(theta0) ** 2
    R = _fresnel_R_mu(n[0], n[1], mu0, math.cos(theta0) ** 2)[idx]
    Rf = float(R)
    Rb = Rf  # eq. (8): R_10(theta_1) = R_01(theta_0)
    T = 1.0 - Rf
    for j in range(1, len(n) - 1):
        if T == 0.0:
            return Rf, 0.0
        mu_j = (s / n[j]) ** 2
        cj = math.sqrt(max(1.0 - mu_j, 0.0))
        tj = math.exp(-ah[j - 1] / cj) if cj > 0 else 0.0
        Rn = float(_fresnel_R_mu(n[j], n[j + 1], mu_j, 1.0 - mu_j)[idx])
        Tn = 1.0 - Rn
        denom = 1.0 - Rb * Rn * tj * tj
        Rf_new = Rf + T * T * Rn * tj * tj / denom  # eq. (59)
        T_new = T * Tn * tj / denom  # eq. (60)
        Rb_new = Rn + Tn * Tn * Rb * tj * tj / denom  # eq. (40) with the bounded stack
        Rf, Rb, T = Rf_new, Rb_new, T_new
    return Rf, T


def diffuse_beer_stack(n_list, alpha_h_list, side: str = "front") -> tuple[float, float]:
    """Eqs. (62)-(63) for :func:`beer_stack_R_T` (real indices, Beer layers), no tmm.

    Same quadrature as :func:`diffuse_stack_reference`.  Returns ``(r, t)``.
    """
    n = [float(x) for x in n_list]
    ah = [float(x) for x in alpha_h_list]
    if side == "back":
        n, ah = n[::-1], ah[::-1]
    breaks = critical_mus(n[0], n[1:])
    cache: dict[float, tuple[float, float]] = {}

    def RT(mu):
        val = cache.get(mu)
        if val is None:
            val = beer_stack_R_T("u", n, ah, math.asin(math.sqrt(min(max(mu, 0.0), 1.0))))
            cache[mu] = val
        return val

    r = hemispherical_integral(lambda mu: RT(mu)[0], breaks)
    t = hemispherical_integral(lambda mu: RT(mu)[1], breaks)
    return r, t


# --------------------------------------------------------------------------------------
# Williams-Clapper / Shore-Spoonhower (n1 = n2), closed-form Fresnel, no tmm
# --------------------------------------------------------------------------------------
def williams_clapper_integrals(n0: float, n1: float, alpha_h: float) -> tuple[float, float]:
    """r_110 (eq. 80) and t_110 (eq. 81) (memoised on the float arguments).

    r_110 = int_0^{pi/2} R_10(theta) t_1(theta)^2 sin 2theta d theta,
    t_110 = int_0^{pi/2} T_10(theta) t_1(theta) sin 2theta d theta,
    theta the angle in the layer (index n1, = background index), t_1 = exp(-alpha h / cos
    theta) (eq. 23), R_10 natural-light Fresnel from n1 to n0 (eq. 6), T_10 = 1 - R_10.
    Integrated in mu = sin^2 theta with the critical point (n0/n1)^2 as breakpoint.
    """
    return _wc_integrals(float(n0), float(n1), float(alpha_h))


@functools.lru_cache(maxsize=256)
def _wc_integrals(n0: float, n1: float, ah: float) -> tuple[float, float]:
    breaks = [(n0 / n1) ** 2] if n0 < n1 else []

    def att(mu):
        c = math.sqrt(max(1.0 - mu, 0.0))
        if ah == 0.0:
            return 1.0
        return math.exp(-ah / c) if c > 0.0 else 0.0

    def fr(mu):
        return float(_fresnel_R_mu(n1, n0, mu)[2]) * att(mu) ** 2

    def ft(mu):
        return (1.0 - float(_fresnel_R_mu(n1, n0, mu)[2])) * att(mu)

    return hemispherical_integral(fr, breaks), hemispherical_integral(ft, breaks)


def _T01_t1(n0, n1, alpha_h, theta0):
    theta0 = np.asarray(theta0, dtype=float)
    T01 = 1.0 - fresnel_natural_R(n0, n1, theta0)[2]
    mu1 = (n0 * np.sin(theta0) / n1) ** 2
    c1 = np.sqrt(np.clip(1.0 - mu1, 0.0, None))
    with np.errstate(divide="ignore"):
        t1 = np.where(c1 > 0, np.exp(-float(alpha_h) / np.where(c1 > 0, c1, 1.0)), 0.0)
    if alpha_h == 0:
        t1 = np.where(mu1 < 1.0, 1.0, 0.0)
    return T01, t1


def williams_clapper_factor(n0, n1, alpha_h, rho_g, theta0, theta0p):
    """Williams-Clapper reflectance factor, eq. (82) (radiance detector, white reference).

    R(theta0, theta0') = (n0/n1)^2 rho_g T_01(theta0) T_01(theta0') t_1(theta1) t_1(theta1')
                         / (1 - rho_g r_110),
    layer and background of the same real index n1, ambient n0, t_1 = exp(-alpha h/cos theta1)
    with n0 sin theta0 = n1 sin theta1, r_110 from eq. (80).  Specular reflection excluded.
    ``theta0``, ``theta0p`` (illumination / observation, radians in n0) broadcast.
    The BRDF is this divided by pi (eq. 76).
    """
    r110, _ = williams_clapper_integrals(n0, n1, alpha_h)
    Ta, ta = _T01_t1(n0, n1, alpha_h, theta0)
    Tb, tb = _T01_t1(n0, n1, alpha_h, theta0p)
    return (n0 / n1) ** 2 * rho_g * Ta * Tb * ta * tb / (1.0 - rho_g * r110)


def shore_spoonhower(n0, n1, alpha_h, rho_g, theta0):
    """Shore-Spoonhower / Elias integrating-sphere reflectance, eq. (83).

    R = t_110 rho_g T_01(theta0) t_1(theta1) / (1 - rho_g r_110)  (specular excluded),
    with r_110, t_110 from eqs. (80)-(81).  ``theta0`` broadcast.
    """
    r110, t110 = williams_clapper_integrals(n0, n1, alpha_h)
    T01, t1 = _T01_t1(n0, n1, alpha_h, theta0)
    return t110 * rho_g * T01 * t1 / (1.0 - rho_g * r110)


# --------------------------------------------------------------------------------------
# Saunderson (bare background, air | paint)
# --------------------------------------------------------------------------------------
def saunderson_sphere(n, rho_g, theta0, n0: float = 1.0):
    """Bare Lambertian background of index n under ambient n0, integrating sphere, eq. (84).

    rho = t_20 rho_g T_02(theta0) / (1 - rho_g r_20), r_20 the internal diffuse reflectance
    (eq. 18 from the background side), t_20 = 1 - r_20, T_02 = 1 - R_02 (natural light).
    Specular excluded.  ``rho_g``, ``theta0`` broadcast.
    """
    r20 = diffuse_reflectance_interface(n, n0)
    t20 = 1.0 - r20
    T02 = 1.0 - fresnel_natural_R(n0, n, theta0)[2]
    rho_g = np.asarray(rho_g, dtype=float)
    return t20 * rho_g * T02 / (1.0 - rho_g * r20)


def saunderson_invert(n, rho, theta0, n0: float = 1.0):
    """Intrinsic reflectance from an integrating-sphere measurement, eq. (86).

    rho_g = rho / (t_20 T_02(theta0) + r_20 rho).  Inverse of :func:`saunderson_sphere`.
    """
    r20 = diffuse_reflectance_interface(n, n0)
    t20 = 1.0 - r20
    T02 = 1.0 - fresnel_natural_R(n0, n, theta0)[2]
    rho = np.asarray(rho, dtype=float)
    return rho / (t20 * T02 + r20 * rho)


def saunderson_radiance(n, rho_g, theta0, theta0p, n0: float = 1.0):
    """Bare background, radiance detector reflectance factor, eq. (85).

    R = (n0/n)^2 T_02(theta0) T_02(theta0') rho_g / (1 - rho_g r_20).
    """
    r20 = diffuse_reflectance_interface(n, n0)
    Ta = 1.0 - fresnel_natural_R(n0, n, theta0)[2]
    Tb = 1.0 - fresnel_natural_R(n0, n, theta0p)[2]
    rho_g = np.asarray(rho_g, dtype=float)
    return (n0 / n) ** 2 * Ta * Tb * rho_g / (1.0 - rho_g * r20)


def saunderson_radiance_invert(n, R, theta0, theta0p, n0: float = 1.0):
    """Inverse of :func:`saunderson_radiance`, eq. (87)."""
    r20 = diffuse_reflectance_interface(n, n0)
    Ta = 1.0 - fresnel_natural_R(n0, n, theta0)[2]
    Tb = 1.0 - fresnel_natural_R(n0, n, theta0p)[2]
    R = np.asarray(R, dtype=float)
    return R / ((n0 / n) ** 2 * Ta * Tb + r20 * R)


# --------------------------------------------------------------------------------------
# General stack on a Lambertian background (tmm based)
# --------------------------------------------------------------------------------------
def background_sphere(n_list, d_list, c_list, lam, rho_g, theta0):
    """Stack on a Lambertian background, integrating sphere, specular excluded: eq. (78).

    R = t_{k+1..0} rho_g T_{0..k+1}(theta0) / (1 - rho_g r_{k+1..0}); the last medium of the
    lists is the background's own medium (index n_g), r, t its back-side diffuse values
    (:func:`diffuse_stack_reference` with side="back"), T from :func:`inc_stack_R_T`.
    Returns (R_diffuse, R_specular) with R_specular = R_{0..k+1}(theta0) of the stack.
    """
    r_b, t_b = diffuse_stack_reference(n_list, d_list, c_list, lam, side="back")
    Rspec, T0 = inc_stack_R_T("u", n_list, d_list, c_list, theta0, lam)
    return t_b * rho_g * T0 / (1.0 - rho_g * r_b), Rspec


def background_radiance_factor(n_list, d_list, c_list, lam, rho_g, theta0, theta0p):
    """Reflectance factor against a perfect white diffuser, eq. (79) (BRDF = this / pi, eq. 76).

    R = (n0/n_g)^2 T(theta0) T(theta0') rho_g / (1 - rho_g r_{k+1..0}), n_g = last medium.
    """
    n0 = float(np.real(n_list[0]))
    ng = float(np.real(n_list[-1]))
    r_b, _ = diffuse_stack_reference(n_list, d_list, c_list, lam, side="back")
    _, Ta = inc_stack_R_T("u", n_list, d_list, c_list, theta0, lam)
    _, Tb = inc_stack_R_T("u", n_list, d_list, c_list, theta0p, lam)
    return (n0 / ng) ** 2 * Ta * Tb * rho_g / (1.0 - rho_g * r_b)
