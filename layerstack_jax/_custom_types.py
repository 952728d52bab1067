"""Array aliases used in signatures (jaxtyping), kept in one place.

Axis names used throughout the package:

* ``wl``   — wavelength (the last axis of every spectrum),
* ``ang``  — angle of incidence / Snell invariant,
* ``pol``  — polarization, always ordered ``(s, p)``,
* ``node`` — hemispherical quadrature node,
* ``med``  — medium of a stack, ordered from the ambient (index 0) to the exit medium,
* ``lay``  — layer of a stack (media without the two semi-infinite ones),
* ``*batch`` — any leading batch axes, broadcast together.

The aliases document shapes and units; they are not checked at run time. ``IndexSpectrum`` is
an *array* of sampled indices; the public :class:`layerstack_jax.Index` is the material class.
"""

from typing import Union

from jaxtyping import Array, ArrayLike, Complex, Float, Inexact

#: Anything convertible to an array of real numbers (Python float, numpy or JAX array).
RealLike = Union[float, int, ArrayLike]
#: Anything convertible to a (possibly complex) array.
ComplexLike = Union[complex, float, int, ArrayLike]

#: A dimensionless spectrum (reflectance, transmittance …) or a BRDF (1/sr) on the grid: ``(*batch, wl)``.
Spectrum = Float[Array, "*batch wl"]
#: Vacuum wavelengths in nm, ``(wl,)``.
Wavelengths = Float[Array, " wl"]
#: Complex refractive index n + ik sampled on the grid (k >= 0 absorbing), ``(*batch, wl)``;
#: a dispersionless medium may give ``(*batch, 1)`` or a scalar.
IndexSpectrum = Inexact[Array, "*batch wl"]

__all__ = [
    "Array",
    "ArrayLike",
    "Complex",
    "ComplexLike",
    "Float",
    "Inexact",
    "IndexSpectrum",
    "RealLike",
    "Spectrum",
    "Wavelengths",
]
