r"""Cosine and sine of a real array in arithmetic that XLA vectorizes (:func:`_cos_sin`), with
their derivative.

Why it exists: every coherent film needs :math:`e^{i\phi}` — a cosine and a sine — at every
(angle, λ) point (:func:`layerstack_jax._kernels.coherent._phase_factor`; P1 of
``benchmarks/README.md``: 640,000 pairs per evaluation), and XLA's own float64 ``cos`` and
``sin`` on CPU make one scalar library call per element, about 20× the cost of this form, which
XLA compiles to vector instructions fused with the rest of the recursion. The form is fdlibm's:
Cody–Waite reduction by multiples of π/2 and minimax polynomials on [−π/4, π/4], accurate to a
few ulp (the docstring of :func:`_cos_sin`; checked against numpy in
tests/test_kernel_arithmetic.py).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


# Cody–Waite split of π/2 (fdlibm's pio2_1, pio2_2, pio2_3 for float64: 33 + 33 + 53 bits, so
# that n·pio2_1 and n·pio2_2 are exact for |n| < 2^20; Cephes' DP1..3 × 2 for float32) and the
# minimax polynomials of fdlibm's __kernel_sin / __kernel_cos on [-π/4, π/4].
_PIO2 = {"float64": (1.57079632673412561417e+00, 6.07710050630396597660e-11, 2.02226624871116645580e-21),
         "float32": (1.5703125, 4.837512969970703125e-4, 7.54978995489188216e-8)}
_SIN = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
        2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)
_COS = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
        -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)


def _horner(z, coefficients):
    """The polynomial Σ_k coefficients[k]·z^k by Horner's rule."""
    acc = coefficients[-1]
    for c in coefficients[-2::-1]:
        acc = acc * z + c
    return acc


@jax.custom_jvp
def _cos_sin(x):
    r"""``(cos x, sin x)`` of a real array, in arithmetic that XLA vectorizes: reduction by
    n = round(2x/π) with π/2 in three parts (Cody–Waite), fdlibm's kernels on the remainder,
    the quadrant n mod 4 by swaps and sign flips. XLA's own float64 ``cos`` and ``sin`` on CPU
    cost ~20× as much (one scalar call per element), and every film needs both at every
    (angle, λ) point (P1: 640,000 pairs per evaluation). Within 2.2 ulp (|x| ≤ 1e6; absolute
    error ≤ 1.5e-16) of the correctly rounded values in float64, 6e-8 in float32; for |x|
    beyond ~1.6e6 (2^20 · π/2) the reduction loses ~|x|·1e-16 absolute, the size of the
    rounding error the phase itself carries there."""
    p = _PIO2["float64" if x.dtype == jnp.float64 else "float32"]
    n = jnp.round(x * (2 / np.pi))
    r = ((x - n * p[0]) - n * p[1]) - n * p[2]
    z = r * r
    sin = r + r * z * _horner(z, _SIN)
    half = 0.5 * z
    w = 1.0 - half
    cos = w + (((1.0 - w) - half) + z * z * _horner(z, _COS))
    quadrant = (n - 4 * jnp.floor(0.25 * n)).astype(jnp.int32)  # n mod 4: cos x = (c, −s, −c, s)[.], sin x = (s, c, −s, −c)[.]
    odd = (quadrant & 1) == 1
    cos, sin = jnp.where(odd, sin, cos), jnp.where(odd, cos, sin)
    return jnp.where(((quadrant + 1) & 2) == 2, -cos, cos), jnp.where((quadrant & 2) == 2, -sin, sin)


@_cos_sin.defjvp
def _cos_sin_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    cos, sin = _cos_sin(x)
    return (cos, sin), (-sin * dx, cos * dx)
