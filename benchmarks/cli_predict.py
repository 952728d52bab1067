"""The command line at library speed: ``layerstack predict --vary`` against ``ls.predict``, one run:

    python -m benchmarks.cli_predict [--n 100000] [--output npy]

The stack of ``examples/varnished_painting.toml`` (a varnish with its α(λ) table over a red paint
of tabulated ρg(λ)), sphere 8° SCE, 380–780 nm by 1 nm (401 λ), N varnish thicknesses. Two
measurements, each in a fresh process so that its wall time and peak resident memory
(``VmHWM``) are its own, in float64:

* **library**: ``import layerstack_jax``, ``ls.load_stack``, the batched stack, ``ls.predict``
  (first call: compile included), ``np.save`` of the result — what a Python user writes;
* **command line**: ``python -m layerstack_cli predict … --vary varnish.thickness_nm=… -o out.npy``
  (whole process: start-up, parsing, the same ``ls.predict``, writing).

Reported: wall time of each, their ratio (target ≤ 1.3), peak RSS of each (target < 1 GB), and the
largest difference between the two outputs (must be 0: the same computation). Writes
``benchmarks/results/cli_predict.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results"
STACK = ROOT / "examples" / "varnished_painting.toml"
GRID = "380:780:1"


def _thicknesses(n: int):
    import numpy as np

    return 10_000.0 + np.arange(n, dtype=float)  # 1 nm apart: the CLI's START:STOP:STEP spelling


def _peak_rss() -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))


def library(n: int, out: str) -> dict:
    t0 = time.perf_counter()
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import layerstack_jax as ls

    stack = ls.load_stack(STACK)
    wl = ls.parse_wavelengths(GRID)
    v = stack.layers[0]
    batched = ls.Stack(stack.ambient, [ls.Layer(v.index, _thicknesses(n)[:, None], coherent=False, alpha=v.alpha,
                                                name=v.name)], stack.exit)
    spectra = np.asarray(ls.predict(batched, wl, ls.Sphere(8.0, "excluded"), batch_shape=(n,)))
    np.save(out, spectra[None])
    return {"wall_s": time.perf_counter() - t0, "peak_rss_bytes": _peak_rss()}


def _child(kind: str, n: int, out: str) -> dict:
    env = dict(os.environ, LAYERSTACK_CACHE_DIR="")  # both compile: a cold start for each
    if kind == "library":
        cmd = [sys.executable, "-m", "benchmarks.cli_predict", "--child", "--n", str(n), "--out", out]
    else:
        cmd = [sys.executable, "-c", "import resource, runpy, sys; sys.argv = ['layerstack'] + sys.argv[1:]; "
               "code = 0\ntry:\n    runpy.run_module('layerstack_cli', run_name='__main__')\nexcept SystemExit as e:\n"
               "    code = e.code or 0\nprint('RSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)\n"
               "sys.exit(code)",
               "predict", str(STACK), "-w", GRID, "-g", "sphere:8:sce",
               "--vary", f"varnish.thickness_nm=10000:{10000 + n - 1}:1", "-o", out]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env)
    wall = time.perf_counter() - t0
    if r.returncode:
        raise SystemExit(f"{kind}: {r.stderr[-3000:]}")
    if kind == "library":
        res = json.loads(r.stdout.strip().splitlines()[-1])
        res["process_wall_s"] = wall
        return res
    rss = int(next(line.split()[1] for line in r.stdout.splitlines() if line.startswith("RSS")))
    return {"wall_s": wall, "process_wall_s": wall, "peak_rss_bytes": rss, "stderr_tail": r.stderr[-300:]}


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n", type=int, default=100_000)
    p.add_argument("--out", help=argparse.SUPPRESS)
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.child:
        print(json.dumps(library(a.n, a.out)))
        return {}
    import numpy as np

    with tempfile.TemporaryDirectory() as tmp:
        lib_out, cli_out = os.path.join(tmp, "lib.npy"), os.path.join(tmp, "cli.npy")
        load0 = os.getloadavg()
        lib = _child("library", a.n, lib_out)
        cli = _child("cli", a.n, cli_out)
        diff = float(np.max(np.abs(np.load(lib_out) - np.load(cli_out))))
    out = {"case": f"{a.n} spectra, {STACK.name}, sphere:8:sce, 401 wavelengths, float64",
           "library": lib, "cli": cli, "ratio": cli["process_wall_s"] / lib["process_wall_s"],
           "max_abs_diff": diff, "loadavg_before": load0, "loadavg_after": os.getloadavg(),
           "targets": {"ratio": 1.3, "peak_rss_bytes": 2**30}}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "cli_predict.json").write_text(json.dumps(out, indent=2))
    lines = ["| N | library process s | CLI process s | ratio (≤ 1.3) | library peak RSS MB | CLI peak RSS MB | max diff | load |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |",
             f"| {a.n} | {lib['process_wall_s']:.1f} | {cli['process_wall_s']:.1f} | {out['ratio']:.2f} | "
             f"{lib['peak_rss_bytes'] / 2**20:.0f} | {cli['peak_rss_bytes'] / 2**20:.0f} | {diff:.1e} | "
             f"{load0[0]:.1f} → {out['loadavg_after'][0]:.1f} |"]
    (RESULTS / "cli_predict.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return out


if __name__ == "__main__":
    main()
