"""The memory that sizes chosen "auto" may fill where the work runs (:func:`memory_budget`):
this process's available memory (the system's, lowered to the room under a cgroup limit), a Dask
worker's memory limit inside a worker, and an accelerator's free memory. Batched prediction
(``predict(..., chunk="auto")``) sizes its vmapped blocks from it, and ``fitting.fit_cube`` its
regions (through the public ``layerstack_jax.memory_budget``).

Imports nothing from the floors above (only ``jax``, for the accelerator's memory statistics).
"""

from __future__ import annotations

import os
import sys
from typing import NamedTuple, Optional

import jax

from .validate import LayerstackError

__all__ = ["MEMORY_FRACTION", "MemoryBudget", "memory_budget"]

#: Fraction of the memory available where the work runs that ``"auto"`` sizes may fill (the rest:
#: the process itself, and room below Dask's spill (60-70 %) and pause (80 %) thresholds).
MEMORY_FRACTION = 0.5


class MemoryBudget(NamedTuple):
    """Memory that ``"auto"`` sizes may fill (:func:`memory_budget`): ``bytes`` (the budget),
    ``available`` (what it is a ``fraction`` of) and ``source`` (where ``available`` comes from)."""

    bytes: int
    available: int
    fraction: float
    source: str

    def describe(self) -> str:
        if self.fraction == 1:
            return f"{self.bytes / 1e6:.4g} MB ({self.source})"
        return (f"{self.bytes / 1e6:.4g} MB ({self.fraction:g} of {self.available / 1e6:.4g} MB, "
                f"{self.source})")


def _read_int(path: str) -> Optional[int]:
    try:
        with open(path) as f:
            text = f.read().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None  # "max" (cgroup v2: no limit) -> None


def _host_available() -> tuple[int, str]:
    """``(bytes, source)`` of the memory this process may still take: the system's available
    memory (``MemAvailable`` of /proc/meminfo, else ``os.sysconf`` free pages), lowered to the
    room left under a cgroup memory limit (v2 ``memory.max - memory.current``, v1
    ``memory.limit_in_bytes - memory.usage_in_bytes``) when there is one."""
    available, source = None, "available system memory"
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    available = int(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if available is None:
        try:
            available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
            source = "free system memory (sysconf)"
        except (ValueError, OSError, AttributeError):  # pragma: no cover - not a POSIX system
            available, source = 4 << 30, "unknown system memory: assumed 4 GiB"
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        limit = _read_int(limit_file)
        if limit is not None and limit < 1 << 60:  # v1 writes "no limit" as a huge number
            room = max(limit - (_read_int(usage_file) or 0), 0)
            if room < available:
                available, source = room, f"room under the cgroup memory limit {limit / 1e6:.4g} MB"
            break
    return int(available), source


def _worker_limit() -> Optional[tuple[int, str]]:
    """``(bytes, source)``: the memory limit of the Dask worker running this task, shared by its
    threads, or None outside a worker (or a worker without a limit)."""
    if "distributed" not in sys.modules:  # a worker process has imported it
        return None
    from distributed import get_worker

    try:
        worker = get_worker()
    except ValueError:  # not in a worker
        return None
    limit = worker.memory_manager.memory_limit
    if not limit:
        return None
    threads = max(int(getattr(worker, "nthreads", 1) or 1), 1)
    return int(limit) // threads, (f"Dask worker {worker.address} memory_limit {limit / 1e6:.4g} MB"
                                   + (f" / {threads} threads" if threads > 1 else ""))


def memory_budget(fraction: float = MEMORY_FRACTION, *, device: bool = False) -> MemoryBudget:
    """The memory ``"auto"`` sizes may fill where this code runs: ``fraction`` of

    * inside a Dask worker: that worker's memory limit
      (``distributed.get_worker().memory_manager.memory_limit``) divided by its threads (tasks
      running at once share it);
    * otherwise: this process's available memory (:func:`_host_available`: the system's
      available memory, or the room under a cgroup limit if smaller);
    * with ``device`` and an accelerator (``jax.local_devices()[0].memory_stats()`` reports a
      ``bytes_limit``): the smaller of that and the accelerator's free memory.
    """
    if not 0 < fraction <= 1:
        raise LayerstackError(f"memory_budget: fraction must be in (0, 1], got {fraction!r}")
    found = _worker_limit()
    available, source = found if found is not None else _host_available()
    if device:
        stats = None
        try:
            stats = jax.local_devices()[0].memory_stats()
        except Exception:  # backends without memory statistics  # pragma: no cover
            stats = None
        if stats and stats.get("bytes_limit"):
            free = int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0))
            if free < available:
                available, source = free, f"free memory of {jax.local_devices()[0].device_kind}"
    return MemoryBudget(int(available * fraction), int(available), float(fraction), source)
