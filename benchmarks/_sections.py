"""Shared plumbing of the whole-model benchmark sections (P2, P3, memory, scaling, accuracy, precision).

Each section is a module with ``run(quick: bool, out_dir: Path) -> dict`` and
``markdown(result: dict) -> list[str]``; ``python -m benchmarks`` runs each in its own
process (``python -m benchmarks._sections SECTION --out r.json``) so that peak-RSS figures are
per section and float32 sections can switch ``jax_enable_x64`` off.  Here: the worker entry
point, jitted timing of the public API through :func:`benchmarks._harness.measure`, and the
matplotlib (object API, Agg canvas) figure helper.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
import traceback
from pathlib import Path

from . import _harness

#: section name -> "module[:run function]" (default ``run``); the module also has ``markdown``.
#: The order is the order of the report.
SECTIONS: dict[str, str] = {
    "P2": "benchmarks.radiometric:run_section",
    "P3": "benchmarks.mixed",
    "MEMORY": "benchmarks.memory",
    "PRECISION": "benchmarks.precision",
    "ACCURACY": "benchmarks.accuracy",
    "SCALING": "benchmarks.scaling",
}

#: Generous per-section worker timeouts (s), quick and full mode alike.
TIMEOUTS: dict[str, float] = {"P2": 900, "P3": 900, "MEMORY": 2000, "SCALING": 1200, "ACCURACY": 900, "PRECISION": 900}


def setup_jax(x64: bool = True):
    """Import jax with float64 on or off (a process-wide choice: one section per process)."""
    import jax

    jax.config.update("jax_enable_x64", bool(x64))
    return jax


def _cpu_s() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def timed(fn, *args, quick: bool = False, max_time: float = 20.0) -> tuple[dict, object]:
    """Time a jitted function as users call it; returns ``(figures, last output)``.

    Compile (trace + lower + XLA compile, ahead of time) is timed apart, in wall time and in
    this process's CPU time; then :func:`benchmarks._harness.measure` times the compiled
    executable (``repeats`` repeats, autoranged to >= 0.2 s each in full mode; per-call
    ``min_s``/``median_s``).  ``cpu_s_per_call`` is the process CPU time over the timed phase
    divided by the calls made: on a contended machine it is the steadier figure (it does not
    count time spent waiting for a core; with 2 threads it can exceed the wall time).
    ``foreign_cpu_frac``: share of the machine's CPU used by other processes meanwhile.
    """
    c0, t0 = _cpu_s(), time.perf_counter()
    lowered = fn.lower(*args)
    compiled = lowered.compile()
    compile_wall, compile_cpu = time.perf_counter() - t0, _cpu_s() - c0
    c0 = _cpu_s()
    with _harness.CpuContention() as c:
        t, out = _harness.measure(compiled, *args, warmup=1, repeats=1 if quick else 5, min_time=0.0 if quick else 0.2,
                                  max_time=max_time, aot=False, return_output=True)
    calls = 1 + (1 if (not quick and t.first_call_s < 0.2) else 0) + t.repeats * t.number  # as measure() calls
    d = {
        "compile_s": compile_wall,
        "compile_cpu_s": compile_cpu,
        "first_call_s": t.first_call_s,
        "min_s": t.min_s,
        "median_s": t.median_s,
        "cpu_s_per_call": (_cpu_s() - c0) / max(calls, 1),
        "repeats": t.repeats,
        "number": t.number,
        "foreign_cpu_frac": c.foreign_frac,
    }
    return d, out


def figure(width: float = 6.4, height: float = 4.2):
    """A matplotlib Figure on an Agg canvas (object API, no pyplot state)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save(fig, path: Path) -> str:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path.name


def contention_note(rows) -> str | None:
    """One line naming the timings taken while other processes used > 10 % of the CPUs."""
    busy = [f"{name} ({100 * f:.0f}%)" for name, f in rows if f is not None and f > 0.1]
    if not busy:
        return None
    return "other processes used > 10% of the CPUs while timing " + ", ".join(busy) + " — those timings are inflated"


def section_module(name: str):
    return importlib.import_module(SECTIONS[name].partition(":")[0])


SECTION_TITLES = {
    "P2": "P2 — incoherent layers over a Lambertian background (sphere SCE)",
    "P3": "P3 — mixed stack: coherent films on an incoherent varnish over a Lambertian background (45°/0°)",
    "MEMORY": "Memory — 100,000 spectra in chunks",
    "SCALING": "Scaling — time vs layers, wavelengths, angles, batch",
    "ACCURACY": "Accuracy vs cost — diffuse-reflectance quadrature",
    "PRECISION": "float32 vs float64 (CPU)",
}


def markdown_lines(sections: dict) -> list[str]:
    """The report's part on the sections: each result rendered by its module's ``markdown``."""
    lines: list[str] = []
    for name, res in sections.items():
        lines += [f"## {SECTION_TITLES.get(name, name)}", ""]
        if res.get("status") != "ok":
            lines += [f"**{name}: {res.get('status')}**", ""]
            continue
        try:
            lines += section_module(name).markdown(res)
        except Exception as e:  # a report bug must not lose the run
            lines.append(f"(could not render {name}: {type(e).__name__}: {e}; see latest.json)")
        lines += ["", f"Section process: peak RSS {res.get('peak_rss_bytes', 0) / 2**20:.0f} MiB, "
                  f"wall {res.get('process_wall_s', 0):.0f} s.", ""]
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks._sections")
    ap.add_argument("section", choices=list(SECTIONS))
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", required=True, help="JSON result file")
    ap.add_argument("--plot-dir", default=str(_harness.RESULTS_DIR))
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    try:
        res = getattr(section_module(a.section), SECTIONS[a.section].partition(":")[2] or "run")(
            quick=a.quick, out_dir=Path(a.plot_dir))
        res.setdefault("status", "ok")
    except Exception as e:  # reported in the table, never silent
        res = {"status": f"failed: {type(e).__name__}: {e}", "error": traceback.format_exc()}
    res["peak_rss_bytes"] = _harness.peak_rss_bytes()
    res["worker_wall_s"] = time.perf_counter() - t0
    _harness.write_json(res, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
