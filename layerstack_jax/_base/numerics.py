r"""NaN-safe elementary operations, written once (PHYSICS.md, trap 3).

``jnp.where(ok, f(x), fallback)`` differentiates *both* branches: where ``f`` divides by zero or
takes the square root of zero, the untaken branch poisons the gradient with NaN (0 · inf). Each
function below guards the argument of the untaken branch too (the "double where" pattern), so its
value *and* its derivative are finite everywhere. The fallback value, and the derivative there,
are stated per function; elsewhere the value is bit for bit that of the plain operation.

All functions are elementwise and broadcast their arguments (any shape ``(*B)``); they are
dimensionless helpers (the result carries the unit of the plain operation).

The dtype helpers (:func:`complex_dtype`, :func:`as_complex`, :func:`complex_from`) write out the
real → complex promotions the kernels intend, so that they also run under
``jax_numpy_dtype_promotion = "strict"`` (the tests' setting): each gives exactly the dtype, and
the values, that JAX's standard promotion gives implicitly.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .custom_types import Array, ArrayLike, Complex, ComplexLike, Float, Inexact, RealLike

__all__ = ["abs2", "as_complex", "complex_dtype", "complex_from", "safe_abs", "safe_atan2", "safe_divide",
           "safe_divide_nonzero", "safe_reciprocal", "safe_sqrt", "sin_from_cos"]


def complex_dtype(*values) -> jnp.dtype:
    """The dtype of ``values`` (arrays, Python numbers or dtypes) combined with a Python complex
    number, as in ``x + 1j * y``: complex64 from float32, complex128 from float64, the default
    complex dtype from integers and Python scalars alone (complex128 with x64 on). Pass
    ``jnp.complex64`` among the values for "at least complex64, else the values' precision".
    Computed under standard promotion on purpose: the real → complex step is the intended one."""
    with jax.numpy_dtype_promotion("standard"):
        return jnp.result_type(*values, 1j)


def as_complex(x: ComplexLike, *others: ComplexLike) -> Complex[Array, "..."]:
    """``x`` as a complex array of :func:`complex_dtype` ``(x, *others)`` (the values unchanged:
    a real x gets a zero imaginary part); ``others`` only take part in choosing the precision."""
    return jnp.asarray(x).astype(complex_dtype(x, *others))


def complex_from(re: RealLike, im: RealLike) -> Complex[Array, "..."]:
    r""":math:`\mathrm{re} + i\,\mathrm{im}` from two real arrays (broadcast together), of
    :func:`complex_dtype` ``(re, im)``: the value ``re + 1j * im`` has for finite inputs, without
    the Python-complex promotion (and without ``0 * inf`` in the real part for an infinite im)."""
    dtype = complex_dtype(re, im)
    real = dtype.type(0).real.dtype
    re, im = jnp.broadcast_arrays(jnp.asarray(re).astype(real), jnp.asarray(im).astype(real))
    return jax.lax.complex(re, im)


def abs2(z: ComplexLike) -> Float[Array, "..."]:
    r""":math:`|z|^2 = (\operatorname{Re} z)^2 + (\operatorname{Im} z)^2` without the square root (and the
    hypot scaling) of ``abs``: cheaper, and its derivative needs no division by :math:`|z|` (finite
    at z = 0). Real array of the shape of ``z``."""
    return jnp.real(z) ** 2 + jnp.imag(z) ** 2


def safe_divide(num: ArrayLike, den: RealLike) -> Inexact[Array, "..."]:
    """``num / den`` where ``den > 0``, else 0, with a finite gradient in both branches.

    For denominators that are physically non-negative (a power flux, a cosine, an intensity):
    a zero or negative one means "no power arrives" and the ratio is 0. ``den`` real;
    ``num`` real or complex; shapes broadcast."""
    ok = den > 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


def safe_divide_nonzero(num: ComplexLike, den: ComplexLike) -> Inexact[Array, "..."]:
    """``num / den`` where ``den != 0``, else 0, with a finite gradient in both branches.

    For denominators of any sign or complex ones (an amplitude, a normal wavevector, the
    denominator of the adding rule for s–p correlations); shapes broadcast."""
    ok = den != 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


def safe_reciprocal(den: ComplexLike) -> Inexact[Array, "..."]:
    """``1 / den``, and 0 where ``den == 0`` (:func:`safe_divide_nonzero` with ``num = 1``)."""
    return safe_divide_nonzero(1.0, den)


def safe_sqrt(x: RealLike) -> Float[Array, "..."]:
    r""":math:`\sqrt{x}` for real ``x > 0``, 0 for ``x <= 0``, with a zero (not infinite or NaN)
    derivative at and below 0 — the zero sub-gradient of the cone :math:`\sqrt{x^2}` at its tip.
    NaN stays NaN (a failed input is not turned into a plausible 0)."""
    nonpositive = x <= 0
    return jnp.where(nonpositive, 0.0, jnp.sqrt(jnp.where(nonpositive, 1.0, x)))


def safe_abs(z: ComplexLike) -> Float[Array, "..."]:
    """:math:`|z|` (:func:`safe_sqrt` of :func:`abs2`): a zero, not NaN, derivative at z = 0."""
    return safe_sqrt(abs2(z))


def safe_atan2(y: RealLike, x: RealLike) -> Float[Array, "..."]:
    r""":math:`\operatorname{atan2}(y, x)` in radians, in :math:`[-\pi, \pi]`, with
    :math:`\operatorname{atan2}(0, 0) = 0` and a zero derivative there instead of NaN.

    Everywhere else value and derivative are those of ``jnp.arctan2`` (signed zeros included:
    ``atan2(-0.0, -1) = -π``). At the origin atan2 has no derivative (no limit either); the
    zero returned there is a convention that keeps a fit or a ΔE gradient finite (neutral greys
    of CIELAB, r_s = r_p = 0 in ellipsometry)."""
    origin = (x == 0) & (y == 0)
    return jnp.where(origin, 0.0, jnp.arctan2(jnp.where(origin, 0.0, y), jnp.where(origin, 1.0, x)))


def sin_from_cos(cos: RealLike) -> Float[Array, "..."]:
    r""":math:`\sin\theta = \sqrt{1 - \cos^2\theta}` of a polar angle θ in [0, π] from its cosine
    (clipped to [0, 1] against rounding: never NaN). Its derivative is infinite at cos = ±1
    (normal incidence); callers that differentiate there use the angle itself."""
    return jnp.sqrt(jnp.clip(1.0 - cos * cos, 0.0, 1.0))
