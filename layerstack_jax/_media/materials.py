r"""Dispersion models: the complex index :math:`\tilde n(\lambda) = n + ik` of a medium.

Every model is an equinox module (a pytree: its coefficients can be fitted) whose call
``model(wavelength_nm)`` returns the complex index on the given grid, or a scalar when the
index does not depend on wavelength — so that nothing wavelength-independent is ever
recomputed per wavelength.

Coefficients of Cauchy and Sellmeier models are quoted with λ in **micrometres**, as in the
literature and the refractiveindex.info database; the call itself takes nanometres.
"""

from __future__ import annotations

from typing import Optional

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._base.custom_types import Coefficients, RealLike, TableColumn
from .._base.leaves import leaf
from .._base.numerics import complex_from
from .._base.validate import LayerstackError, check_finite, check_nonnegative, check_wavelength_range, is_concrete

__all__ = ["Material", "Index", "Cauchy", "Sellmeier", "Tabulated", "as_material"]


class Material(eqx.Module):
    """Base class: a callable ``wavelength_nm -> complex index`` (n + ik, k >= 0)."""

    def __call__(self, wavelength_nm):  # pragma: no cover - abstract
        raise NotImplementedError


def _complex(n, k):
    """n + ik; stays a numpy constant when both are concrete, so that static work (critical
    angles, segment layout) can be decided at trace time instead of on every call."""
    if is_concrete((n, k)):
        return np.asarray(n) + 1j * np.asarray(k)
    return complex_from(n, k)


class Index(Material):
    """A given index: scalars (constant) or arrays already sampled on the model's wavelength grid.

    Attributes:
        n: real part, dimensionless; scalar or array broadcastable to ``(*batch, wl)``.
        k: extinction coefficient (>= 0), same shapes.
    """

    n: RealLike = leaf(spectral=True, per_wavelength=True, file_key="n")
    k: RealLike = leaf(spectral=True, file_key="k", default=0.0)

    def __check_init__(self):
        check_finite("Index.n", self.n)
        check_nonnegative("Index.k", self.k, "(extinction coefficient) must be >= 0 (convention n + ik)")

    def __call__(self, wavelength_nm):
        return _complex(self.n, self.k)


class Cauchy(Material):
    r"""Cauchy dispersion :math:`n = A + B/\lambda^2 + C/\lambda^4` (λ in µm; B in µm², C in µm⁴),
    with a constant extinction coefficient k.

    Attributes:
        A: dimensionless; B in µm²; C in µm⁴; k dimensionless (>= 0). Each a scalar or an array
            broadcastable against the wavelength grid ``(wl,)`` (e.g. ``(*batch, 1)``).

    Called with wavelengths in nm of shape ``(wl,)`` it returns the complex index n + ik,
    shape ``(wl,)`` (broadcast with the coefficients' shapes).
    """

    A: RealLike = leaf(spectral=True)
    B: RealLike = leaf(spectral=True, default=0.0)
    C: RealLike = leaf(spectral=True, default=0.0)
    k: RealLike = leaf(spectral=True, default=0.0)

    def __check_init__(self):
        check_nonnegative("Cauchy.k", self.k)

    def __call__(self, wavelength_nm):
        lam2 = (jnp.asarray(wavelength_nm) * 1e-3) ** 2
        return _complex(self.A + self.B / lam2 + self.C / lam2**2, self.k)


class Sellmeier(Material):
    r"""Sellmeier dispersion :math:`n^2 = 1 + \sum_i B_i \lambda^2 / (\lambda^2 - C_i)`
    (λ in µm, :math:`C_i` in µm²), with a constant extinction coefficient k.

    Attributes:
        B: dimensionless oscillator strengths, shape ``(term,)`` (or a scalar: one term).
        C: resonance terms in µm², same shape as ``B``.
        k: extinction coefficient (>= 0, dimensionless), scalar or broadcastable to ``(wl,)``.

    Called with wavelengths in nm of shape ``(wl,)`` it returns the complex index n + ik,
    shape ``(wl,)``.
    """

    B: Coefficients
    C: Coefficients
    k: RealLike = leaf(spectral=True, default=0.0)

    def __check_init__(self):
        if is_concrete(self.B) and np.shape(self.B) != np.shape(self.C):
            raise LayerstackError("Sellmeier.B and Sellmeier.C must have the same length")
        check_nonnegative("Sellmeier.k", self.k)

    def __call__(self, wavelength_nm):
        lam2 = (jnp.asarray(wavelength_nm) * 1e-3) ** 2
        B = jnp.atleast_1d(jnp.asarray(self.B))
        C = jnp.atleast_1d(jnp.asarray(self.C))
        n2 = 1.0 + jnp.sum(B[:, None] * lam2 / (lam2 - C[:, None]), axis=0)
        return _complex(jnp.sqrt(n2), self.k)


def interpolate_table(x, table_nm, values):
    """``values`` (on the increasing ``table_nm``) linearly interpolated at wavelengths ``x``
    (nm; inside the table, see :func:`~layerstack_jax._base.validate.check_wavelength_range`).

    With concrete ``x`` — a model's wavelength grid, fixed while a fit or a design varies
    thicknesses and coefficients — each ``x``'s interval and weight are found now, in numpy, and
    a compiled model holds them as data: the result is a numpy constant when ``values`` are
    concrete too, else a gather and a weighted sum of the traced values (differentiable in
    them; a concrete table gives a numpy float64 result whatever JAX's precision, rounded where
    it meets JAX arrays). Traced ``x`` and one-point tables take ``jnp.interp`` (a search at run
    time)."""
    table = np.asarray(table_nm, dtype=float)
    if not is_concrete(x) or table.size < 2:
        return jnp.interp(x, table, jnp.asarray(values))
    x = np.asarray(x)
    i = np.clip(np.searchsorted(table, x, side="right") - 1, 0, table.size - 2)
    w = np.clip((x - table[i]) / (table[i + 1] - table[i]), 0.0, 1.0)
    v = np.asarray(values) if is_concrete(values) else jnp.asarray(values)
    return v[..., i] * (1.0 - w) + v[..., i + 1] * w


class Tabulated(Material):
    """Tabulated (n, k) linearly interpolated on wavelength (differentiable in the table values).

    Raises a :class:`LayerstackError` when asked for a wavelength outside the table: data are
    never silently extrapolated.

    Attributes:
        wavelength_nm: increasing table wavelengths, nm, shape ``(table,)`` (static, not fitted).
        n, k: table values (dimensionless), shape ``(table,)`` each; ``k=None`` means 0.
        name: label used in messages.

    Called with wavelengths in nm of shape ``(wl,)`` it returns the complex index n + ik,
    shape ``(wl,)``.
    """

    wavelength_nm: np.ndarray = eqx.field(static=True, converter=lambda x: tuple(np.asarray(x, float).tolist()))
    n: TableColumn = leaf(per_wavelength=True)
    k: Optional[TableColumn] = None
    name: str = eqx.field(static=True, default="tabulated")

    def __check_init__(self):
        wl = np.asarray(self.wavelength_nm)
        if wl.ndim != 1 or wl.size < 2 or np.any(np.diff(wl) <= 0):
            raise LayerstackError(f"{self.name}: table wavelengths must be strictly increasing (>= 2 points)")
        for field, v in (("n", self.n), ("k", self.k)):
            if v is not None and is_concrete(v) and np.shape(v) != wl.shape:
                raise LayerstackError(f"{self.name}: column {field} has {np.size(v)} values for {wl.size} wavelengths")
        check_finite(f"{self.name}.n", self.n)
        check_nonnegative(f"{self.name}.k", self.k)

    @property
    def data_range_nm(self) -> tuple:
        """``(first, last)`` table wavelength in nm: the range the material can be evaluated on."""
        return (float(self.wavelength_nm[0]), float(self.wavelength_nm[-1]))

    def __call__(self, wavelength_nm):
        table = np.asarray(self.wavelength_nm)
        x = check_wavelength_range(self.name, wavelength_nm, float(table[0]), float(table[-1]))
        n = interpolate_table(x, table, self.n)
        k = 0.0 if self.k is None else interpolate_table(x, table, self.k)
        return _complex(n, k)


def as_material(x) -> Material:
    """Promote a number (or complex number n + ik) to :class:`Index`; pass materials through."""
    if isinstance(x, Material):
        return x
    if isinstance(x, complex):
        return Index(x.real, x.imag)
    if callable(x):
        raise LayerstackError(f"unsupported material object {x!r}: use a layerstack_jax Material")
    a = jnp.asarray(x) if not isinstance(x, (float, int)) else x
    if jnp.iscomplexobj(a):
        return Index(jnp.real(a), jnp.imag(a))
    return Index(a)
