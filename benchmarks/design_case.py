"""D1: cost of one design iteration — merit value and gradient w.r.t. 20 thicknesses of a
20-layer coherent stack over 400 wavelengths × 10 angles (s and p), float64.

    python -m benchmarks.design_case [--repeats 5]

Prints a Markdown row: compile time, value alone, value-and-gradient (reverse mode), ratio.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.design_case")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--wavelengths", type=int, default=400)
    p.add_argument("--angles", type=int, default=10)
    a = p.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    import fitting as ft
    import layerstack_jax as ls

    wl = jnp.linspace(400.0, 800.0, a.wavelengths)
    angles = np.linspace(0.0, 45.0, a.angles)
    d0 = np.random.default_rng(7).uniform(60.0, 160.0, 20)
    stack = ls.Stack(1.0, [ls.Layer(2.35 if i % 2 == 0 else 1.46, d0[i]) for i in range(20)], ls.Substrate(1.52))
    target = ft.SpectralTarget(wl, 0.0, 0.01, angle_deg=angles, polarization="natural")
    free = tuple(range(20))

    def merit(d):
        return ft.merit(ft.with_thicknesses(stack, free, d), [target])

    value = jax.jit(merit)
    value_grad = jax.jit(jax.value_and_grad(merit))
    d = jnp.asarray(d0)
    rows = {}
    for name, fn in (("value", value), ("value+grad", value_grad)):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(d))
        first = time.perf_counter() - t0
        runs = []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(fn(d))
            runs.append(time.perf_counter() - t0)
        rows[name] = (first, min(runs), float(np.median(runs)))
    v, g = rows["value"], rows["value+grad"]
    print(f"# D1 design iteration: 20 layers, {a.wavelengths} λ × {a.angles} angles, s+p, float64 "
          f"({os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f})\n")
    print("| quantity | min | median | first call (compile + run) |\n| --- | --- | --- | --- |")
    print(f"| merit value | {v[1] * 1e3:.1f} ms | {v[2] * 1e3:.1f} ms | {v[0]:.2f} s |")
    print(f"| value + gradient (reverse mode, 20 thicknesses) | {g[1] * 1e3:.1f} ms | {g[2] * 1e3:.1f} ms | {g[0]:.2f} s |")
    print(f"| gradient / value | {g[1] / v[1]:.2f} | | |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
