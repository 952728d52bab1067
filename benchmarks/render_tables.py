"""Timing of the renderer tables of one rough coating (standalone).

    python -m benchmarks.render_tables [--angles 90] [--wavelengths 81] [--out 30] [--phi 19] [--sigma 25]

Coating: Hirayama Fig. 8 (air · dielectric 1.4, 1000 nm · Ag 5 nm · dielectric 1.4, 1000 nm · Al),
fixed indices (Ag 0.05 + 4.0i, Al 0.96 + 6.69i: no database access), He–Torrance object of
σ0 nm and τ = 300 nm, float64 on the CPU. Reports the compile time (first call), then the median
of three calls of ``coating_tables`` (a) k_r, k_t and k_d without, (b) with the interpolation-error
estimate, (c) specular tables only, and the stated interpolation errors. Target (issue 16):
(a) ≤ 2 s after compilation on 2 cores for 90 angles × 81 wavelengths.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import layerstack_jax as ls  # noqa: E402
from layerstack_jax._appearance.render_tables import coating_tables  # noqa: E402


def fig8_stack():
    silver, aluminium = ls.Index(0.05, 4.0), ls.Index(0.96, 6.69)
    return ls.Stack(ambient=1.0, layers=[ls.Layer(1.4, 1000.0), ls.Layer(silver, 5.0), ls.Layer(1.4, 1000.0)],
                    exit=ls.Substrate(aluminium))


def timed(fn, repeats=3):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--angles", type=int, default=90)
    p.add_argument("--wavelengths", type=int, default=81)
    p.add_argument("--out", type=int, default=30, help="outgoing polar cosines B")
    p.add_argument("--phi", type=int, default=19, help="outgoing azimuths P on [0, π]")
    p.add_argument("--sigma", type=float, default=25.0, help="rms roughness σ0 (nm)")
    p.add_argument("--block", type=int, default=8)
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")  # aliasing warnings of the 1000 nm films on a coarse grid
    wl = np.linspace(380.0, 780.0, a.wavelengths)
    stack = fig8_stack()
    opts = dict(n_angles=a.angles, n_angles_out=a.out, n_phi=a.phi, sigma_nm=a.sigma, tau_nm=300.0, block=a.block)
    print(f"# render tables: {a.angles} angles x {a.wavelengths} wavelengths, k_d {a.angles}x{a.out}x{a.phi}x"
          f"{a.wavelengths}, sigma0 = {a.sigma} nm, tau = 300 nm")
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, jax {jax.__version__}, "
          f"{jax.devices()[0].platform}, float64")
    t0 = time.perf_counter()
    coating_tables(stack, wl, **opts)  # compiles the table and midpoint shapes (shared)
    print(f"first call (compile + run, with error estimate): {time.perf_counter() - t0:.2f} s")
    t_plain, _ = timed(lambda: coating_tables(stack, wl, estimate_error=False, **opts))
    t_err, tabs = timed(lambda: coating_tables(stack, wl, **opts))
    coating_tables(stack, wl, include_diffuse=False, **opts)
    t_spec, _ = timed(lambda: coating_tables(stack, wl, include_diffuse=False, estimate_error=False, **opts))
    print(f"(a) k_r, k_t, k_d:                 {t_plain:.3f} s  (target <= 2 s)")
    print(f"(b) same + interpolation error:    {t_err:.3f} s")
    print(f"(c) specular tables only:          {t_spec:.4f} s")
    print(f"k_d table: {tabs.k_d.size / 1e6:.2f} M values, {tabs.k_d.nbytes / 2**20:.1f} MiB")
    print(f"interpolation error (relative, floor 1e-3 of the peak): k_r/k_t {tabs.interpolation_error_k_r:.3g}, "
          f"k_d {tabs.interpolation_error_k_d:.3g}")
    print(f"interpolation error (absolute): k_r/k_t {tabs.absolute_error_k_r:.3g}, k_d {tabs.absolute_error_k_d:.3g} 1/sr "
          f"(k_d peak {tabs.k_d.max():.3g} 1/sr)")


if __name__ == "__main__":
    main()
