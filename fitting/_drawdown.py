r"""Two-constant Kubelka–Munk calibration from drawdowns: a paint's absorption K(λ) and
scattering S(λ) per unit thickness from its films over grounds of known reflectance.

Paint databases are made this way (Kubelka 1948): the paint is drawn down at a known dry
thickness X over a black and a white card (or over the black and white halves of one card), and
each drawdown is measured. Over one ground a reading fixes one number per wavelength; K and S
need two — hence two grounds (a body over black shows mostly S, over white mostly K), or one
ground and two thicknesses. An opaque
drawdown fixes only K/S (its :math:`R_\infty`, Kubelka 1948 eq. 9) whatever the ground. Two
drawdowns leave no degrees of freedom (as many unknowns as readings: χ² cannot judge the fit,
and with noise the solver may wander where a reading is dark); a third, at another thickness,
makes the fit checkable and its standard errors calibrated (tests/test_drawdown.py).

A strongly absorbing pigment drawn down alone (masstone) is nearly black in its absorption band:
there the readings are the surface reflection and K, S are not determined. Paint makers
calibrate such pigments from *tints* — the pigment mixed with a white of known K, S at known
fractions (Duncan's rule, K = fK_p + (1 − f)K_w, S = fS_p + (1 − f)S_w) — which keeps every
drawdown bright enough to read (``white=``, ``fractions=``).

Here each drawdown is a :class:`~layerstack_jax.KubelkaMunk` body (Kubelka's hyperbolic
solution for thickness X over ground :math:`R_g`, Kubelka 1948 eqs. 5–6) under the binder's
interface, measured by the given geometry: the surface reflection and the internal reflection
at the binder–air interface (Saunderson's k₁, k₂) come from the library's exact interface
algebra, not from constants. K(λ) and S(λ) are free at every wavelength (or on a basis), shared
by the drawdowns; each drawdown's ground and thickness are known and held. The fit is an
ordinary :class:`~fitting.Objective`: ``fit`` gives K, S with standard errors and says when the
drawdowns cannot separate them; ``fit_batch`` fits replicates.
"""

from __future__ import annotations

from typing import Optional, Union

import numpy as np

from layerstack_jax import (
    Geometry,
    KubelkaMunk,
    LayerstackError,
    Mixture,
    Paint,
    Stack,
    k_over_s,
)

from ._dataset import Dataset
from ._objective import Objective
from ._parameters import Parameter

__all__ = ["drawdown_calibration"]


def _ground_spectra(grounds, n: int, wl: int) -> np.ndarray:
    """Each drawdown's ground reflectance as ``(n, wl)``: from one number, one number per
    drawdown ``(n,)`` or a spectrum per drawdown ``(n, wl)``."""
    rg = np.asarray(grounds, float)
    if rg.shape == (n,):
        rg = rg[:, None]
    try:
        rg = np.broadcast_to(rg, (n, wl)).copy()
    except ValueError:
        raise LayerstackError(f"drawdown_calibration: grounds must be a number, one per drawdown ({n},) or "
                              f"({n}, {wl}) spectra, got shape {np.shape(grounds)}") from None
    if np.any(~np.isfinite(rg)) or np.any((rg < 0) | (rg > 1)):
        raise LayerstackError(f"drawdown_calibration: grounds must lie in [0, 1], got range "
                              f"[{np.nanmin(rg):.4g}, {np.nanmax(rg):.4g}]")
    return rg


def drawdown_calibration(wavelength_nm, geometry: Geometry, readings, grounds, thickness_nm, *,
                         binder_index=1.5, ambient=1.0, sigma=None, start: Optional[tuple] = None,
                         basis: Union[str, int] = "free", white: Optional[Paint] = None, fractions=None,
                         nodes: Optional[int] = None) -> Objective:
    r"""Objective of a two-constant Kubelka–Munk calibration (module docstring): K(λ), S(λ)
    (1/nm) of one paint from ``n`` drawdowns of known thickness over known grounds.

    Args:
        wavelength_nm: ``(wl,)`` grid (nm) of the readings.
        geometry: how the drawdowns were measured (e.g. ``Sphere(8.0, "included")``,
            ``Directional(45.0, 0.0)``).
        readings: ``(n, wl)`` readings of the drawdowns (the instrument's reflectance factor).
        grounds: each drawdown's ground reflectance :math:`R_g` in [0, 1] *under the paint*
            (the internal reflectance of the card in contact with the binder): a number per
            drawdown ``(n,)`` or a spectrum per drawdown ``(n, wl)``.
        thickness_nm: dry film thickness X (nm): one number, or one per drawdown ``(n,)``.
        binder_index: the binder's refractive index (the interface above the body).
        ambient: index above the drawdowns (air).
        sigma: σ of the readings (scalar or ``(n, wl)``), or None (estimated from the residuals).
        start: ``(K, S)`` starting values (numbers or ``(wl,)``, 1/nm). Default: S = 1/X̄
            (one scattering length per film) and K = S · K/S of the brightest reading taken as
            :math:`R_\infty` (Kubelka 1948 eq. 9).
        basis: ``"free"`` (one K and one S per wavelength) or an int (B-spline functions over
            the grid for each).
        white, fractions: tints (module docstring): a :class:`~layerstack_jax.Paint` of known
            K, S mixed into the drawdowns, and ``(n,)`` the calibrated paint's fraction in each
            (1 for a masstone); the white's share is 1 − fraction. None: every drawdown is the
            paint alone.
        nodes: hemispherical quadrature nodes of the model (default: the library's).

    Returns an :class:`~fitting.Objective` whose free parameters are named ``"K"`` and ``"S"``;
    ``ft.fit(objective).values["K"]`` is the spectrum on the grid when ``basis="free"``. Its
    datasets hold the drawdowns as samples, so ``ft.fit_batch(objective, replicates)`` fits
    ``(replicates, n, wl)`` readings of the same drawdowns.
    """
    wl = np.asarray(wavelength_nm, float)
    data = np.asarray(readings, float)
    if data.ndim != 2 or data.shape[1] != wl.size:
        raise LayerstackError(f"drawdown_calibration: readings must be (drawdowns, {wl.size}) on the grid, "
                              f"got shape {data.shape}")
    n = data.shape[0]
    if n < 2:
        raise LayerstackError("drawdown_calibration: K and S need at least two drawdowns (over a black and a white "
                              "ground, or two thicknesses): one reading per wavelength fixes only one number")
    rg = _ground_spectra(grounds, n, wl.size)
    x = np.asarray(thickness_nm, float)
    if x.ndim == 0:
        x = np.full(n, float(x))
    if x.shape != (n,) or np.any(~np.isfinite(x)) or np.any(x <= 0):
        raise LayerstackError(f"drawdown_calibration: thickness_nm must be > 0 nm, one number or one per drawdown "
                              f"({n},), got {np.asarray(thickness_nm)!r}")
    if start is None:
        s0 = np.full(wl.size, 1.0 / float(np.mean(x)))
        brightest = np.clip(np.max(data, axis=0), 0.02, 0.98)
        k0 = s0 * np.asarray(k_over_s(brightest))
    else:
        k0, s0 = (np.broadcast_to(np.asarray(v, float), wl.shape).copy() for v in start)

    paint_path = ("exit", "paint")
    mixing = []
    if white is not None or fractions is not None:
        f = np.asarray(fractions, float) if fractions is not None else None
        if white is None or f is None or f.shape != (n,) or np.any(~np.isfinite(f)) or np.any((f <= 0) | (f > 1)):
            raise LayerstackError(f"drawdown_calibration: tints need white= (a Paint of known K, S) and fractions= "
                                  f"(the paint's share in each of the {n} drawdowns, in (0, 1]), got white={white!r}, "
                                  f"fractions={fractions!r}")
        shares = np.stack([f, 1.0 - f], axis=-1)
        paint_path = ("exit", "paint", "pigments", 0)
        mixing = [Parameter(("exit", "paint", "concentrations"), name="fractions", per_sample=True, value=shares,
                            fixed=np.ones_like(shares, bool))]

    def stack(k, s):
        paint = Paint(k, s, name="paint")
        body = paint if not mixing else Mixture(mixing[0].value[0], [paint, white])
        return Stack(ambient, [], KubelkaMunk(binder_index, body, float(x[0]), rg[0]))

    spectral = dict(kind="alpha", basis=basis)
    parameters = [Parameter((*paint_path, "absorption"), name="K", value=None, **spectral),
                  Parameter((*paint_path, "scattering"), name="S", value=None, **spectral),
                  Parameter(("exit", "ground"), kind="rho_g", name="ground", basis="free", per_sample=True,
                            value=rg, fixed=np.ones_like(rg, bool)),
                  Parameter(("exit", "thickness"), kind="thickness", name="X", per_sample=True, value=x,
                            fixed=np.ones(n, bool)), *mixing]
    kwargs = {} if nodes is None else {"nodes": nodes}
    return Objective(stack(k0, s0), wl, Dataset(geometry, data, sigma=sigma), parameters, n_samples=n, **kwargs)
