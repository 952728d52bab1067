"""The coherent kernel's own forms of XLA operations (``_cos_sin._cos_sin``,
``_fresnel._forward_sqrt``, ``_fresnel.divide``): equal to numpy's to a few ulp, the branch of
the square root, exact special values, derivatives."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from layerstack_jax._kernels.cos_sin import _cos_sin
from layerstack_jax._kernels.fresnel import _forward_sqrt, divide


def test_cos_sin_matches_numpy():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-10, 10, 20000), rng.uniform(-1e4, 1e4, 20000), rng.uniform(-1e6, 1e6, 5000),
                        [0.0, -0.0, np.pi / 4, np.pi / 2, np.pi, 1e-300, 2.0**20]])
    cos, sin = jax.jit(_cos_sin)(jnp.asarray(x))
    assert np.max(np.abs(np.asarray(cos) - np.cos(x))) <= 3e-16
    assert np.max(np.abs(np.asarray(sin) - np.sin(x))) <= 3e-16
    c32, s32 = jax.jit(_cos_sin)(jnp.asarray(x[:40000], dtype=jnp.float32))
    assert c32.dtype == jnp.float32
    x32 = np.asarray(x[:40000], np.float32).astype(np.float64)
    assert np.max(np.abs(np.asarray(c32, np.float64) - np.cos(x32))) <= 1.5e-7
    assert np.max(np.abs(np.asarray(s32, np.float64) - np.sin(x32))) <= 1.5e-7


def test_cos_sin_derivative():
    x = jnp.linspace(-20.0, 20.0, 101)
    _, (dc, ds) = jax.jvp(_cos_sin, (x,), (jnp.ones_like(x),))
    np.testing.assert_allclose(np.asarray(dc), -np.sin(np.asarray(x)), atol=3e-16)
    np.testing.assert_allclose(np.asarray(ds), np.cos(np.asarray(x)), atol=3e-16)


def test_forward_sqrt_is_the_decaying_root():
    rng = np.random.default_rng(1)
    m = 10.0 ** rng.uniform(-8, 4, (2, 20000))
    z = np.concatenate([rng.normal(size=20000) * m[0] + 1j * rng.normal(size=20000) * m[1],
                        rng.normal(size=500) + 0j, rng.normal(size=500) - 0j, 1j * rng.normal(size=500),
                        [0j, -0j, 1 - 0j, -1 - 0j, -1 + 0j, -1e-300j]])
    want = np.sqrt(z)
    want = np.where(want.imag < 0, -want, want)
    got = np.asarray(_forward_sqrt(jnp.asarray(z)))
    assert np.all(got.imag >= 0) and np.all(np.isfinite(got))
    assert np.max(np.abs(got - want) / np.maximum(np.abs(want), 1e-300)) <= 4.5e-16


def test_divide():
    rng = np.random.default_rng(2)
    a = rng.normal(size=5000) + 1j * rng.normal(size=5000)
    b = rng.normal(size=5000) + 1j * rng.normal(size=5000)
    got = np.asarray(divide(jnp.asarray(a), jnp.asarray(b)))
    assert np.max(np.abs(got - a / b) / np.abs(a / b)) <= 6e-16
    # a quantity over itself is exactly 1 (an interface at its critical angle: R = 1 exactly)
    assert np.all(np.asarray(divide(jnp.asarray(b), jnp.asarray(b))).real == 1.0)
