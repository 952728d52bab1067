"""Input validation that names the offending field, eagerly *and* under ``jit``/``grad``.

Every check returns its input. On concrete values (plain Python, NumPy, or JAX arrays outside a
transformation) a violation raises :class:`LayerstackError` at once. On traced values (inside
``jax.jit``, ``jax.grad``, ``jax.vmap`` …) the value is returned wrapped by
:func:`equinox.error_if` with the same message, so the violation raises when the compiled
function runs (as an ``equinox`` runtime error whose text names the field) instead of returning
a number. Callers must *use the returned value* for the traced check to take effect: the
choke point is :func:`layerstack_jax._stacks.stack.resolve`, through which every public function
samples a stack.

Plausibility checks (:func:`warn_if_implausible`, :func:`warn_if`) only warn, naming the field
and the likely mistake (µm given for nm, percent for a fraction).

While a public function is traced into one compiled program (:mod:`layerstack_jax._base.programs`),
a :class:`ProgramChecks` collector is active instead: every traced check and plausibility test
becomes an output flag of the program, and the host raises or warns after it ran — the same
error (with the offending values) and the same warnings as an eager call.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import warnings
from typing import Callable, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "LayerstackError",
    "LayerstackWarning",
    "is_concrete",
    "check",
    "PendingChecks",
    "check_finite",
    "check_nonnegative",
    "check_positive",
    "check_unit_interval",
    "check_angle_deg",
    "check_wavelength_range",
    "warn_if_implausible",
    "warn_if",
    "warn_if_radians",
    "check_agree",
    "value_text",
    "ProgramChecks",
    "collecting_checks",
]


class LayerstackError(ValueError):
    """Raised for invalid physical input (the message names the field)."""


class LayerstackWarning(UserWarning):
    """Implausible but possible input (the message names the field and the likely mistake)."""


def is_concrete(x) -> bool:
    """True when no leaf of ``x`` is a JAX tracer (its values can be inspected now)."""
    leaves = jax.tree_util.tree_leaves(x)
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def value_text(a: np.ndarray) -> str:
    """A value or the range of an array, for messages."""
    a = np.asarray(a)
    if a.size == 1:
        return repr(a.reshape(()).item())
    if np.iscomplexobj(a):
        return (f"values in [{float(a.real.min())!r}, {float(a.real.max())!r}] + "
                f"i[{float(a.imag.min())!r}, {float(a.imag.max())!r}]")
    return (f"range [{float(np.nanmin(a))!r}, {float(np.nanmax(a))!r}]" if np.any(np.isfinite(a))
            else "no finite value")


class PendingChecks:
    """Traced checks collected over one evaluation (e.g. every leaf of a stack in
    :func:`~layerstack_jax._stacks.stack.resolve`) and raised by one ``equinox.branched_error_if``
    attached to the first traced value checked — one runtime branch instead of one per leaf
    (each costs a conditional in the compiled loop). That value is an input of the computation,
    so the check cannot be removed as dead code."""

    def __init__(self):
        self.predicates: list = []
        self.messages: list[str] = []
        self.first = None  # (key, value) of the first traced value checked

    def add(self, key, x, predicate, message: str) -> None:
        if self.first is None:
            self.first = (key, x)
        self.predicates.append(predicate)
        self.messages.append(message)

    def attach(self):
        """``(key, checked value)`` of the first traced value, or None when nothing was traced."""
        if self.first is None:
            return None
        key, x = self.first
        preds = jnp.stack(self.predicates)
        return key, eqx.branched_error_if(x, jnp.any(preds), jnp.argmax(preds), tuple(self.messages))


class ProgramChecks:
    """What the checks met while tracing one public program found, as traced values.

    ``errors``: one boolean per traced check (True: the input violates it); ``warnings``:
    ``(flag, values, message)`` per plausibility test, ``message(values_as_numpy) -> str``. The
    program returns the flags (and the values of flagged tests) next to its result; the host
    decides (:mod:`layerstack_jax._base.programs`). With ``errors=False`` only the plausibility tests
    are collected; traced checks stay ``equinox.error_if`` (a batched prediction's loop body)."""

    def __init__(self, errors: bool = True):
        self.collect_errors = errors
        self.errors: list = []
        self.warnings: list = []


_PROGRAM_CHECKS: contextvars.ContextVar = contextvars.ContextVar("layerstack_program_checks", default=None)


@contextlib.contextmanager
def collecting_checks(errors: bool = True):
    """Within this block, traced plausibility tests — and, with ``errors``, traced checks — are
    collected into the yielded :class:`ProgramChecks` instead of calling back to the host /
    ``equinox.error_if``. The values traced here are a caller's concrete inputs, so they are
    checked even inside :func:`traced_checks_off`."""
    collector = ProgramChecks(errors)
    token = _PROGRAM_CHECKS.set(collector)
    checks_on = _TRACED_CHECKS.set(True)
    try:
        yield collector
    finally:
        _TRACED_CHECKS.reset(checks_on)
        _PROGRAM_CHECKS.reset(token)


_TRACED_CHECKS = contextvars.ContextVar("layerstack_traced_checks", default=True)


@contextlib.contextmanager
def traced_checks_off():
    """While tracing inside this block, traced values are not checked at run time (concrete
    values still are). For callers that keep their traced values valid themselves and must see
    a trial point outside the domain as a non-finite number rather than an error: the fitting
    solvers keep parameters within their bounds by a transform, but a line search may still try
    a point where that transform overflows (α = inf); the solver rejects such a step by its
    non-finite cost, where an error would end the whole fit. The fixed parts of a fitted model
    were checked eagerly when the objective was built.

    It acts while a function is traced: a ``jax.jit`` function first traced inside the block
    keeps its checks off when called again outside it (JAX reuses the traced program)."""
    token = _TRACED_CHECKS.set(False)
    try:
        yield
    finally:
        _TRACED_CHECKS.reset(token)


def check(name: str, x, bad: Callable, what: str, *, pending: Optional[PendingChecks] = None, key=None):
    """``x``, checked: ``bad(a, xp)`` (``xp`` = numpy or jax.numpy) marks the invalid entries.

    Concrete ``x``: raises ``LayerstackError("<name> <what>, got <values>")`` if any entry is
    bad. Traced ``x``: returns ``equinox.error_if(x, any(bad), "<name> <what>")``, or, with
    ``pending``, records the check there (under ``key``) and returns ``x`` unchanged (inside
    :func:`traced_checks_off`: ``x`` unchecked). None passes.
    """
    if x is None:
        return None
    if is_concrete(x):
        a = np.asarray(x)
        if np.any(bad(a, np)):
            raise LayerstackError(f"{name} {what}, got {value_text(a)}")
        return x
    xj = jnp.asarray(x)
    if not _TRACED_CHECKS.get():
        return xj
    collector = _PROGRAM_CHECKS.get()
    if collector is not None and collector.collect_errors:
        collector.errors.append(jnp.any(bad(xj, jnp)))
        return xj
    if pending is not None:
        pending.add(key, xj, jnp.any(bad(xj, jnp)), f"{name} {what}")
        return xj
    return eqx.error_if(xj, jnp.any(bad(xj, jnp)), f"{name} {what}")


def check_wavelength_range(name: str, x, lo: float, hi: float):
    """Wavelengths ``x`` (nm) inside a material table's range ``[lo, hi]`` (tolerance 1e-9 nm):
    ``x`` itself, a numpy array when concrete (so that a table's interpolation can be set up at
    trace time) and a JAX array when traced; a :class:`LayerstackError` naming the material (``name``), the range
    asked for and the data range — at once on concrete wavelengths, at run time
    (``equinox.error_if``) on traced ones, not at all inside :func:`traced_checks_off` (the fitting
    objective checks its grid against every table when it is built)."""
    if is_concrete(x):
        w = np.asarray(x)
        if np.any(w < lo - 1e-9) or np.any(w > hi + 1e-9):
            raise LayerstackError(f"{name}: wavelengths {w.min():g}–{w.max():g} nm outside the data range "
                                  f"{lo:g}–{hi:g} nm")
        return w
    x = jnp.asarray(x)
    if not _TRACED_CHECKS.get():
        return x
    outside = (x < lo - 1e-9) | (x > hi + 1e-9)
    collector = _PROGRAM_CHECKS.get()
    if collector is not None and collector.collect_errors:
        collector.errors.append(jnp.any(outside))
        return x
    return eqx.error_if(x, outside, f"{name}: wavelengths outside the data range {lo:g}–{hi:g} nm")


def check_finite(name: str, x, **pending):
    """``x`` with no NaN or infinite entry."""
    return check(name, x, lambda a, xp: ~xp.isfinite(a), "must be finite (no NaN or infinity)", **pending)


def check_nonnegative(name: str, x, what: str = "must be >= 0", **pending):
    """``x`` finite and ≥ 0 (thickness, α, k …)."""
    return check(name, x, lambda a, xp: ~xp.isfinite(a) | (a < 0), f"{what} and finite (no NaN or infinity)", **pending)


def check_positive(name: str, x, what: str = "must be > 0", **pending):
    """``x`` finite and > 0 (wavelengths, real parts of indices)."""
    return check(name, x, lambda a, xp: ~xp.isfinite(a) | (a <= 0), f"{what} and finite (no NaN or infinity)", **pending)


def check_unit_interval(name: str, x, **pending):
    """``x`` finite and in [0, 1] (ρg, fractions)."""
    return check(name, x, lambda a, xp: ~xp.isfinite(a) | (a < 0) | (a > 1), "must lie in [0, 1]", **pending)


def check_angle_deg(name: str, x, *, grazing: bool = False):
    """An angle from the normal in degrees, in [0, 90) — an instrument's angle (grazing light
    carries no power in) — or in [0, 90] with ``grazing=True`` (a function of the angle, where
    90° is a valid limit: R = 1, T = 0; a rounding excess of 1e-9° is tolerated)."""
    if grazing:
        return check(name, x, lambda a, xp: ~xp.isfinite(a) | (a < 0) | (a > 90 + 1e-9), "must lie in [0, 90] degrees")
    return check(name, x, lambda a, xp: ~xp.isfinite(a) | (a < 0) | (a >= 90), "must lie in [0, 90) degrees")


def warn_if_implausible(name: str, x, implausible: Callable, likely: str) -> None:
    """Warn (:class:`LayerstackWarning`) when ``x`` has an entry marked by ``implausible(a, xp)``
    (``xp`` = numpy or jax.numpy); ``likely`` says the probable mistake. The message names the
    field and its values: ``"<name>: <values>: <likely>"``. See :func:`warn_if`."""
    if x is None:
        return
    warn_if(x, implausible, lambda a: f"{name}: {value_text(a)}: {likely}", stacklevel=4)


def warn_if(values, implausible: Callable, message: Callable, *, stacklevel: int = 3) -> None:
    """Warn (:class:`LayerstackWarning`) with ``message(values)`` when ``implausible(values, xp)``
    (``xp`` = numpy or jax.numpy; ``values`` any pytree of arrays) has a True entry.

    Concrete values: tested and warned at once (``message`` gets numpy arrays). Traced values
    while a public program is traced (:func:`collecting_checks`): the test becomes an output of the
    program and the host warns after it ran. Traced values elsewhere (inside a user's ``jit``,
    ``grad`` or ``vmap``): when the test is True the program calls back to the host
    (``jax.debug.callback`` in a ``lax.cond``: nothing but the test runs otherwise), which warns;
    under ``vmap`` once per call, with the first flagged element's values
    (:func:`_first_flagged`); not inside :func:`traced_checks_off` (a solver's trial points).
    """
    if is_concrete(values):
        a = jax.tree_util.tree_map(np.asarray, values)
        if np.any(implausible(a, np)):
            warnings.warn(message(a), LayerstackWarning, stacklevel=stacklevel)
        return
    flag = jnp.any(implausible(values, jnp))
    collector = _PROGRAM_CHECKS.get()
    if collector is not None:
        collector.warnings.append((flag, values, message))
    elif _TRACED_CHECKS.get():
        flag, values = _first_flagged(flag, jax.lax.stop_gradient(values))
        jax.lax.cond(flag, lambda: jax.debug.callback(functools.partial(_warn_on_host, message), flag, values),
                     lambda: None)


@jax.custom_batching.custom_vmap
def _first_flagged(flag, values):
    """``(flag, values)`` as given; under ``vmap``, unbatched: whether any element is flagged and
    the first flagged element's values. A batched flag would turn the ``lax.cond`` of
    :func:`warn_if` into a select that runs the call back for every element, and JAX unrolls a
    vmapped ``jax.debug.callback`` into one call per element (2000 draws: 2000 call backs compiled)."""
    return flag, values


@_first_flagged.def_vmap
def _first_flagged_vmap(axis_size, in_batched, flag, values):
    flag_batched, values_batched = in_batched
    first = jnp.argmax(flag) if flag_batched else 0
    flag = jnp.any(flag) if flag_batched else flag
    values = jax.tree_util.tree_map(lambda v, b: v[first] if b else v, values, values_batched)
    flag, values = _first_flagged(flag, values)  # an outer vmap reduces its own axis in turn
    return (flag, values), (False, jax.tree_util.tree_map(lambda _: False, values))


def _warn_on_host(message: Callable, flag, values) -> None:
    if np.any(np.asarray(flag)):
        warnings.warn(message(jax.tree_util.tree_map(np.asarray, values)), LayerstackWarning, stacklevel=2)


def warn_if_radians(name: str, angle_deg) -> None:
    """Warn when angles meant in degrees read like radians: all within (0, π/2] and not all whole
    degrees (``specular:1.2217`` for 70°)."""
    warn_if_implausible(name, angle_deg,
                        lambda a, xp: (xp.max(a) > 0) & (xp.max(a) <= xp.pi / 2) & xp.any(a != xp.round(a)),
                        "all within (0, pi/2] and not whole degrees: radians given? angles are in degrees")


def check_agree(message: str, a, b, *, rtol: float) -> None:
    """Raise ``LayerstackError(message)`` unless ``a`` and ``b`` agree within ``rtol``
    (``|a − b| ≤ rtol |b|``, as ``numpy.allclose`` with ``atol=0``). Concrete values: at once;
    traced while a public program is traced: a check output of the program; traced elsewhere:
    not checked."""
    if is_concrete((a, b)):
        if not np.allclose(np.asarray(a), np.asarray(b), rtol=rtol, atol=0):
            raise LayerstackError(message)
        return
    collector = _PROGRAM_CHECKS.get()
    if collector is not None and collector.collect_errors and _TRACED_CHECKS.get():
        collector.errors.append(jnp.any(jnp.abs(jnp.asarray(a) - jnp.asarray(b)) > rtol * jnp.abs(jnp.asarray(b))))
