"""Shared helpers for the layerstack_jax test-suite (no expected values are computed here with
the library: these only build inputs and batch calls)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

import layerstack_jax as ls

INF = np.inf


def index_leaf(x):
    """``Index`` whose n and k are float64 JAX arrays (pytree leaves that vmap/jit can trace)."""
    x = complex(x)
    return ls.Index(jnp.asarray(x.real, dtype=jnp.float64), jnp.asarray(x.imag, dtype=jnp.float64))


def build_stack(n_list, d_list, coherent=None, alpha=None, *, leaves=False, background=None):
    """Stack from tmm-style lists (outer media first/last, their thicknesses ignored).

    ``coherent``: one bool per interior layer (default all coherent); ``alpha``: one value (or
    None) per interior layer; ``leaves``: wrap every number in a JAX array (for batching);
    ``background``: ρg to put a LambertianBackground of index n_list[-1] as exit.
    """
    n_list = list(n_list)
    K = len(n_list) - 2
    coherent = [True] * K if coherent is None else list(coherent)
    alpha = [None] * K if alpha is None else list(alpha)
    mk = index_leaf if leaves else (lambda x: ls.Index(complex(x).real, complex(x).imag))
    th = (lambda x: jnp.asarray(float(x), dtype=jnp.float64)) if leaves else float
    layers = [
        ls.Layer(mk(n), th(d), coherent=c, alpha=None if a is None else th(a))
        for n, d, c, a in zip(n_list[1:-1], list(d_list)[1:-1], coherent, alpha)
    ]
    exit_ = ls.Substrate(mk(n_list[-1])) if background is None else ls.LambertianBackground(mk(n_list[-1]), background)
    return ls.Stack(ambient=mk(n_list[0]), layers=layers, exit=exit_)


def tree_stack(trees):
    """Stack a list of identically structured pytrees along a new leading axis."""
    return jax.tree.map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *trees)


def pad_index_matched(n_list, d_list, K_target, rng, coherent=None, alpha=None, *, pad_coherent=True):
    """Insert zero-thickness, index-matched (copy of the medium above) layers at random positions
    until the stack has ``K_target`` interior layers: an exact optical no-op (interfaces with
    r = 0, t = 1, no phase, no attenuation; PHYSICS.md trap 7), used so that stacks of 1..K
    layers share one compiled shape. ``coherent`` / ``alpha`` (per interior layer) are padded
    along (inserted layers: ``pad_coherent``, α = 0 if incoherent)."""
    n = list(n_list)
    d = list(d_list)
    c = None if coherent is None else list(coherent)
    a = None if alpha is None else list(alpha)
    while len(n) - 2 < K_target:
        pos = int(rng.integers(1, len(n)))  # insert before medium `pos` (1..len-1)
        n.insert(pos, n[pos - 1])
        d.insert(pos, 0.0)
        if c is not None:
            c.insert(pos - 1, pad_coherent)
        if a is not None:
            a.insert(pos - 1, None if pad_coherent else 0.0)
    return n, d, c, a


def snell_angle(n_from: float, n_to: float, theta: float) -> float:
    """Angle in real medium n_to for the Snell invariant n_from sin(theta) (must propagate)."""
    return math.asin(n_from * math.sin(theta) / n_to)


def max_abs(a, b) -> float:
    """max |a - b| (0 for empty arrays; NaN propagates as NaN so comparisons fail)."""
    diff = np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))
    if diff.size == 0:
        return 0.0
    return float(np.max(diff)) if not np.any(np.isnan(diff)) else float("nan")


#: jitted entry point (one compile per stack structure and array shapes; Python-float leaves of
#: the stack are traced, so changing values never recompiles)
# angles in radians (ls.specular takes degrees; angle_rad= says radians)
specular_jit = jax.jit(lambda st, wl, angle_rad, both_sides=True: ls.specular(st, wl, angle_rad=angle_rad, both_sides=both_sides),
                       static_argnames=("both_sides",))


# --------------------------------------------------------------------------- XLA compilations
_COMPILES = {"on": False, "n": 0}


def _count_compiles(event, duration, **kw):
    if _COMPILES["on"] and event == "/jax/core/compile/backend_compile_duration":
        _COMPILES["n"] += 1


jax.monitoring.register_event_duration_secs_listener(_count_compiles)


def compiles(f, *args, **kwargs):
    """``(f(...), number of XLA compilations it made)`` (JAX's compile events: a public API,
    unlike a jitted function's ``_cache_size``, whose C++ fast-path cache may stay empty)."""
    _COMPILES.update(on=True, n=0)
    try:
        out = f(*args, **kwargs)
    finally:
        _COMPILES["on"] = False
    return out, _COMPILES["n"]


def relative_error(a, b) -> float:
    """max |a - b| / max |b| (the absolute error where b is empty or all zero)."""
    a, b = np.asarray(a), np.asarray(b)
    scale = np.max(np.abs(b), initial=0.0)
    err = np.max(np.abs(a - b), initial=0.0)
    return float(err / scale) if scale > 0 else float(err)
