"""The jit of a single fit's programs (:class:`fit_jit`): compiled with
:data:`SINGLE_FIT_COMPILER_OPTIONS` on the CPU where they apply."""

from __future__ import annotations

import functools
import os
from typing import Callable, Optional

import jax

__all__ = ["SINGLE_FIT_COMPILER_OPTIONS", "fit_jit"]


#: XLA options of the compiled programs of a single fit on the CPU (:func:`fit_jit`): XLA's
#: classic fusion emitters rather than its MLIR ones. A fit of one measurement spends most of
#: its time compiling (E1: 3-angle × 700-λ ψ/Δ, Cauchy film on SiO2/Si: half the XLA time for
#: the solver's program, the further fits as fast; benchmarks/results/ellipsometry_fit_history.md);
#: batched fits (``fit_batch``, ``fit_cube``: run time dominates) keep XLA's defaults.
SINGLE_FIT_COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


@functools.cache
def _compiler_options(backend: str) -> Optional[dict]:
    """:data:`SINGLE_FIT_COMPILER_OPTIONS` where they apply: on the CPU backend, when this XLA
    knows them (probed once on a trivial program: an XLA without the option refuses it) and the
    user has not set one of them in ``XLA_FLAGS`` (theirs win); else None (XLA's defaults)."""
    flags = os.environ.get("XLA_FLAGS", "")
    if backend != "cpu" or any(name in flags for name in SINGLE_FIT_COMPILER_OPTIONS):
        return None
    try:
        jax.jit(lambda v: v + 1, compiler_options=SINGLE_FIT_COMPILER_OPTIONS).lower(1.0).compile()
    except Exception:  # noqa: BLE001 — an XLA without the option: its defaults
        return None
    return dict(SINGLE_FIT_COMPILER_OPTIONS)


class fit_jit:
    """``jax.jit(fn)`` for a single fit's programs: called from Python (not under a JAX
    transformation) it compiles with :data:`SINGLE_FIT_COMPILER_OPTIONS` on the CPU
    (:func:`_compiler_options`), and its attributes (``lower``, ``_cache_size`` …) are that
    function's; traced inside another function, where JAX takes compiler options only from the
    outermost ``jit``, it is the plain ``jax.jit(fn)``."""

    def __init__(self, fn: Callable):
        self.jitted = jax.jit(fn)
        options = _compiler_options(jax.default_backend())
        self.top = self.jitted if options is None else jax.jit(fn, compiler_options=options)

    def __call__(self, *args, **kwargs):
        traced = any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves((args, kwargs)))
        return (self.jitted if traced else self.top)(*args, **kwargs)

    def __getattr__(self, name):
        try:
            top = object.__getattribute__(self, "top")
        except AttributeError:  # not built yet (copy, pickle)
            raise AttributeError(name) from None
        return getattr(top, name)
