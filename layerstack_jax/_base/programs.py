"""One compiled program per public call.

Run op by op, a public function such as :func:`~layerstack_jax.reflectance` makes XLA compile
every small operation it meets the first time (about two hundred programs for one varnish over a
paint). :func:`public_program` compiles the whole call into one program instead, once per *call
structure*, and reuses it for new values:

* **traced data**: every array leaf of the arguments (JAX or NumPy), and every Python float or
  complex that is not zero — indices, thicknesses, α, ρg, dispersion coefficients, angles;
* **static structure**: the pytree structure (number and kinds of layers, coherent flags,
  geometry kind, names), integers (``nodes``), booleans, strings, callables, and Python zeros
  (a zero option such as a port cone of 0° switches a feature off, a choice made while tracing).

The checks stay those of an eager call. While tracing, the checks of
:mod:`layerstack_jax._base.validate` become outputs of the program (:func:`~layerstack_jax._base.validate.collecting_checks`):
when a check fails, the call is made again op by op, which raises the :class:`LayerstackError`
naming the field and its values; flagged plausibility tests are warned on the host. Called on
traced values (inside the user's ``jit``, ``grad`` or ``vmap``) the function runs as it is,
inlined into the user's program. Functions that compile their own core (``coated_rough``,
``he_torrance_brdf``, ``coating_tables``: an ``equinox.filter_jit`` inside) are not wrapped; a
function that cannot be traced as one program runs op by op, as before. :func:`fixed_optics`
is not wrapped either: the optics it returns are reused by many later evaluations, and made from
concrete indices they carry a static layout of the hemispherical nodes (which node segments
reach which layers, :func:`~layerstack_jax._stacks.illumination.hemisphere`) that traced indices
cannot give.

Compiled programs are also kept on disk by JAX's persistent compilation cache, which the first
compilation turns on (:func:`use_compilation_cache`) unless the user configured one or set
``LAYERSTACK_CACHE_DIR`` to the empty string.
"""

from __future__ import annotations

import collections
import functools
import os
import threading
import warnings
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .validate import LayerstackWarning, collecting_checks, is_concrete

__all__ = ["public_program", "use_compilation_cache", "compilation_cache_dir", "CACHE_MAX_BYTES"]

#: Size limit of the compiled programs kept on disk (JAX evicts the least recently used first).
CACHE_MAX_BYTES = 2 ** 30

#: Programs that compiled faster than this are not kept on disk (JAX's default, 1 s, would skip the
#: ~0.5–1 s programs of single public calls, whose first call the cache is meant to spare).
CACHE_MIN_COMPILE_SECONDS = 0.2

#: Programs kept in memory per public function (least recently used dropped first).
_PROGRAMS_PER_FUNCTION = 64

_cache_lock = threading.Lock()


def compilation_cache_dir() -> str:
    """Where compiled programs are kept: ``$LAYERSTACK_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/layerstack/xla`` (``~/.cache/layerstack/xla``); empty when
    ``LAYERSTACK_CACHE_DIR`` is set to the empty string (no cache)."""
    path = os.environ.get("LAYERSTACK_CACHE_DIR")
    if path is not None:
        return path
    return os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"),
                        "layerstack", "xla")


def use_compilation_cache() -> None:
    """Turn on JAX's persistent compilation cache in :func:`compilation_cache_dir` (size-limited
    to :data:`CACHE_MAX_BYTES`), unless a cache directory is configured already or
    ``LAYERSTACK_CACHE_DIR`` is empty. Programs that took at least
    :data:`CACHE_MIN_COMPILE_SECONDS` to compile are kept (unless
    ``jax_persistent_cache_min_compile_time_secs`` was changed from JAX's default).

    A new process then loads the programs an earlier one compiled for the same model structure
    instead of compiling them again, keyed by the program, the JAX version and the compile
    options, so a stale entry is never used."""
    path = compilation_cache_dir()
    with _cache_lock:
        if not path or jax.config.jax_compilation_cache_dir is not None:
            return
        jax.config.update("jax_compilation_cache_dir", path)
        jax.config.update("jax_compilation_cache_max_size", CACHE_MAX_BYTES)
        if jax.config.jax_persistent_cache_min_compile_time_secs == 1.0:  # JAX's default: a public program
            jax.config.update("jax_persistent_cache_min_compile_time_secs", CACHE_MIN_COMPILE_SECONDS)


def _is_traced_leaf(x) -> bool:
    """Whether an argument leaf is data (traced) rather than structure (static)."""
    if isinstance(x, (jax.Array, np.ndarray)):
        return True
    if isinstance(x, (bool, np.bool_)):
        return False
    if isinstance(x, (float, complex, np.floating, np.complexfloating)):
        return x != 0
    return False  # integers (node counts), strings, None, callables


class _Program(NamedTuple):
    run: Callable   # the jitted program: traced leaves -> (arrays, any check failed, plausibility tests)
    meta: dict      # filled while it is traced: "out_tree", "out_static" (non-array leaves), "messages"


def _split_outputs(out):
    leaves, tree = jax.tree_util.tree_flatten(out)
    is_array = [isinstance(x, (jax.Array, np.ndarray, np.generic)) for x in leaves]
    return [x for x, a in zip(leaves, is_array) if a], tree, tuple(None if a else x for x, a in zip(leaves, is_array))


def _join_outputs(meta: dict, arrays):
    it = iter(arrays)
    leaves = [next(it) if s is None else s for s in meta["out_static"]]
    return jax.tree_util.tree_unflatten(meta["out_tree"], leaves)


def public_program(fn: Callable) -> Callable:
    """``fn`` (a public function of concrete inputs) compiled as one program per call structure
    (module docstring). The wrapped function has ``fn``'s signature, docstring and results."""
    programs: collections.OrderedDict = collections.OrderedDict()
    lock = threading.Lock()

    def make_program(treedef, mask, static) -> _Program:
        meta: dict = {}

        def program(*traced_leaves):
            it = iter(traced_leaves)
            leaves = [next(it) if m else s for m, s in zip(mask, static)]
            args, kwargs = jax.tree_util.tree_unflatten(treedef, leaves)
            with collecting_checks() as checks:
                out = fn(*args, **kwargs)
            arrays, meta["out_tree"], meta["out_static"] = _split_outputs(out)
            meta["messages"] = tuple(message for _, _, message in checks.warnings)
            failed = jnp.any(jnp.stack([jnp.any(e) for e in checks.errors])) if checks.errors else jnp.asarray(False)
            return arrays, failed, [(flag, values) for flag, values, _ in checks.warnings]

        return _Program(jax.jit(program), meta)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        if jax.config.jax_disable_jit or not is_concrete((args, kwargs)):
            return fn(*args, **kwargs)  # inside the user's transformation: part of their program
        leaves, treedef = jax.tree_util.tree_flatten((args, kwargs))
        mask = tuple(_is_traced_leaf(x) for x in leaves)
        traced = [x for x, m in zip(leaves, mask) if m]
        static = tuple(None if m else x for x, m in zip(leaves, mask))
        try:
            avals = tuple(jax.typeof(x) for x in traced)
            key = (treedef, mask, static, avals)
            hash(key)
        except TypeError:  # an unhashable static leaf: no program for this call
            return fn(*args, **kwargs)
        with lock:
            program = programs.get(key)
            if program is None:
                program = programs[key] = make_program(treedef, mask, static)
                while len(programs) > _PROGRAMS_PER_FUNCTION:
                    programs.popitem(last=False)
            programs.move_to_end(key)
        if program is False:
            return fn(*args, **kwargs)
        if not program.meta.get("ran"):
            use_compilation_cache()
        try:
            arrays, failed, tests = program.run(*traced)
        except Exception:
            if program.meta.get("ran"):  # it ran before: a genuine error of this call
                raise
            with lock:  # not traceable as one program: op by op, as before, for this call structure
                programs[key] = False
            return fn(*args, **kwargs)
        program.meta["ran"] = True
        if isinstance(failed, jax.core.Tracer):  # called on constants inside the user's transformation
            return fn(*args, **kwargs)
        if bool(failed):  # a check failed: the eager call raises it, naming the field and its values
            return fn(*args, **kwargs)
        for (flag, values), message in zip(tests, program.meta["messages"]):
            if bool(flag):
                warnings.warn(message(jax.tree_util.tree_map(np.asarray, values)), LayerstackWarning, stacklevel=2)
        return _join_outputs(program.meta, arrays)

    call.__wrapped_program__ = fn
    return call
