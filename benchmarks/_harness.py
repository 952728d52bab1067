"""Timing, memory and reporting helpers for the benchmarks.

Nothing here imports jax, torch or any peer at import time; ``jax`` is only touched when the
caller already imported it (to block on asynchronous results) or when machine info asks for
the backend.
"""

from __future__ import annotations

import datetime as _dt
import importlib.metadata as _md
import json
import math
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

__all__ = [
    "Timing",
    "block",
    "measure",
    "peak_rss_bytes",
    "run_subprocess",
    "SubprocessResult",
    "machine_info",
    "cpu_count",
    "loadavg",
    "busy_warning",
    "CpuContention",
    "write_json",
    "write_markdown",
    "RESULTS_DIR",
]

RESULTS_DIR = Path(__file__).resolve().parent / "results"


# --------------------------------------------------------------------------------------
# blocking on asynchronous outputs
# --------------------------------------------------------------------------------------


def _leaves(out: Any):
    if isinstance(out, (list, tuple)):
        for o in out:
            yield from _leaves(o)
    elif isinstance(out, dict):
        for o in out.values():
            yield from _leaves(o)
    else:
        yield out


def block(out: Any) -> Any:
    """Wait until ``out`` is computed.

    JAX arrays (anywhere in a pytree) go through ``jax.block_until_ready``; torch tensors on a
    CUDA device trigger ``torch.cuda.synchronize``; everything else is already synchronous.
    Neither framework is imported here: if it is not in ``sys.modules`` the output cannot be
    one of its arrays.
    """
    jax = sys.modules.get("jax")
    if jax is not None:
        out = jax.block_until_ready(out)
    torch = sys.modules.get("torch")
    if torch is not None:
        for leaf in _leaves(out):
            if isinstance(leaf, torch.Tensor) and leaf.device.type == "cuda":
                torch.cuda.synchronize(leaf.device)
                break
    return out


# --------------------------------------------------------------------------------------
# timing
# --------------------------------------------------------------------------------------


@dataclass
class Timing:
    """Result of :func:`measure`. All times in seconds, per call of ``fn``."""

    first_call_s: float  # wall time of the very first call (includes tracing/compilation)
    compile_s: float | None  # compile time (see compile_method)
    compile_method: str  # "aot" (jit(...).lower().compile()), "first-call" (first - median), "none"
    lower_s: float | None  # tracing + lowering (aot only)
    min_s: float
    median_s: float
    mean_s: float
    max_s: float
    repeats: int  # number of timed repeats
    number: int  # calls per repeat (autoranged so a repeat lasts >= min_time)
    samples_s: list[float] = field(default_factory=list)  # per-call time of each repeat

    def as_dict(self) -> dict:
        return asdict(self)


def _is_jitted(fn: Any) -> bool:
    # jax.jit(...) objects (and equinox filter_jit wrappers) expose ``lower``.
    return callable(getattr(fn, "lower", None)) and "jax" in sys.modules


def measure(
    fn: Callable,
    *args: Any,
    warmup: int = 1,
    repeats: int = 5,
    min_time: float = 0.2,
    number: int | None = None,
    max_time: float | None = None,
    aot: bool | None = None,
    return_output: bool = False,
    **kwargs: Any,
) -> Timing | tuple[Timing, Any]:
    """Time ``fn(*args, **kwargs)``.

    * The first call is timed on its own (``first_call_s``); it includes any tracing or
      compilation.  ``warmup`` counts this first call, further warm-up calls are untimed.
    * If ``fn`` is a jitted JAX function (has ``.lower``) and ``aot`` is not False, the
      compile time is measured explicitly: ``fn.lower(*args)`` (``lower_s``) then
      ``.compile()`` (``compile_s``), and the steady state is timed on the compiled
      executable.  Otherwise ``compile_s = max(first_call - median, 0)``.
    * Each of ``repeats`` timed repeats runs ``number`` calls; when ``number`` is None it
      is chosen (1, 2, 5, 10, ...) so that a repeat lasts at least ``min_time`` seconds.
      Reported times are per call: min, median, mean and max over the repeats.
    * ``max_time`` (seconds) caps the timed phase: repeats stop early once exceeded
      (at least one repeat always runs).

    Outputs are passed through :func:`block` so asynchronous dispatch is accounted for.
    With ``return_output`` the result is ``(Timing, last output)``.
    """
    if aot is None:
        aot = _is_jitted(fn)
    lower_s = compile_s = None
    compile_method = "first-call"
    call = fn
    if aot:
        if kwargs:
            raise ValueError("aot timing needs positional arguments only")
        t0 = time.perf_counter()
        lowered = fn.lower(*args)
        t1 = time.perf_counter()
        compiled = lowered.compile()
        t2 = time.perf_counter()
        lower_s, compile_s, compile_method = t1 - t0, t2 - t1, "aot"
        call = compiled

    t0 = time.perf_counter()
    out = block(call(*args, **kwargs))
    first = time.perf_counter() - t0
    for _ in range(max(0, warmup - 1)):
        out = block(call(*args, **kwargs))

    if number is None:
        number = 1
        if min_time > 0 and first < min_time:
            # autorange on a steady-state estimate (the first call may include compilation)
            t0 = time.perf_counter()
            out = block(call(*args, **kwargs))
            est = max(time.perf_counter() - t0, 1e-9)
            for cand in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000):
                number = cand
                if cand * est >= min_time:
                    break

    samples = []
    t_start = time.perf_counter()
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        for _ in range(number):
            out = call(*args, **kwargs)
        out = block(out)
        samples.append((time.perf_counter() - t0) / number)
        if max_time is not None and time.perf_counter() - t_start > max_time:
            break

    med = statistics.median(samples)
    if compile_method == "first-call":
        compile_s = max(first - med, 0.0)
    timing = Timing(
        first_call_s=first,
        compile_s=compile_s,
        compile_method=compile_method,
        lower_s=lower_s,
        min_s=min(samples),
        median_s=med,
        mean_s=statistics.fmean(samples),
        max_s=max(samples),
        repeats=len(samples),
        number=number,
        samples_s=samples,
    )
    return (timing, out) if return_output else timing


# --------------------------------------------------------------------------------------
# memory
# --------------------------------------------------------------------------------------


def _vmhwm_bytes(pid: int | str = "self") -> int | None:
    """``VmHWM`` (peak RSS of the current address space) from /proc, or None."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def peak_rss_bytes() -> int:
    """Peak resident set size of this process so far.

    Linux: ``VmHWM`` from ``/proc/self/status``; elsewhere ``getrusage(RUSAGE_SELF).ru_maxrss``.
    Why not ``ru_maxrss`` on Linux: for a process started by fork/vfork + exec (every
    subprocess), the kernel folds the *parent's* RSS at exec time into the child's
    ``ru_maxrss``, so a child of a 500 MiB parent reports >= 500 MiB. ``VmHWM`` belongs to the
    exec'd address space only. Either way it is a high-water mark: read it before and after
    the work of interest, and run each case in its own process (:func:`run_subprocess`).
    """
    hwm = _vmhwm_bytes()
    if hwm is not None:
        return hwm
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(r) * (1 if sys.platform == "darwin" else 1024)  # Linux reports KiB


@dataclass
class SubprocessResult:
    returncode: int
    stdout: str
    stderr: str
    peak_rss_bytes: int  # best estimate of the child's own peak RSS (see run_subprocess)
    wall_s: float
    timed_out: bool = False
    ru_maxrss_bytes: int = 0  # raw os.wait4 ru_maxrss (includes the parent's RSS at exec on Linux)
    vmhwm_polled_bytes: int | None = None  # last VmHWM of the child seen while polling /proc


def run_subprocess(
    argv: Sequence[str],
    *,
    env: dict | None = None,
    cwd: str | os.PathLike | None = None,
    timeout: float | None = None,
) -> SubprocessResult:
    """Run ``argv``; return its output and its peak RSS.

    Output goes through temporary files (no pipe deadlock). The child is reaped with
    ``os.wait4`` on its pid, so its rusage is its own, not the maximum over all children as
    ``RUSAGE_CHILDREN`` would give. On Linux that ``ru_maxrss`` is floored by this (parent)
    process's RSS at spawn time (see :func:`peak_rss_bytes`), so the child's ``VmHWM`` is also
    polled from ``/proc/<pid>/status`` every 20 ms; ``peak_rss_bytes`` is the polled VmHWM when
    available (may miss a spike in the last 20 ms of the child's life), else ``ru_maxrss``.
    For an exact figure, have the child report :func:`peak_rss_bytes` itself, as the
    benchmark workers do.
    """
    with tempfile.TemporaryFile("w+") as fout, tempfile.TemporaryFile("w+") as ferr:
        t0 = time.perf_counter()
        proc = subprocess.Popen(list(argv), stdout=fout, stderr=ferr, env=env, cwd=cwd)
        timed_out = False
        hwm = None
        deadline = None if timeout is None else t0 + timeout
        while True:
            pid, status, ru = os.wait4(proc.pid, os.WNOHANG)
            if pid == proc.pid:
                break
            h = _vmhwm_bytes(proc.pid)
            if h is not None:
                hwm = h if hwm is None else max(hwm, h)
            if deadline is not None and time.perf_counter() > deadline:
                proc.kill()
                timed_out = True
                pid, status, ru = os.wait4(proc.pid, 0)
                break
            time.sleep(0.02)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)  # keep Popen from waiting again
        fout.seek(0)
        ferr.seek(0)
        rss = int(ru.ru_maxrss) * (1 if sys.platform == "darwin" else 1024)
        best = hwm if hwm is not None else rss
        return SubprocessResult(proc.returncode, fout.read(), ferr.read(), best, wall, timed_out, rss, hwm)


# --------------------------------------------------------------------------------------
# machine info
# --------------------------------------------------------------------------------------


def cpu_count() -> int:
    """CPUs this process may run on (affinity), falling back to ``os.cpu_count()``."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def loadavg() -> list[float] | None:
    """1, 5 and 15-minute load averages (other work on the machine skews timings)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):
        return None


class CpuContention:
    """Share of the machine's CPU time used by *other* processes while a block runs.

    ``with CpuContention() as c: ...`` then ``c.foreign_frac`` (0 = machine otherwise idle,
    1 = every CPU fully used by something else) and ``c.steal_frac`` (hypervisor steal).
    From /proc/stat (all CPUs) minus this process's own rusage; None where unavailable.
    """

    def __init__(self) -> None:
        self.foreign_frac: float | None = None
        self.steal_frac: float | None = None

    @staticmethod
    def _stat():
        try:
            with open("/proc/stat") as f:
                v = [int(x) for x in f.readline().split()[1:]]
        except (OSError, ValueError):
            return None
        # user nice system idle iowait irq softirq steal guest guest_nice
        busy = v[0] + v[1] + v[2] + v[5] + v[6]
        steal = v[7] if len(v) > 7 else 0
        return busy, steal

    @staticmethod
    def _own() -> float:
        r = resource.getrusage(resource.RUSAGE_SELF)
        c = resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime + c.ru_utime + c.ru_stime

    def __enter__(self):
        self._t0, self._s0, self._o0 = time.perf_counter(), self._stat(), self._own()
        return self

    def __exit__(self, *exc):
        s1 = self._stat()
        if self._s0 is None or s1 is None:
            return False
        wall = time.perf_counter() - self._t0
        hz = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
        total = wall * cpu_count()
        if total <= 0:
            return False
        busy = (s1[0] - self._s0[0]) / hz
        own = self._own() - self._o0
        self.foreign_frac = round(min(max((busy - own) / total, 0.0), 1.0), 3)
        self.steal_frac = round(max((s1[1] - self._s0[1]) / hz / total, 0.0), 3)
        return False


def busy_warning(load: list[float] | None, cpus: int) -> str | None:
    """A warning line when the 1-minute load says other processes compete for the CPUs."""
    if load is not None and load[0] > 0.5 * cpus:
        return (f"machine busy: 1-min load average {load[0]} on {cpus} CPUs when the run started; "
                "timings are inflated and noisy (min is the better estimate) - rerun on an idle machine")
    return None


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _mem_total_gib() -> float | None:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    return round(int(line.split()[1]) / 1024**2, 1)
    except OSError:
        pass
    return None


def _version(dist: str) -> str | None:
    try:
        return _md.version(dist)
    except _md.PackageNotFoundError:
        return None


def _git_rev() -> str | None:
    root = Path(__file__).resolve().parent.parent
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True, timeout=5
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain"], cwd=root, capture_output=True, text=True, timeout=5
        ).stdout.strip()
        return (rev + ("+dirty" if dirty else "")) or None
    except (OSError, subprocess.SubprocessError):
        return None


def machine_info(dtype: str = "float64", with_jax_backend: bool = True) -> dict:
    """Description of the machine and software stack.

    ``with_jax_backend`` reads ``jax.default_backend()`` and the devices (in a subprocess
    unless jax is already imported); versions come from package metadata (no import).
    """
    info: dict[str, Any] = {
        "timestamp": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "hostname": platform.node(),
        "platform": platform.platform(),
        "cpu_model": _cpu_model(),
        "cpu_count": cpu_count(),
        "cpu_count_os": os.cpu_count(),
        "mem_total_gib": _mem_total_gib(),
        "loadavg_at_start": loadavg(),
        "python": platform.python_version(),
        "python_executable": sys.executable,
        "dtype": dtype,
        "git": _git_rev(),
        "versions": {
            d: _version(d)
            for d in ("jax", "jaxlib", "numpy", "scipy", "tmm", "torch", "tmm-fast", "tmm-faster", "jaxlayerlumos", "tmmax")
        },
        "env": {k: os.environ[k] for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "XLA_FLAGS", "JAX_ENABLE_X64", "JAX_PLATFORMS") if k in os.environ},
    }
    if with_jax_backend:
        info.update(_jax_backend_info())
    return info


def _jax_backend_info() -> dict:
    """jax backend and devices; asked of a subprocess unless jax is already imported here
    (keeps the benchmark runner small, see :func:`peak_rss_bytes`)."""
    jax = sys.modules.get("jax")
    try:
        if jax is not None:
            return {"jax_backend": jax.default_backend(), "jax_devices": [str(d) for d in jax.devices()]}
        code = "import jax, json; print(json.dumps([jax.default_backend(), [str(d) for d in jax.devices()]]))"
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        backend, devices = json.loads(out.stdout.strip().splitlines()[-1])
        return {"jax_backend": backend, "jax_devices": devices}
    except Exception as e:  # reported, never fatal
        return {"jax_backend": f"unavailable: {type(e).__name__}: {e}"}


# --------------------------------------------------------------------------------------
# writers
# --------------------------------------------------------------------------------------


def _atomic_write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path


def _jsonable(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if hasattr(x, "item") and callable(x.item):  # numpy scalars
        try:
            return _jsonable(x.item())
        except Exception:
            pass
    return x


def write_json(payload: dict, path: str | os.PathLike = RESULTS_DIR / "latest.json") -> Path:
    return _atomic_write(Path(path), json.dumps(_jsonable(payload), indent=2, sort_keys=False) + "\n")


def _fmt(x: Any, kind: str = "g") -> str:
    if x is None:
        return "—"
    if isinstance(x, str):
        return x
    if kind == "ms":
        return f"{x * 1e3:.3g}"
    if kind == "s":
        return f"{x:.3g}"
    if kind == "us":
        return f"{x * 1e6:.3g}"
    if kind == "mb":
        return f"{x / 2**20:.0f}"
    if kind == "e":
        return f"{x:.1e}"
    return f"{x:.3g}" if isinstance(x, float) else str(x)


def _md_escape(s: str) -> str:
    return str(s).replace("|", "\\|").replace("\n", " ")


MD_COLUMNS: list[tuple[str, str, str]] = [
    # (header, row key, format)
    ("case", "case", ""),
    ("impl", "impl", ""),
    ("kind", "kind", ""),
    ("status", "status", ""),
    ("points timed", "points_timed", ""),
    ("compile / 1st-call overhead (s)", "compile_s", "s"),
    ("min (ms)", "min_s", "ms"),
    ("median (ms)", "median_s", "ms"),
    ("µs / point", "per_point_s", "us"),
    ("full grid (s)", "full_grid_s", "s"),
    ("peak RSS (MiB)", "peak_rss_bytes", "mb"),
    ("max abs ΔR vs tmm", "max_abs_dR", "e"),
    ("max abs ΔT vs tmm", "max_abs_dT", "e"),
]


def write_markdown(payload: dict, path: str | os.PathLike = RESULTS_DIR / "latest.md",
                   section_lines: list[str] = ()) -> Path:
    """Markdown report: machine summary, results table, per-row notes, peer status list, then
    ``section_lines`` (the whole-model sections, :func:`benchmarks._sections.markdown_lines`)."""
    m = payload.get("machine", {})
    v = m.get("versions", {})
    lines = [f"# layerstack benchmarks — {m.get('timestamp', '')}", ""]
    lines.append(f"- command: `{payload.get('command', '')}`  (mode: {payload.get('mode', '')})")
    lines.append(
        f"- machine: {m.get('cpu_model')} — {m.get('cpu_count')} CPUs usable, "
        f"{m.get('mem_total_gib')} GiB RAM; {m.get('platform')}"
    )
    lines.append(
        f"- python {m.get('python')}; jax {v.get('jax')} / jaxlib {v.get('jaxlib')} "
        f"(backend: {m.get('jax_backend')}); numpy {v.get('numpy')}; dtype {m.get('dtype')}; git {m.get('git')}"
    )
    peers = {k: val for k, val in v.items() if k not in ("jax", "jaxlib", "numpy", "scipy")}
    lines.append("- peers installed: " + ", ".join(f"{k} {val or '(missing)'}" for k, val in peers.items()))
    lines.append(f"- load average (1/5/15 min) at start: {m.get('loadavg_at_start')}")
    for c in payload.get("cases", []):
        lines.append(f"- case {c['name']}: {c['description']} ({c['n_points']} points)")
    warn = busy_warning(m.get("loadavg_at_start"), m.get("cpu_count") or 1)
    busy_rows = [r for r in payload.get("rows", []) if (r.get("foreign_cpu_frac") or 0) > 0.1]
    if warn:
        lines.append(f"- **WARNING: {warn}**")
    if busy_rows:
        lines.append("- **WARNING: other processes used > 10% of the CPUs while timing "
                     + ", ".join(f"{r['impl']}/{r['kind']} ({100 * r['foreign_cpu_frac']:.0f}%)" for r in busy_rows)
                     + "; those timings are inflated**")
    if payload.get("targets"):
        from . import targets as _targets

        lines += ["", "## Targets", "",
                  "Judged on the minimum over repeats (the least contended estimate on a shared machine).", ""]
        lines += _targets.markdown(payload["targets"])
    rows_p1 = payload.get("rows", [])
    if rows_p1:
        lines += ["", "## P1 — coherent multilayer, all implementations"]
        lines += ["", "| " + " | ".join(h for h, _, _ in MD_COLUMNS) + " |", "|" + "---|" * len(MD_COLUMNS)]
    for row in rows_p1:
        cells = [_md_escape(_fmt(row.get(key), fmt)) for _, key, fmt in MD_COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    lines += [] if not rows_p1 else ["", "Times are per call of the whole case (both polarizations) unless the notes say otherwise;",
              "`full grid (s)` is the measured median for rows timed on the full grid, else the per-point",
              "cost extrapolated to the full grid. `compile / 1st-call overhead` is trace + lower + XLA",
              "compile when measured ahead-of-time (jitted JAX functions), otherwise first call minus median.",
              "Peak RSS is the worker process's own high-water mark (VmHWM) right after timing, imports included.", ""]
    notes = [(row, row.get("notes")) for row in payload.get("rows", []) if row.get("notes")]
    if notes:
        lines.append("## Notes")
        lines.append("")
        for row, n in notes:
            n = n if isinstance(n, list) else [n]
            lines.append(f"- **{row.get('case')} / {row.get('impl')} / {row.get('kind')}**: " + "; ".join(map(str, n)))
        lines.append("")
    peer_status = payload.get("peers", {})
    if peer_status:
        lines.append("## Peer status (validated against `tmm` on a random absorbing dispersive stack)")
        lines.append("")
        lines.append("| peer | version | status |")
        lines.append("|---|---|---|")
        for name, st in peer_status.items():
            lines.append(f"| {name} | {st.get('version') or '—'} | {_md_escape(st.get('status', ''))} |")
        lines.append("")
    hooks = payload.get("hooks", {})
    if hooks:
        lines.append("## Registration hooks")
        lines.append("")
        for name, st in hooks.items():
            lines.append(f"- {name}: {st}")
        lines.append("")
    lines += list(section_lines)
    return _atomic_write(Path(path), "\n".join(lines))
