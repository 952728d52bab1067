"""Array aliases used in signatures (jaxtyping), kept in one place.

Axis names used throughout the package:

* ``wl``   — wavelength (the last axis of every spectrum),
* ``ang``  — angle of incidence / Snell invariant,
* ``pol``  — polarization, always ordered ``(s, p)``,
* ``node`` — hemispherical quadrature node,
* ``med``  — medium of a stack, ordered from the ambient (index 0) to the exit medium,
* ``lay``  — layer of a stack (media without the two semi-infinite ones),
* ``*batch`` — any leading batch axes, broadcast together.

The aliases document shapes and units; the library does not check them at run time (the tests
do: ``tests/test_shapes.py`` wraps the public functions with jaxtyping + beartype).
``IndexSpectrum`` is an *array* of sampled indices; the public :class:`layerstack_jax.Index` is
the material class.
"""

from typing import Any, Callable, Protocol, Union, runtime_checkable

import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float, Inexact, Real


@runtime_checkable
class DuckArray(Protocol):
    """Any array object with a ``shape`` and a ``dtype`` that NumPy can read: a memmap, a Dask
    array (a batched leaf of :func:`layerstack_jax.predict` may be one)."""

    @property
    def shape(self) -> tuple: ...

    @property
    def dtype(self) -> Any: ...


#: A real number or a real array of any shape: a Python int/float, a NumPy or JAX array (a tracer
#: under ``jit``/``vmap``/``grad``), or a :class:`DuckArray` (Dask). As a model leaf (a thickness,
#: an index n, a dispersion coefficient) it is a scalar, ``(wl,)``, ``(*batch, 1)`` or
#: ``(*batch, wl)`` — broadcastable against the wavelength grid.
RealLike = Real[Union[ArrayLike, DuckArray], "..."]
#: A real spectrum given by value or by function: a :data:`RealLike` on the model grid, or a
#: callable ``wavelength_nm (wl,) -> (wl,)`` such as :class:`~layerstack_jax.TabulatedSpectrum`.
RealSpectrumLike = Union[RealLike, Callable[..., Any]]
#: Coefficients of a sum of terms (Sellmeier terms, oscillators): a scalar (one term) or ``(osc,)``
#: (one per term); real. Batched (:func:`layerstack_jax.predict`) ``(*batch, osc)``.
Coefficients = Real[Union[ArrayLike, DuckArray], "*osc"]
#: One column of a table sampled at the table's own wavelengths, ``(table,)``, or ``(*batch, table)``
#: batched (:func:`layerstack_jax.predict`); real.
TableColumn = Real[Union[ArrayLike, DuckArray], "*batch table"]
#: Anything convertible to a (possibly complex) array.
ComplexLike = Union[complex, float, int, ArrayLike]

#: A dimensionless spectrum (reflectance, transmittance …) or a BRDF (1/sr) on the grid: ``(*batch, wl)``.
Spectrum = Float[Array, "*batch wl"]
#: Vacuum wavelengths in nm, ``(wl,)`` (an integer grid such as ``np.arange(400, 701, 10)`` is
#: accepted as it is).
Wavelengths = Real[Array, " wl"]
#: Complex refractive index n + ik sampled on the grid (k >= 0 absorbing), broadcastable to
#: ``(*batch, wl)``: a dispersionless medium gives ``(*batch, 1)`` or a scalar. A NumPy array when
#: the index is a constant (so that critical angles are decided at trace time), a JAX array otherwise.
IndexSpectrum = Inexact[Union[Array, np.ndarray], "..."]

__all__ = [
    "Array",
    "ArrayLike",
    "Complex",
    "Coefficients",
    "ComplexLike",
    "DuckArray",
    "Float",
    "Inexact",
    "IndexSpectrum",
    "Real",
    "RealLike",
    "RealSpectrumLike",
    "Spectrum",
    "TableColumn",
    "Wavelengths",
]
