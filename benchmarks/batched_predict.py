"""Batched prediction through the public path (:func:`layerstack_jax._instruments.batched.predict`), standalone:

    python -m benchmarks.batched_predict [--n 100000 10000] [--chunk 4] [--step 2048]

The P2 stack (3 incoherent absorbing layers, n = 1.5, 1.6, 1.45, α(λ) of
:func:`benchmarks.radiometric.build`, over a Lambertian background n_g = 1.52 with ρg(λ); sphere 8°
SCE; 401 λ), one set of three thicknesses per spectrum given as batched leaves ``(N, 1)`` of the
stack. Each N runs in its own process (``--child``) so that its peak resident memory
(``VmHWM``: imports, XLA runtime, compiled code, the ``(N, 401)`` float64 output — 321 MB at
N = 100,000 — and the chunk intermediates) is its own. Reported: compile (first call on one
``step`` of spectra), wall time and spectra/s of the timed call (compiled function reused), peak
RSS, the load of the machine during the run (foreign CPU share), and a check of 3 random rows
against single :func:`layerstack_jax.reflectance` calls. Writes
``benchmarks/results/batched_predict.json`` and ``.md``.

Targets (issue 19): peak RSS < 1 GB and >= 2,000 spectra/s at N = 100,000 on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "results"


def _peak_rss() -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))


def _cpu_times():
    """(this process's CPU seconds, the machine's busy CPU seconds) from /proc."""
    with open("/proc/stat") as f:
        fields = [float(v) for v in f.readline().split()[1:]]
    tick = os.sysconf("SC_CLK_TCK")
    busy = (sum(fields) - fields[3] - fields[4]) / tick
    t = os.times()
    return t.user + t.system, busy


def child(n: int, chunk: int, step: int) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    import layerstack_jax as ls
    from layerstack_jax._instruments.batched import predict

    from .radiometric import build

    _, wl, alpha, rho, indices = build(ls.DEFAULT_NODES, jnp.float64)
    wl, alpha, rho = np.asarray(wl), [np.asarray(a) for a in alpha], np.asarray(rho)
    H = np.random.default_rng(0).uniform(2e3, 3e4, (n, 3))

    def stack(h):
        layers = [ls.Layer(ni, h[..., j:j + 1] if h.ndim > 1 else h[j], coherent=False, alpha=a)
                  for j, (ni, a) in enumerate(zip(indices, alpha))]
        return ls.Stack(1.0, layers, ls.LambertianBackground(1.52, rho))

    geometry = ls.Sphere(8.0, "excluded")
    t0 = time.perf_counter()
    predict(stack(H[:step]), wl, geometry, chunk=chunk, step=step)  # compiles (same shapes as the timed run)
    compile_s = time.perf_counter() - t0
    cpu0, busy0 = _cpu_times()
    t0 = time.perf_counter()
    out = predict(stack(H), wl, geometry, chunk=chunk, step=step)
    wall = time.perf_counter() - t0
    cpu1, busy1 = _cpu_times()
    foreign = max(0.0, (busy1 - busy0) - (cpu1 - cpu0)) / max(busy1 - busy0, 1e-9)
    rows = np.random.default_rng(1).choice(n, 3, replace=False)
    err = max(float(np.max(np.abs(out[i] - np.asarray(ls.reflectance(stack(H[i]), wl, geometry))))) for i in rows)
    return {"n": n, "chunk": chunk, "step": step, "compile_s": compile_s, "wall_s": wall, "spectra_per_s": n / wall,
            "peak_rss_bytes": _peak_rss(), "output_bytes": int(out.nbytes), "finite": bool(np.isfinite(out).all()),
            "max_abs_diff_vs_reflectance": err, "foreign_cpu_frac": foreign, "loadavg": os.getloadavg()}


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n", type=int, nargs="+", default=[100_000, 10_000])
    p.add_argument("--chunk", type=int, default=4)
    p.add_argument("--step", type=int, default=2048)
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.child:
        print(json.dumps(child(a.n[0], a.chunk, a.step)))
        return {}
    runs = []
    for n in a.n:
        r = subprocess.run([sys.executable, "-m", "benchmarks.batched_predict", "--child", "--n", str(n),
                            "--chunk", str(a.chunk), "--step", str(a.step)],
                           capture_output=True, text=True, cwd=Path(__file__).resolve().parents[1])
        if r.returncode:
            raise SystemExit(r.stderr[-3000:])
        runs.append(json.loads(r.stdout.strip().splitlines()[-1]))
        print(runs[-1], flush=True)
    out = {"case": "P2 batched predict (public predict())", "cpu_count": os.cpu_count(), "runs": runs,
           "targets": {"peak_rss_bytes": 2**30, "spectra_per_s": 2000}}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "batched_predict.json").write_text(json.dumps(out, indent=2))
    lines = ["| N | chunk | step | compile s | wall s | spectra/s | peak RSS MB | output MB | max diff | foreign CPU |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in runs:
        lines.append(f"| {r['n']} | {r['chunk']} | {r['step']} | {r['compile_s']:.1f} | {r['wall_s']:.1f} | "
                     f"{r['spectra_per_s']:.0f} | {r['peak_rss_bytes'] / 2**20:.0f} | {r['output_bytes'] / 2**20:.0f} | "
                     f"{r['max_abs_diff_vs_reflectance']:.1e} | {r['foreign_cpu_frac']:.0%} |")
    (RESULTS / "batched_predict.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return out


if __name__ == "__main__":
    main()
