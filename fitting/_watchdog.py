"""Waiting for a compiled solve without waiting forever.

JAX dispatches a compiled computation and returns at once; reading its result
(``np.asarray``) then blocks inside XLA until the computation is done. A computation that
can never finish — a deadlock in the runtime, a host callback that never returns — would
leave that read waiting forever, with no error and no output. :func:`wait_for` waits by
polling instead (``jax.Array.is_ready``), and gives up in plain words:

* when the computation runs on the CPU and the process has used almost no CPU time for
  ``stall_s`` seconds (:data:`STALL_S`): a computation that runs keeps at least one core busy,
  so one that has stopped using CPU is stuck, not slow (a loaded machine slows it down, it does
  not bring its CPU time to a halt);
* when the wall clock passes ``deadline`` (the caller's own time limit), on any device.

The computation itself cannot be cancelled: it stays where it is while the error travels up.
(A program with host callbacks runs while it is dispatched, before there is anything to wait
for: this watch covers the compiled solves, which hold none.)
"""

from __future__ import annotations

import time
from typing import Optional

import jax
import numpy as np

from layerstack_jax import LayerstackError

__all__ = ["STALL_S", "wait_for"]

#: Seconds a CPU computation may go without the process using CPU time before it is declared
#: stuck (:func:`wait_for`).
STALL_S = 120.0

#: CPU seconds that count as progress within a stall window: well above what the polling itself
#: uses (tens of microseconds per poll), far below what a running computation uses.
_MIN_CPU_S = 0.05

#: Longest pause between two polls (seconds).
_MAX_POLL_S = 0.2

#: Pause between two polls as a fraction of the time waited so far (and at least
#: :data:`_MIN_POLL_S`): a result is read back at most this fraction of its computing time late.
#: The polls then number about ln(wait / _MIN_POLL_S) / _POLL_FRACTION (~460 for a 1 s solve,
#: each a few microseconds); a pause that doubled at each poll would leave the result of a ~1 s
#: solve (one ``fit_batch`` chunk) waiting up to the longest pause.
_POLL_FRACTION = 0.02
_MIN_POLL_S = 1e-4


def _on_cpu(leaves) -> bool:
    return all(d.platform == "cpu" for leaf in leaves for d in leaf.devices())


def _pending(out) -> list:
    """The leaves of ``out`` still being computed (JAX arrays, or anything with ``is_ready``)."""
    return [leaf for leaf in jax.tree.leaves(out) if hasattr(leaf, "is_ready")]


def wait_for(out, *, what: str, stall_s: Optional[float] = STALL_S, deadline: Optional[float] = None,
             hint: str = ""):
    """NumPy copies of the JAX arrays in the pytree ``out`` once they are computed.

    Raises :class:`~layerstack_jax.LayerstackError` naming ``what`` (e.g. ``"fit_batch:
    chunk 2 of 5"``) when the computation is stuck (on the CPU, the process used less than
    :data:`_MIN_CPU_S` CPU seconds in ``stall_s`` seconds; None: never) or when
    ``time.monotonic()`` passes ``deadline`` (None: no limit); ``hint`` is added to the message."""
    leaves = _pending(out)
    watch_cpu = stall_s is not None and _on_cpu(leaves)
    start = time.monotonic()
    t_ref, cpu_ref = start, time.process_time()
    pause = _MIN_POLL_S
    while not all(leaf.is_ready() for leaf in leaves):
        time.sleep(pause)
        now, cpu = time.monotonic(), time.process_time()
        pause = min(max(_MIN_POLL_S, _POLL_FRACTION * (now - start)), _MAX_POLL_S)
        if cpu - cpu_ref >= _MIN_CPU_S:
            t_ref, cpu_ref = now, cpu
        elif watch_cpu and now - t_ref > stall_s:
            raise LayerstackError(
                f"{what}: the compiled computation has stopped: the process has used no CPU time for "
                f"{now - t_ref:.0f} s ({now - start:.0f} s since it started). It cannot finish; its result is "
                f"not available and the computation cannot be cancelled{'; ' + hint if hint else ''}.")
        if deadline is not None and now > deadline:
            raise LayerstackError(
                f"{what}: not finished within the time limit (still running after {now - start:.0f} s of this "
                f"part){'; ' + hint if hint else ''}.")
    return jax.tree.map(np.asarray, out)
