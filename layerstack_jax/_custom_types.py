"""Array aliases used in signatures (jaxtyping).

Axis names used throughout the package:

* ``wl``   — wavelength (the last axis of every spectrum),
* ``ang``  — angle of incidence / Snell invariant,
* ``pol``  — polarization, always ordered ``(s, p)``,
* ``node`` — hemispherical quadrature node,
* ``med``  — medium of a stack, ordered from the ambient (index 0) to the exit medium,
* ``lay``  — layer of a stack (media without the two semi-infinite ones),
* ``*batch`` — any leading batch axes, broadcast together.
"""

from typing import Union

import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float, Inexact

#: Anything convertible to an array of real numbers (Python float, numpy or JAX array).
RealLike = Union[float, int, ArrayLike]
#: Anything convertible to a (possibly complex) array.
ComplexLike = Union[complex, float, int, ArrayLike]

Real = Float[Array, "..."]
Cplx = Complex[Array, "..."]
Spectrum = Float[Array, "*batch wl"]
Wavelengths = Float[Array, " wl"]
Index = Inexact[Array, "*batch wl"]

__all__ = [
    "Array",
    "ArrayLike",
    "Complex",
    "Cplx",
    "Float",
    "Index",
    "Real",
    "RealLike",
    "ComplexLike",
    "Spectrum",
    "Wavelengths",
    "np",
]
