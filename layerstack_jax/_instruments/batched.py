r"""Batched prediction: many spectra of one stack structure, in chunks of bounded memory.

Any leaf of a :class:`~layerstack_jax.Stack` — a thickness, α(λ), ρg(λ), an index n or k, a
dispersion coefficient — may carry leading *batch* axes; :func:`predict` returns what
:func:`~layerstack_jax.reflectance` returns for one stack, with those axes in front:
``(*batch, *angle, wl)``.

Which axes of a leaf are batch axes (the rule the :class:`~layerstack_jax.Layer` docstring
states: leaves broadcast against ``(*batch, wl)``):

* *spectral* leaves — ``Layer.thickness``, ``Layer.alpha``, ``LambertianBackground.reflectance``,
  ``Index.n``/``k``, ``Cauchy.A``/``B``/``C``/``k``, ``Sellmeier.k`` … (each field declares its role
  where it is defined: :mod:`layerstack_jax._base.leaves`) — are a scalar, ``(1,)`` or
  ``(wl,)`` for one stack; with batch axes they are ``(*batch, 1)`` or ``(*batch, wl)``. When
  ``batch_shape`` is given, ``(*batch_shape,)`` (one scalar per spectrum, no trailing axis) is
  accepted too.
* *vector* leaves — ``Sellmeier.B``/``C``, tabulated values (``TabulatedSpectrum.values``,
  ``Tabulated.n``/``k``), database formula coefficients — are ``(m,)`` for one stack and
  ``(*batch, m)`` batched.

The batch shape is ``batch_shape`` if given, else the broadcast of the leaves' batch parts. A
leaf whose batch part does not broadcast to it raises a :class:`LayerstackError` naming the
field (``layers[0].thickness``, ``exit.reflectance`` …).

How it runs (PHYSICS.md, trap 8): the batch is flattened to N spectra; one jitted function per
model structure and shared values evaluates ``step`` spectra per call as
``jax.lax.map(spectrum, rows, batch_size=chunk)`` — XLA vmaps the forward model over blocks of
``chunk`` spectra and loops over the blocks, so the intermediates scale with ``chunk``, never
with N. A Python loop only over calls (the last one padded, so one compiled shape serves all)
copies each call's result into the output array on the host and advances a progress bar. On a
machine with several accelerators (``jax.local_devices()``) each call is split over all of them
by ``jax.shard_map`` along the spectra: one process drives every device, each running the same
chunked ``lax.map`` on its share of the rows (equal to one device's result: tests/test_sharding.py).
Leaves that are not batched stay constants of the compiled function (critical angles and
quadrature segments are laid out once); when only thick-layer thicknesses, α and ρg are
batched, the Fresnel algebra (:func:`~layerstack_jax.fixed_optics`) is computed once, not per
spectrum. Inside ``jax.jit``/``jax.grad`` (traced leaves) the same ``lax.map`` runs in the
caller's trace and a JAX array is returned. With Dask arrays among the leaves, :func:`predict`
returns a lazy Dask array, one task per block of the batch, computed on whatever scheduler is
active (threads, processes, a ``distributed.Client``): each worker process compiles once per
structure (the cache above) and runs this same chunked loop on its block.

``chunk="auto"`` (the default) sizes the vmapped block from the memory available where the
work runs (:func:`memory_budget`: a Dask worker's memory limit inside a worker, else this
process's available memory, and an accelerator's free memory): the program compiled for
``min(AUTO_CHUNK_MAX, N)`` spectra per block is measured (``compiled.memory_analysis()``:
temp + argument + output bytes), and used as it is if it fits the budget; otherwise the block
shrinks to ``⌊(budget − argument − output) / (temp / chunk)⌋`` spectra (the working memory per
spectrum measured on that program) and a budget that cannot hold one spectrum is a
:class:`LayerstackError` naming ``chunk``. The sizes chosen and the budget are logged
(``layerstack_jax.batched`` logger) and remembered per compiled program.

Leaves are checked by the stack's own constructors: a Dask leaf is read once there (its
non-negativity check), so very large batches should come as NumPy arrays (or memmaps).
"""

from __future__ import annotations

import collections
import hashlib
import logging
import math
import time
from typing import Callable, NamedTuple, Optional, Union

import jax
import jax.numpy as jnp
import numpy as np

from .._base.leaves import stack_leaves
from .._base.memory import MemoryBudget, memory_budget
from .._base.progress import reporter
from .._base.validate import LayerstackError, collecting_checks, is_concrete
from .._kernels.quadrature import DEFAULT_NODES
from .._stacks.stack import Stack, check_stack
from .geometry import Geometry, fixed_optics, reflectance

__all__ = ["predict", "batch_layout", "BatchLayout", "DEFAULT_CHUNK", "DEFAULT_STEP", "AUTO_CHUNK_MAX"]

#: Spectra per vmapped block inside ``lax.map`` (bounds the intermediates: ~1.7 MB per P2 spectrum)
#: where ``chunk="auto"`` cannot measure (inside a JAX transformation, or no memory analysis).
DEFAULT_CHUNK = 4
#: Largest ``chunk="auto"`` block, by platform: on CPU blocks larger than ~10 spectra only slow
#: down (benchmarks/README.md: 1388 → 602 spectra/s from chunk 10 to 1000); accelerators gain
#: from wide blocks.
AUTO_CHUNK_MAX = {"cpu": 8, "default": 1024}
#: Spectra per compiled call (one progress update; the host copies this many spectra at a time).
DEFAULT_STEP = 2048

log = logging.getLogger("layerstack_jax.batched")

class BatchLayout(NamedTuple):
    """How the leaves of a stack are batched (made by :func:`batch_layout`).

    ``batch_shape``: the leading axes of the result; ``batched``: per leaf of
    ``jax.tree_util.tree_flatten(stack)``, True if it carries batch axes; ``cores``: per leaf,
    the shape of one stack's value (``()``, ``(1,)``, ``(wl,)``, ``(m,)``); ``names``: per leaf,
    the field name used in messages (``layers[0].thickness``)."""

    batch_shape: tuple
    batched: tuple
    cores: tuple
    names: tuple


def _field_names(stack: Stack):
    """Per leaf: (readable field name, axes role) — as each field declares it (:mod:`layerstack_jax._base.leaves`)."""
    return [(leaf.name, leaf.role.axes) for leaf in stack_leaves(stack)]


def _broadcasts(part: tuple, batch: tuple) -> bool:
    """True if ``part`` (a leaf's batch axes) broadcasts to ``batch`` (numpy rules)."""
    if len(part) > len(batch):
        return False
    return all(p in (1, b) for p, b in zip(part[::-1], batch[::-1]))


def _split_leaf(name: str, role: str, shape: tuple, wl: int, batch: Optional[tuple]):
    """``(batch part or None if shared, core shape)`` of one leaf; raises naming the field."""
    hint = (f"{name}: shape {shape} does not fit a batch of stacks on {wl} wavelengths: give it as "
            "(*batch, 1) for one value per spectrum, (*batch, wl) for one spectrum each")
    if role == "spectral":
        if batch is not None:
            nb = len(batch)
            cores = ((), (1,), (wl,))
            as_batched = nb > 0 and len(shape) >= nb and shape[nb:] in cores and _broadcasts(shape[:nb], batch)
            as_shared = shape in cores
            if as_batched and as_shared and shape != (1,):
                raise LayerstackError(
                    f"{name}: shape {shape} is ambiguous for batch_shape {batch} on {wl} wavelengths (one value per "
                    f"spectrum, or one spectrum shared by all?): give it as {batch + (1,)} or as (1, {wl})")
            if as_shared:
                return None, shape
            if as_batched:
                return shape[:nb], shape[nb:]
            raise LayerstackError(hint + f" (batch_shape {batch})")
        if len(shape) <= 1:
            if shape in ((), (1,), (wl,)):
                return None, shape
            raise LayerstackError(hint + ", or pass batch_shape=")
        if shape[-1] not in (1, wl):
            raise LayerstackError(hint)
        return shape[:-1], shape[-1:]
    # vector leaves: one trailing core axis at most
    if batch is not None:
        nb = len(batch)
        if nb and len(shape) == nb + 1 and _broadcasts(shape[:nb], batch):
            return shape[:nb], shape[nb:]
        if len(shape) <= 1:
            return None, shape
        raise LayerstackError(f"{name}: shape {shape} is neither one stack's value (m,) nor (*{batch}, m)")
    if len(shape) <= 1:
        return None, shape
    return shape[:-1], shape[-1:]


def batch_layout(stack: Stack, n_wavelengths: int, batch_shape=None) -> BatchLayout:
    """Which leaves of ``stack`` carry batch axes, and the batch shape (module docstring).

    Args:
        stack: a :class:`~layerstack_jax.Stack` whose leaves may carry leading batch axes.
        n_wavelengths: length of the wavelength grid.
        batch_shape: the batch shape, or None to infer it from the leaves.

    Raises :class:`LayerstackError` naming the field whose shape does not fit."""
    if not isinstance(stack, Stack):
        raise LayerstackError(f"predict: stack must be a layerstack_jax.Stack, got {type(stack).__name__}")
    if batch_shape is None:
        batch = None
    else:
        batch = tuple(int(b) for b in (batch_shape if isinstance(batch_shape, (tuple, list)) else (batch_shape,)))
    if batch is not None and any(b < 1 for b in batch):
        raise LayerstackError(f"batch_shape must hold positive lengths, got {batch_shape!r}")
    leaves = jax.tree_util.tree_leaves(stack)
    info = _field_names(stack)
    parts, cores = [], []
    for (name, role), leaf in zip(info, leaves):
        part, core = _split_leaf(name, role, tuple(np.shape(leaf)), int(n_wavelengths), batch)
        parts.append(part)
        cores.append(core)
    if batch is None:
        try:
            batch = tuple(np.broadcast_shapes(*[p for p in parts if p is not None]))
        except ValueError:
            shown = ", ".join(f"{n} {p}" for (n, _), p in zip(info, parts) if p is not None)
            raise LayerstackError(f"the batch axes of the leaves do not broadcast together: {shown}") from None
    else:
        for (name, _), p in zip(info, parts):
            if p is not None and not _broadcasts(p, batch):
                raise LayerstackError(f"{name}: batch axes {p} do not broadcast to batch_shape {batch}")
    return BatchLayout(batch, tuple(p is not None for p in parts), tuple(cores), tuple(n for n, _ in info))


def _optics_fixed_by(stack: Stack, names: tuple, batched: tuple) -> bool:
    """True if every batched leaf leaves :func:`fixed_optics` unchanged (its field says so: a thick
    layer's thickness, α, ρg, a scattering body's numbers), so the Fresnel algebra can be computed
    once for the batch."""
    return all(leaf.fixed_optics for leaf, b in zip(stack_leaves(stack), batched) if b)


def _digest(tree) -> str:
    """Content hash of a pytree of constants (values, shapes, dtypes, structure)."""
    h = hashlib.sha1()
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    h.update(str(treedef).encode())
    for leaf in leaves:
        a = np.asarray(leaf)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


_COMPILED: "collections.OrderedDict[tuple, Callable]" = collections.OrderedDict()
_MAX_COMPILED = 8
#: ``(compiled-program key, step) -> (temp, argument, output bytes)`` measured by ``chunk="auto"``
_MEASURED: "collections.OrderedDict[tuple, tuple]" = collections.OrderedDict()


def _spectrum_function(treedef, shared: list, batched: tuple, wl, geometry: Geometry, nodes: int, optics):
    """``rows -> (one spectrum, implausible)``: the stack rebuilt from shared constants and one
    batch row; ``implausible``: any of its plausibility tests (µm for nm …) flagged the row
    (:func:`~layerstack_jax._base.validate.collecting_checks`: a flag per row instead of a call back
    to the host from inside the loop)."""

    def spectrum(rows):
        it = iter(rows)
        leaves = [next(it) if b else s for s, b in zip(shared, batched)]
        stack = jax.tree_util.tree_unflatten(treedef, leaves)
        with collecting_checks(errors=False) as checks:
            out = reflectance(stack, wl, geometry, nodes=nodes, optics=optics)
        flags = [jnp.any(flag) for flag, _, _ in checks.warnings]
        return out, jnp.any(jnp.stack(flags)) if flags else jnp.zeros((), bool)

    return spectrum


def _compiled(stack: Stack, lay: BatchLayout, wl, geometry: Geometry, nodes: int, chunk: int, use_optics: bool,
              template_rows: tuple, with_key: bool = False):
    """The jitted ``rows (step, *core) -> spectra (step, *angle, wl)`` for this structure and
    these shared values; cached (``_MAX_COMPILED`` entries, least recently used dropped).
    ``with_key``: ``(function, cache key)``."""
    leaves, treedef = jax.tree_util.tree_flatten(stack)
    shared = [None if b else leaf for leaf, b in zip(leaves, lay.batched)]
    key = (treedef, lay.batched, tuple((r.shape[1:], r.dtype.str) for r in template_rows),
           _digest([s for s in shared if s is not None]), _digest((geometry, np.asarray(wl))), nodes, chunk, use_optics)
    fn = _COMPILED.get(key)
    if fn is not None:
        _COMPILED.move_to_end(key)
        return (fn, key) if with_key else fn
    optics = None
    if use_optics:
        first = iter(r[0] for r in template_rows)
        one = jax.tree_util.tree_unflatten(treedef, [next(first) if b else s for s, b in zip(shared, lay.batched)])
        optics = fixed_optics(one, wl, geometry, nodes=nodes)
    spectrum = _spectrum_function(treedef, shared, lay.batched, wl, geometry, nodes, optics)
    fn = jax.jit(_over_devices(lambda rows: jax.lax.map(spectrum, rows, batch_size=chunk)))
    _COMPILED[key] = fn
    while len(_COMPILED) > _MAX_COMPILED:
        _COMPILED.popitem(last=False)
    return (fn, key) if with_key else fn


def _auto_chunk_max() -> int:
    """The largest ``chunk="auto"`` block on the default backend (:data:`AUTO_CHUNK_MAX`)."""
    return AUTO_CHUNK_MAX.get(jax.default_backend(), AUTO_CHUNK_MAX["default"])


def _memory_of(fn: Callable, key: tuple, rows: tuple, step: int) -> Optional[tuple]:
    """``(temp, argument, output)`` bytes of ``fn`` compiled for ``step`` rows shaped like
    ``rows`` (``compiled.memory_analysis()``; the compilation is jit's own, reused by the call
    that follows); None where the backend gives no analysis. Remembered per program and step."""
    mkey = (key, step)
    if mkey in _MEASURED:
        _MEASURED.move_to_end(mkey)
        return _MEASURED[mkey]
    shapes = tuple(jax.ShapeDtypeStruct((step,) + r.shape[1:], r.dtype) for r in rows)
    try:
        m = fn.lower(shapes).compile().memory_analysis()
    except Exception as e:  # a backend without memory analysis  # pragma: no cover
        log.debug("predict: no memory analysis (%s)", e)
        return None
    if m is None:  # pragma: no cover
        return None
    found = (int(m.temp_size_in_bytes), int(m.argument_size_in_bytes), int(m.output_size_in_bytes))
    _MEASURED[mkey] = found
    while len(_MEASURED) > 4 * _MAX_COMPILED:
        _MEASURED.popitem(last=False)
    return found


def _step_for(step: int, chunk: int, n: int) -> int:
    """``step`` rounded up to a multiple of ``chunk`` × local devices, at most N rounded up so."""
    per_call = chunk * len(jax.local_devices())  # one chunk per device at least: equal device shares
    return int(-(-min(max(int(step), per_call), n) // per_call) * per_call)


def _resolve_auto_chunk(build: Callable, rows: tuple, step: int, n: int, memory: Optional[int]):
    """``(chunk, step, fn)`` for ``chunk="auto"``: the program for ``c = min(AUTO_CHUNK_MAX, N)``
    spectra per block is compiled and measured (temp ``T``, arguments ``A``, outputs ``O``
    bytes of one call of ``step`` spectra); if ``T + A + O`` fits the budget it is used, else
    the block shrinks to ``⌊(budget − A − O) / (T / c)⌋`` spectra (``T / c``: the working
    memory per spectrum measured), at least 1 (else a LayerstackError naming ``chunk``)."""
    budget = (MemoryBudget(int(memory), int(memory), 1.0, "given (memory=)") if memory is not None
              else memory_budget(device=True))
    chunk = min(_auto_chunk_max(), n)
    fn, key = build(chunk)
    call = _step_for(step, chunk, n)
    found = _memory_of(fn, key, rows, call)
    if found is None:  # pragma: no cover - no analysis: the fixed default
        chunk = min(DEFAULT_CHUNK, n)
        log.info("predict: chunk auto -> %d (the default: no memory analysis on %s)", chunk, jax.default_backend())
        return chunk, _step_for(step, chunk, n), build(chunk)[0]
    temp, args, outs = found
    per_spectrum = temp / chunk
    if temp + args + outs > budget.bytes:
        fits = int((budget.bytes - args - outs) // per_spectrum) if per_spectrum > 0 else chunk
        if fits < 1:
            raise LayerstackError(
                f"predict: chunk: the memory budget {budget.describe()} cannot hold one block of 1 spectrum: "
                f"{per_spectrum / 1e6:.4g} MB of working memory per spectrum plus {(args + outs) / 1e6:.4g} MB for "
                f"the {call} spectra of one call in and out (lower step=, or give the process more memory)")
        chunk = fits
        fn, key = build(chunk)
        call = _step_for(step, chunk, n)
    log.info("predict: chunk auto -> %d spectra per block, step %d (measured %.4g MB working memory per spectrum, "
             "%.4g MB per call of %d spectra in and out); budget %s", chunk, call, per_spectrum / 1e6,
             (args + outs) / 1e6, call, budget.describe())
    return chunk, call, fn


def _over_devices(blocks: Callable) -> Callable:
    """``blocks`` (rows ``(step, *core)`` -> ``(step, ...)``) split over every local device.

    With one device, ``blocks`` itself. With several (accelerators, or CPU devices made by
    ``XLA_FLAGS=--xla_force_host_platform_device_count``), a ``jax.shard_map`` over a 1-D mesh
    of them: each device runs the same chunked ``lax.map`` on its contiguous share of the rows
    (``step`` is a multiple of ``chunk`` × devices, see :func:`predict`), and the results come
    back in row order. No communication between devices: the spectra are independent."""
    devices = jax.local_devices()
    if len(devices) == 1:
        return blocks
    mesh = jax.sharding.Mesh(np.array(devices), ("spectra",))
    spec = jax.sharding.PartitionSpec("spectra")
    # check_vma=False: the traced validation (an equinox error branch on replicated constants) mixes
    # device-varying and replicated values in one cond; every output row is per-device anyway
    return jax.shard_map(blocks, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False)


def _rows(leaf, batch: tuple, core: tuple, flat_index: np.ndarray):
    """Rows ``flat_index`` of a batched leaf broadcast to ``(*batch, *core)``: ``(len, *core)``,
    copying only those rows (the broadcast itself is a view)."""
    a = np.asarray(leaf)
    view = np.broadcast_to(a, batch + core)
    return np.ascontiguousarray(view[np.unravel_index(flat_index, batch)])


def predict(stack: Stack, wavelength_nm, geometry: Geometry, *, batch_shape=None, chunk: Union[int, str] = "auto",
            step: int = DEFAULT_STEP, progress: Union[None, bool, Callable[[int, int], None]] = None,
            nodes: int = DEFAULT_NODES, out: Optional[np.ndarray] = None, memory: Optional[int] = None):
    r"""What :func:`~layerstack_jax.reflectance` reads for every stack of a batch (module docstring).

    Args:
        stack: a stack whose leaves may carry leading batch axes (spectral leaves broadcast
            against ``(*batch, wl)``: a thickness per spectrum is ``(*batch, 1)``, or
            ``(*batch,)`` when ``batch_shape`` is given).
        wavelength_nm: ``(wl,)`` vacuum wavelengths in nm.
        geometry: any :class:`~layerstack_jax.Geometry` (angles in degrees; array angles add
            ``(*angle)`` axes after the batch axes).
        batch_shape: the batch axes, or None to infer them from the leaves.
        chunk: spectra per vmapped block (memory: about 1.7 MB per spectrum for a 401-λ sphere
            prediction over a background), or ``"auto"`` (default): sized from the memory
            available where the work runs (module docstring; :func:`memory_budget`), at most
            :data:`AUTO_CHUNK_MAX` (8 on CPU); :data:`DEFAULT_CHUNK` inside a transformation.
        step: spectra per compiled call (rounded up to a multiple of ``chunk`` times the
            number of local devices): the host copies and the progress bar advances once per
            call. With several devices each call is split over all of them (module docstring).
        progress: True for a progress bar (tqdm), a callable ``f(done, total)``, or None/False.
            None shows a bar when more than 100,000 spectra are predicted.
        nodes: Gauss–Legendre nodes per critical-angle segment of the diffuse integrals.
        out: optional preallocated float array ``(*batch, *angle, wl)`` (e.g. a
            ``numpy.memmap``) to write into; returned.
        memory: bytes ``chunk="auto"`` may fill (default: :func:`memory_budget` where the
            work runs, e.g. each Dask worker's own).

    Returns:
        ``(*batch, *angle, wl)``, in the unit the geometry reads (a dimensionless reflectance
        (factor), 1/sr for :class:`~layerstack_jax.BRDF`): a NumPy array (or ``out``) for
        concrete inputs, a JAX array when called inside a transformation (``jax.jit``,
        ``jax.grad``, ``jax.vmap``), where it is differentiable like
        :func:`~layerstack_jax.reflectance`.

    Raises :class:`LayerstackError` naming the field whose batch axes do not fit, for a bad
    ``chunk``/``step``, or for an invalid stack (negative thickness, ρg outside [0, 1], …).
    """
    if not isinstance(geometry, Geometry):
        raise LayerstackError(f"predict: geometry must be a layerstack_jax Geometry, got {geometry!r}")
    for what, v in (("chunk", chunk), ("step", step)):
        if what == "chunk" and isinstance(v, str) and v == "auto":
            continue
        if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1):
            allowed = "an integer >= 1 or 'auto'" if what == "chunk" else "an integer >= 1"
            raise LayerstackError(f"predict: {what} must be {allowed}, got {v!r}")
    if memory is not None and not (isinstance(memory, (int, np.integer)) and memory >= 1):
        raise LayerstackError(f"predict: memory must be a number of bytes >= 1, got {memory!r}")
    wl = wavelength_nm if not is_concrete(wavelength_nm) else np.asarray(wavelength_nm, dtype=float)
    if np.ndim(wl) != 1:
        raise LayerstackError(f"wavelength_nm must be 1-D, got shape {np.shape(wl)}")
    lay = batch_layout(stack, np.shape(wl)[0], batch_shape)
    leaves, treedef = jax.tree_util.tree_flatten(stack)
    batch = lay.batch_shape
    n = math.prod(batch)
    if not any(lay.batched):  # nothing batched: one spectrum, repeated over an explicit batch_shape
        value = reflectance(stack, wl, geometry, nodes=nodes)
        value = jnp.broadcast_to(value, batch + value.shape)
        return np.array(value) if is_concrete((stack, wl, geometry)) else value
    auto = isinstance(chunk, str)
    if any(_is_dask(leaf) for leaf in leaves):
        return _predict_dask(leaves, treedef, lay, wl, geometry, nodes, chunk if auto else int(chunk), int(step),
                             memory)
    if not is_concrete((stack, wl, geometry)):
        return _predict_traced(leaves, treedef, lay, wl, geometry, nodes, DEFAULT_CHUNK if auto else int(chunk))
    batched = [(leaf, core) for leaf, core, b in zip(leaves, lay.cores, lay.batched) if b]
    first = tuple(_rows(leaf, batch, core, np.zeros(1, int)) for leaf, core in batched)
    use_optics = _optics_fixed_by(stack, lay.names, lay.batched)

    def build(c):
        return _compiled(stack, lay, wl, geometry, nodes, c, use_optics, first, with_key=True)

    if auto:
        chunk, step, fn = _resolve_auto_chunk(build, first, int(step), n, memory)
    else:
        chunk = int(min(chunk, n))
        step = _step_for(step, chunk, n)
        fn = build(chunk)[0]
    update = reporter(progress, n, desc="predict", unit="spectrum", auto=n > 100_000)
    t0 = time.perf_counter()
    flat_out = None
    warned = False
    for start in range(0, n, step):
        idx = np.arange(start, start + step)
        valid = min(step, n - start)
        idx[valid:] = start  # pad the last call with copies of its first row: one compiled shape
        rows = tuple(_rows(leaf, batch, core, idx) for leaf, core in batched)
        values, implausible = fn(rows)
        values = np.asarray(values)
        if not warned and np.any(np.asarray(implausible)[:valid]):  # the first flagged row, eagerly: the message
            warned = True                                             # names the field and its values
            row = int(np.argmax(np.asarray(implausible)[:valid]))
            one = iter(r[row] for r in rows)
            check_stack(jax.tree_util.tree_unflatten(treedef, [next(one) if b else leaf for leaf, b
                                                               in zip(leaves, lay.batched)]), wl)
        if flat_out is None:
            out, flat_out = _output(out, batch, values.shape[1:], values.dtype)
        flat_out[start:start + valid] = values[:valid]
        if update is not None:
            update(start + valid)
    elapsed = time.perf_counter() - t0
    log.info("predicted %d spectra in %.3g s (%.4g spectra/s, chunk %d, step %d)", n, elapsed,
             n / max(elapsed, 1e-12), chunk, step)
    return out


def _output(out, batch: tuple, tail: tuple, dtype):
    """The result array ``(*batch, *tail)`` (``out`` checked, or a new one) and its flat view ``(N, *tail)``."""
    if out is None:
        out = np.empty(batch + tail, dtype=dtype)
    elif tuple(out.shape) != batch + tail:
        raise LayerstackError(f"predict: out has shape {tuple(out.shape)}, the result is {batch + tail}")
    flat = out.reshape((math.prod(batch),) + tail)  # a view for C-contiguous arrays and memmaps
    if not np.shares_memory(flat, out):
        raise LayerstackError("predict: out must be C-contiguous")
    return out, flat


def _is_dask(x) -> bool:
    return type(x).__module__.startswith("dask.") and hasattr(x, "chunks")


def _dask_block(*blocks, template, batched, core_ndim, wl, geometry, nodes, chunk, step, x64, memory=None):
    """One block of :func:`_predict_dask`: the numpy path of :func:`predict` on the block's stacks
    (runs on a Dask worker: compiles once per worker process and structure, then reuses).
    ``template``: one stack of the batch (a pytree definition does not survive pickling)."""
    if bool(jax.config.jax_enable_x64) != x64:  # a fresh worker process: the caller's precision
        jax.config.update("jax_enable_x64", x64)
    shared, treedef = jax.tree_util.tree_flatten(template)
    it = iter(blocks)
    leaves = [np.asarray(next(it)) if b else s for s, b in zip(shared, batched)]
    batch = np.broadcast_shapes(*[leaf.shape[:leaf.ndim - k] for leaf, k, b in zip(leaves, core_ndim, batched) if b])
    stack = jax.tree_util.tree_unflatten(treedef, leaves)
    return predict(stack, wl, geometry, batch_shape=tuple(batch), chunk=chunk, step=step, progress=False,
                   nodes=nodes, memory=memory)


def _predict_dask(leaves, treedef, lay: BatchLayout, wl, geometry: Geometry, nodes: int, chunk, step: int,
                  memory: Optional[int] = None):
    """:func:`predict` with Dask arrays among the batched leaves: a lazy Dask array
    ``(*batch, *angle, wl)``, one task per block of the batch (chunked like the Dask leaves),
    computed on whatever scheduler is active (threads, processes, a ``distributed.Client``).
    ``chunk="auto"`` is resolved by each task where it runs (a worker's own memory limit)."""
    import dask.array as da

    batch = lay.batch_shape
    nb = len(batch)
    arrays = []
    for leaf, core, b in zip(leaves, lay.cores, lay.batched):
        if not b:
            continue
        a = leaf if _is_dask(leaf) else da.from_array(np.asarray(leaf), chunks=-1)
        arrays.append(da.broadcast_to(a, batch + core))
    # one block structure for every batched leaf: the first Dask leaf's batch chunks, whole core axes
    ref = next(a for a in arrays if a.numblocks[:nb] != (1,) * nb) if any(
        a.numblocks[:nb] != (1,) * nb for a in arrays) else arrays[0]
    batch_chunks = ref.chunks[:nb]
    arrays = [a.rechunk(batch_chunks + tuple((c,) for c in a.shape[nb:])) for a in arrays]
    first = tuple(np.asarray(a[(0,) * nb].compute()) for a in arrays)
    it = iter(first)
    one = jax.tree_util.tree_unflatten(treedef, [next(it) if b else s for s, b in zip(leaves, lay.batched)])
    tail = jax.eval_shape(lambda st: reflectance(st, wl, geometry, nodes=nodes), one)
    out_ind = tuple(f"b{i}" for i in range(nb)) + tuple(f"t{i}" for i in range(len(tail.shape)))
    args = []
    for k, a in enumerate(arrays):
        args += [a, tuple(f"b{i}" for i in range(nb)) + tuple(f"c{k}_{j}" for j in range(a.ndim - nb))]
    return da.blockwise(
        _dask_block, out_ind, *args, new_axes={f"t{i}": n for i, n in enumerate(tail.shape)}, concatenate=True,
        dtype=tail.dtype, meta=np.empty((0,) * len(out_ind), tail.dtype), template=one,
        batched=lay.batched, core_ndim=tuple(len(c) for c in lay.cores), wl=np.asarray(wl), geometry=geometry,
        nodes=nodes, chunk=chunk, step=step, x64=bool(jax.config.jax_enable_x64), memory=memory)


def _predict_traced(leaves, treedef, lay: BatchLayout, wl, geometry: Geometry, nodes: int, chunk: int):
    """:func:`predict` inside a JAX transformation: one ``lax.map`` over vmapped blocks in the
    caller's trace (differentiable), returning a JAX array ``(*batch, *angle, wl)``."""
    batch = lay.batch_shape
    n = math.prod(batch)
    rows = tuple(jnp.reshape(jnp.broadcast_to(jnp.asarray(leaf), batch + core), (n,) + core)
                 for leaf, core, b in zip(leaves, lay.cores, lay.batched) if b)
    shared = [None if b else leaf for leaf, b in zip(leaves, lay.batched)]
    spectrum = _spectrum_function(treedef, shared, lay.batched, wl, geometry, nodes, None)
    values, _ = jax.lax.map(spectrum, rows, batch_size=min(chunk, n))  # no warnings inside a transformation
    return jnp.reshape(values, batch + values.shape[1:])
