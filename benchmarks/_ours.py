"""Registration hook for ``layerstack_jax`` benchmarks.

#####################################################################################
#  >>> LAYERSTACK_JAX REGISTRATION HOOK <<<
#
#  Expected API (agreed, not yet landed):
#
#      rt(n, d, wavelengths, angles) -> (R, T)      # jittable
#          n            complex (layers + 2, W)      ambient first, exit last, n + ik
#          d            float   (layers,)            nm
#          wavelengths  float   (W,)                 nm
#          angles       float   (A,)                 rad
#          R, T         float   (2, A, W)            polarizations ordered (s, p)
#
#  To plug it in, put the function's attribute name in API_NAMES below (first match
#  wins), e.g. ``API_NAMES = ("coherent_rt",)``.  Without editing this file, any
#  function with that signature can be benchmarked via the environment variable
#      LAYERSTACK_BENCH_RT="package.module:function"
#  The forward and value-and-gradient (w.r.t. d, objective mean(R)) benchmarks below are
#  then registered for every case in ``BENCH_CASES``, jitted, with compile time measured
#  ahead of time (jit(...).lower(...).compile()).
#####################################################################################
"""

from __future__ import annotations

import importlib
import os
from typing import Any, Callable

import numpy as np

from .cases import CoherentStack

IMPL = "layerstack_jax"
API_NAMES: tuple[str, ...] = ()  # <<< fill in when the API lands, e.g. ("coherent_rt",)
ENV_VAR = "LAYERSTACK_BENCH_RT"
BENCH_CASES: tuple[str, ...] = ("P1",)
BENCH_KINDS: tuple[str, ...] = ("forward", "value_and_grad")


def resolve() -> tuple[Callable | None, str]:
    """(function, description) or (None, reason it is not available)."""
    spec = os.environ.get(ENV_VAR)
    if spec:
        mod_name, _, attr = spec.partition(":")
        try:
            fn = getattr(importlib.import_module(mod_name), attr)
        except Exception as e:
            return None, f"not registered: {ENV_VAR}={spec!r} failed ({type(e).__name__}: {e})"
        return fn, f"{spec} (from ${ENV_VAR})"
    if not API_NAMES:
        try:
            importlib.import_module("layerstack_jax")
        except Exception as e:
            return None, f"not registered: import layerstack_jax failed ({type(e).__name__}: {e})"
        return coherent_rt, "layerstack_jax.specular (via benchmarks._ours.coherent_rt)"
    try:
        mod = importlib.import_module("layerstack_jax")
    except Exception as e:
        return None, f"not registered: import layerstack_jax failed ({type(e).__name__}: {e})"
    for name in API_NAMES:
        fn = getattr(mod, name, None)
        if callable(fn):
            return fn, f"layerstack_jax.{name}"
    return None, f"not registered: none of {API_NAMES} found in layerstack_jax"


def coherent_rt(n, d, wavelengths, angles):
    """The agreed benchmark signature on top of the public API: builds a Stack from index
    arrays (ambient, layers…, exit) and returns R, T shaped (2, A, W)."""
    import jax.numpy as jnp

    import layerstack_jax as ls

    def index(row):
        return ls.Index(jnp.real(row), jnp.imag(row))

    stack = ls.Stack(
        ambient=index(n[0]),
        layers=[ls.Layer(index(n[i + 1]), d[i]) for i in range(d.shape[0])],
        exit=ls.Substrate(index(n[-1])),
    )
    out = ls.specular(stack, wavelengths, angle_rad=angles, both_sides=False)
    return jnp.moveaxis(out.R_front, -2, 0), jnp.moveaxis(out.T_front, -2, 0)


def register(add: Callable[..., None]) -> str:
    """Called by the registry: ``add(case, impl, kind)`` for each benchmark; returns a status line."""
    fn, desc = resolve()
    if fn is None:
        return desc
    for case in BENCH_CASES:
        for kind in BENCH_KINDS:
            add(case, IMPL, kind)
    return f"registered: {desc} for {', '.join(BENCH_CASES)} ({', '.join(BENCH_KINDS)})"


def _unpack_rt(out: Any):
    if isinstance(out, dict):
        return out["R"], out["T"]
    if hasattr(out, "R") and hasattr(out, "T"):
        return out.R, out.T
    R, T = out
    return R, T


def _jax_inputs(stack: CoherentStack):
    import jax

    jax.config.update("jax_enable_x64", True)  # cases are float64
    import jax.numpy as jnp

    return (
        jnp.asarray(stack.n, dtype=jnp.complex128),
        jnp.asarray(stack.d, dtype=jnp.float64),
        jnp.asarray(stack.wavelengths, dtype=jnp.float64),
        jnp.asarray(stack.angles, dtype=jnp.float64),
    )


def build_forward(stack: CoherentStack):
    from ._peers import Built

    fn, desc = resolve()
    if fn is None:
        raise RuntimeError(desc)
    import jax

    args = _jax_inputs(stack)
    jitted = jax.jit(lambda n, d, wl, th: _unpack_rt(fn(n, d, wl, th)))
    if stack.pols != ("s", "p"):
        raise ValueError("layerstack_jax returns both polarizations (s, p)")
    return Built(
        fn=jitted,
        args=args,
        to_numpy=lambda o: (np.asarray(o[0], np.float64), np.asarray(o[1], np.float64)),
        notes=[f"{desc}, jax.jit, x64, backend {jax.default_backend()}"],
    )


def build_value_and_grad(stack: CoherentStack):
    from ._peers import Built

    fn, desc = resolve()
    if fn is None:
        raise RuntimeError(desc)
    import jax
    import jax.numpy as jnp

    n, d, wl, th = _jax_inputs(stack)

    def objective(d_, n_, wl_, th_):
        R, _ = _unpack_rt(fn(n_, d_, wl_, th_))
        return jnp.mean(R)

    vg = jax.jit(jax.value_and_grad(objective))
    return Built(
        fn=vg,
        args=(d, n, wl, th),
        to_numpy=lambda o: (float(o[0]), np.asarray(o[1], np.float64)),
        notes=[f"{desc}, jax.jit(jax.value_and_grad), objective mean(R) over pols x angles x wavelengths"],
    )
