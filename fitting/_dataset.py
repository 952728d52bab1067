r"""Measurements: a :class:`Dataset` is what one instrument geometry read on every sample of
the fit: ``data`` shaped ``(samples, wl)`` on the model wavelength grid (or on its own grid,
then resampled linearly onto the model grid — which must lie inside the data's range: nothing is
extrapolated, :func:`resample`), with optional per-point standard deviations σ (or weights) and
a mask of valid points; or CIELAB colours of a colorimeter through a
:class:`layerstack_jax.ColourSpace`. :func:`_prepare` checks a dataset and turns it into the
``(data, weight, mask)`` arrays on the model grid that an :class:`~fitting.Objective` holds."""

from __future__ import annotations

import dataclasses
import warnings
from typing import Optional

import numpy as np
from jax.typing import ArrayLike

from layerstack_jax import (
    ColourSpace,
    Geometry,
    LayerstackError,
    LayerstackWarning,
    RealLike,
)

__all__ = ["Dataset", "resample", "NEGATIVE_READING_FLOOR"]

#: Without σ, readings down to this (absolute, in the reading's unit) are accepted as noise
#: around a dark, dark-corrected sample; below it they are an error.
NEGATIVE_READING_FLOOR = 0.01


def _geometry_label(g: Geometry) -> str:
    """The geometry's own spelling (``Geometry.label``)."""
    return g.label


def resample(wavelength_nm, values, grid_nm, *, what: str = "data") -> np.ndarray:
    """Linear interpolation of ``values`` (``(..., n)`` on ``wavelength_nm``) onto ``grid_nm``.

    ``wavelength_nm``: ``(n,)`` and ``grid_nm``: ``(wl,)``, both in nm; returns ``(..., wl)``
    in the unit of ``values``.

    Raises :class:`LayerstackError` when the grid reaches outside the data's range (no
    extrapolation) or the data wavelengths do not increase strictly.
    """
    w = np.asarray(wavelength_nm, dtype=float)
    g = np.asarray(grid_nm, dtype=float)
    v = np.asarray(values, dtype=float)
    if w.ndim != 1 or w.size < 1 or v.shape[-1] != w.size:
        raise LayerstackError(f"{what}: {v.shape[-1]} values for {w.size} wavelengths")
    if w.size > 1 and np.any(np.diff(w) <= 0):
        raise LayerstackError(f"{what}: wavelengths must increase strictly")
    tol = 1e-9 * max(1.0, float(np.max(np.abs(g))))
    if g.min() < w[0] - tol or g.max() > w[-1] + tol:
        raise LayerstackError(
            f"{what}: the data cover {w[0]:g}–{w[-1]:g} nm but the model grid spans {g.min():g}–{g.max():g} nm; "
            "data are never extrapolated: narrow the model grid or mask the missing points"
        )
    if w.size == g.size and np.allclose(w, g, rtol=0, atol=tol):
        return v.copy()
    if w.size == 1:
        return np.broadcast_to(v, v.shape[:-1] + g.shape).copy()
    # one set of brackets and weights for every spectrum (no loop over rows)
    gc = np.clip(g, w[0], w[-1])
    i = np.clip(np.searchsorted(w, gc, side="right") - 1, 0, w.size - 2)
    t = (gc - w[i]) / (w[i + 1] - w[i])
    return v[..., i] * (1.0 - t) + v[..., i + 1] * t


@dataclasses.dataclass(frozen=True, eq=False)
class Dataset:
    """Spectra measured in one geometry, one row per sample.

    Attributes:
        geometry: a :class:`~layerstack_jax.Geometry` (``Sphere``, ``Directional`` …) — what
            :func:`layerstack_jax.reflectance` computes is compared with ``data``.
        data: ``(samples, wl)`` or ``(wl,)`` (one sample); NaN allowed only where masked.
        sigma: standard deviation of each point (scalar, ``(wl,)`` or ``(samples, wl)``);
            covariances are then absolute (not rescaled by χ²).
        weights: alternative to σ: residual weights (σ = 1/weight up to a common factor);
            covariances are rescaled by the reduced χ².
        mask: boolean, True where the point is used (default: all).
        wavelength_nm: the data's own wavelengths if they differ from the model grid
            (resampled linearly; the model grid must lie inside).
        name: label in reports.
        colour: a :class:`layerstack_jax.ColourSpace` on the model grid: residuals in CIELAB.
            The model spectra are converted to L*, a*, b* (observer and illuminant of the colour
            space); ``data`` are CIELAB values ``(samples, 3)`` (a colorimeter's readings) or
            spectra ``(samples, wl)`` converted once; σ is then in ΔE*ab units (scalar, ``(3,)``
            or ``(samples, 3)``), so χ² sums ΔE*ab²/σ².
        bare: True for a measurement of the bare exit medium — the stack with all its layers
            removed (the uncoated background of a calibration series: it pins ρg(λ), which
            otherwise trades off against α(λ) where the coating is dark). One spectrum,
            ``(wl,)`` or ``(1, wl)``, whatever the number of samples; only shared parameters
            (ρg, n_g) reach it.
    """

    geometry: Geometry
    data: RealLike
    sigma: Optional[RealLike] = None
    weights: Optional[RealLike] = None
    mask: Optional[ArrayLike] = None
    wavelength_nm: Optional[RealLike] = None
    name: str = ""
    colour: Optional[ColourSpace] = None
    bare: bool = False

    @property
    def label(self) -> str:
        return self.name or (_geometry_label(self.geometry) + (" CIELAB" if self.colour is not None else ""))


def _prepare_colour(ds: Dataset, grid: np.ndarray, n_samples: Optional[int], label: str):
    """:func:`_prepare` for a CIELAB dataset: ``(data, weight, mask)`` shaped ``(samples, 3)``."""
    cs = ds.colour
    if not isinstance(cs, ColourSpace):
        raise LayerstackError(f"{label}: colour must be a layerstack_jax.ColourSpace, got {type(cs).__name__}")
    if len(cs.wavelength_nm) != grid.size or not np.allclose(cs.wavelength_nm, grid, rtol=0, atol=1e-9):
        raise LayerstackError(f"{label}: the colour space must be built on the model wavelength grid")
    if ds.mask is not None:
        raise LayerstackError(f"{label}: masks are for spectra; a CIELAB dataset uses all three coordinates")
    y = np.asarray(ds.data, dtype=float)
    if y.ndim == 1:
        y = y[None]
    if y.ndim != 2:
        raise LayerstackError(f"{label}: data must be CIELAB (samples, 3) or spectra (samples, wl), got {y.shape}")
    if not np.all(np.isfinite(y)):
        raise LayerstackError(f"{label}: NaN or infinite data")
    spectral = y.shape[1] != 3 or ds.wavelength_nm is not None
    if spectral:
        wl_data = grid if ds.wavelength_nm is None else np.asarray(ds.wavelength_nm, dtype=float)
        if y.shape[1] != wl_data.size:
            raise LayerstackError(f"{label}: data are neither CIELAB (3 columns) nor spectra on the grid ({wl_data.size})")
        if np.any(y < 0):
            raise LayerstackError(f"{label}: negative reflectance in the spectra to convert to CIELAB")
        if ds.wavelength_nm is not None:
            y = resample(wl_data, y, grid, what=label)
        y = np.asarray(cs.Lab(y))
    if ds.sigma is not None and ds.weights is not None:
        raise LayerstackError(f"{label}: give sigma or weights, not both")
    if n_samples is not None and y.shape[0] != n_samples:
        raise LayerstackError(f"{label}: {y.shape[0]} colours for {n_samples} samples")
    given = ds.sigma if ds.sigma is not None else ds.weights
    try:
        v = np.broadcast_to(np.asarray(1.0 if given is None else given, dtype=float), y.shape).astype(float)
    except ValueError:
        raise LayerstackError(f"{label}: {'sigma' if ds.sigma is not None else 'weights'} shaped "
                              f"{np.shape(given)} does not match the CIELAB data {y.shape}") from None
    if ds.sigma is not None:
        if not np.all(np.isfinite(v) & (v > 0)):
            raise LayerstackError(f"{label}: sigma must be finite and > 0")
        weight = 1.0 / v
    else:
        if not np.all(np.isfinite(v) & (v >= 0)):
            raise LayerstackError(f"{label}: weights must be finite and >= 0")
        weight = v
    return y, weight, np.ones(y.shape, bool)


def _prepare(ds: Dataset, grid: np.ndarray, n_samples: Optional[int], index: int):
    """Checked ``(data, weight, mask)`` arrays shaped ``(samples, wl)`` on the model grid
    (``(samples, 3)`` for a CIELAB dataset)."""
    label = f"dataset {index} ({ds.label})"
    if not isinstance(ds.geometry, Geometry):
        raise LayerstackError(f"{label}: geometry must be a layerstack_jax Geometry, got {ds.geometry!r}")
    if ds.bare and n_samples is not None:
        n_samples = 1
    if ds.colour is not None:
        return _prepare_colour(ds, grid, n_samples, label)
    y = np.asarray(ds.data, dtype=float)
    if y.ndim == 1:
        y = y[None]
    if y.ndim != 2:
        raise LayerstackError(f"{label}: data must be shaped (samples, wavelengths), got {y.shape}")
    wl_data = grid if ds.wavelength_nm is None else np.asarray(ds.wavelength_nm, dtype=float)
    if y.shape[1] != wl_data.size:
        raise LayerstackError(
            f"{label}: data have {y.shape[1]} points per spectrum but "
            + ("the model grid has" if ds.wavelength_nm is None else "wavelength_nm has")
            + f" {wl_data.size}"
        )

    def per_point(v, what, default):
        a = np.broadcast_to(np.asarray(default if v is None else v, dtype=float), y.shape) if v is None or np.ndim(v) == 0 \
            else np.asarray(v, dtype=float)
        if a.ndim == 1:
            a = a[None]
        try:
            return np.broadcast_to(a, y.shape).astype(float)
        except ValueError:
            raise LayerstackError(f"{label}: {what} shaped {np.shape(v)} does not match data {y.shape}") from None

    if ds.sigma is not None and ds.weights is not None:
        raise LayerstackError(f"{label}: give sigma or weights, not both")
    if ds.mask is None:
        mask = np.ones(y.shape, bool)
    else:
        m = np.asarray(ds.mask)
        if m.dtype != bool:
            raise LayerstackError(f"{label}: mask must be boolean (True = point used)")
        mask = np.broadcast_to(m[None] if m.ndim == 1 else m, y.shape).copy()
    if ds.sigma is not None:
        sigma = per_point(ds.sigma, "sigma", 1.0)
        bad = mask & ~(np.isfinite(sigma) & (sigma > 0))
        if np.any(bad):
            raise LayerstackError(f"{label}: sigma must be finite and > 0 at every used point")
        weight = 1.0 / np.where(sigma > 0, sigma, 1.0)
    else:
        weight = per_point(ds.weights, "weights", 1.0)
        if np.any(mask & ~(np.isfinite(weight) & (weight >= 0))):
            raise LayerstackError(f"{label}: weights must be finite and >= 0")
    # values checks at used points
    used = mask
    nan = used & ~np.isfinite(y)
    if np.any(nan):
        s, j = np.argwhere(nan)[0]
        raise LayerstackError(
            f"{label}: NaN or infinite data at sample {s}, {wl_data[j]:g} nm; mask missing points (mask=False)"
        )
    if not ds.geometry.signed:  # Δ, C, S may be < 0; reflectances only by noise
        # Dark-corrected readings of a dark sample scatter around 0: a reading is valid down to
        # -5σ (σ given), or down to -NOISE_FLOOR (absolute) when no σ is given.
        floor = -5.0 / weight if ds.sigma is not None else np.full(y.shape, -NEGATIVE_READING_FLOOR)
        neg = used & (y < floor)
        if np.any(neg):
            s, j = np.argwhere(neg)[0]
            allowed = "-5 sigma" if ds.sigma is not None else f"-{NEGATIVE_READING_FLOOR:g} without sigma"
            raise LayerstackError(
                f"{label}: reading {y[s, j]:g} at sample {s}, {wl_data[j]:g} nm is below {allowed} "
                f"({floor[s, j]:.3g}): not noise around a dark reading; wrong baseline or units?"
            )
    if ds.geometry.reading_is_fraction and np.any(used & (y > 1.5)) and ds.colour is None:
        warnings.warn(f"{label}: data up to {np.max(np.where(used, y, 0)):g} for a {ds.geometry.quantity_label} "
                      "(a fraction, usually <= 1): percent given? divide by 100", LayerstackWarning, stacklevel=4)
    if ds.wavelength_nm is not None:
        y = resample(wl_data, np.where(mask, y, 0.0), grid, what=label)
        weight = resample(wl_data, weight, grid, what=label)
        # a model point is used only if both neighbouring data points are
        m = resample(wl_data, mask.astype(float), grid, what=label)
        mask = m > 1 - 1e-12
    if n_samples is not None and y.shape[0] != n_samples:
        raise LayerstackError(f"{label}: {y.shape[0]} spectra for {n_samples} samples"
                              + (" (a bare-background dataset holds one spectrum)" if ds.bare else ""))
    y = np.where(mask, y, 0.0)
    return y, np.where(mask, weight, 0.0), mask
