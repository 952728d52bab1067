"""Fitting benchmarks F1 and F2 (standalone): ``python -m benchmarks.fitting_cases [--n 1000]``.

* F1 — 1,000 independent fits of 401-point spectra (380–780 nm): thickness of the top layer +
  3 B-spline coefficients of the middle layer's α(λ), ρg known; 3 incoherent layers over a
  Lambertian background, integrating sphere (8°, SCE). One :func:`fitting.fit_batch` call
  (chunks of 100, solved in vmapped blocks of 4), once with Levenberg–Marquardt (the default)
  and once with Gauss–Newton; wall time includes compilation.
* F2 — joint calibration fit: 5 samples × 401 λ (45°/0°), α(λ) and ρg(λ) on 20-coefficient
  B-spline bases, 5 per-sample thicknesses (the first one known: α·h degeneracy), plus the
  bare-background spectrum fitted with them (``calibration_series`` default: without it, ρg
  and α trade off where the coated samples are dark), time to converge (compile included, and
  again with the compiled solver), once with Levenberg–Marquardt and once with scipy's bounded
  trust-region solver (``"trf"``). F2b: ρg fixed to the inversion of the bare-background
  measurement (Simonot eq. 87).

Data are synthetic (forward model with the true values, Gaussian noise σ = 0.002). Prints a
Markdown table. Figures depend on the machine and its load: report them with the machine.
"""

from __future__ import annotations

import argparse
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import fitting  # noqa: E402
import layerstack_jax as ls  # noqa: E402

WL = np.linspace(380.0, 780.0, 401)
SIGMA = 0.002


def _f1_stack(h_top, alpha_mid):
    band = 1e-6 + 3e-5 * np.exp(-(((WL - 550.0) / 25.0) ** 2))
    return ls.Stack(1.0, [
        ls.Layer(1.52, h_top, coherent=False, alpha=band, name="top"),
        ls.Layer(ls.Cauchy(1.50, 0.004), 15_000.0, coherent=False, alpha=alpha_mid, name="ink"),
        ls.Layer(1.45, 8_000.0, coherent=False, alpha=1e-6, name="primer"),
    ], ls.LambertianBackground(1.5, 0.15 + 0.6 / (1 + np.exp(-(WL - 560.0) / 25.0))))


def f1(n: int, chunk: int, method: str = "lm") -> dict:
    B = fitting.bspline_basis(WL, 3)
    rng = np.random.default_rng(1)
    geometry = ls.Sphere(8.0)
    t0 = time.perf_counter()
    h = rng.uniform(15_000.0, 30_000.0, n)
    c = rng.uniform(0.5e-5, 4e-5, (n, 3))
    one = lambda hc: ls.reflectance(_f1_stack(hc[0], B @ hc[1:]), WL, geometry)  # noqa: E731
    forward = jax.jit(lambda hc: jax.lax.map(one, hc, batch_size=50))  # bounded memory
    data = np.asarray(forward(np.column_stack([h, c]))) + SIGMA * rng.standard_normal((n, WL.size))
    t_data = time.perf_counter() - t0
    obj = fitting.Objective(_f1_stack(20_000.0, B @ np.full(3, 1e-5)), WL, fitting.Dataset(geometry, data[0], sigma=SIGMA),
                            [fitting.thickness("top"), fitting.alpha("ink", basis=B, value=np.full(3, 1e-5))])
    t0, c0 = time.perf_counter(), time.process_time()
    b = fitting.fit_batch(obj, data, method=method, chunk_size=chunk)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    # the same call again: the compiled solver is reused — the fits' own rate
    t0, c0 = time.perf_counter(), time.process_time()
    b2 = fitting.fit_batch(obj, data, method=method, chunk_size=chunk)
    wall2, cpu2 = time.perf_counter() - t0, time.process_time() - c0
    assert np.array_equal(b2.x, b.x, equal_nan=True)
    err_h = np.abs(b.values["thickness[top]"] - h) / b.errors["thickness[top]"]
    return {"case": f"F1 ({method})", "what": f"{n} independent fits, 401 λ, h + 3 α coefficients, 3 incoherent layers, sphere",
            "wall_s": wall, "converged": f"{int(b.converged.sum())}/{n}",
            "note": f"CPU {cpu:.1f} s; again (compiled): {wall2:.1f} s wall = {n / wall2:.0f} fits/s, CPU {cpu2:.1f} s = "
                    f"{n / cpu2:.0f} fits/CPU-s; median steps {np.median(b.num_steps):g}; |h−h_true|/σ_h median "
                    f"{np.median(err_h):.2f}; data generation {t_data:.1f} s (not counted)",
            "cpu_s": cpu, "again_wall_s": wall2, "again_cpu_s": cpu2}


def f2(rho_free: bool = True, method: str = "lm") -> dict:
    Ba, Br = fitting.bspline_basis(WL, 20), fitting.bspline_basis(WL, 20)
    geometry = ls.Directional(45.0, 0.0)
    alpha = 2e-5 * np.exp(-(WL - 380.0) / 35.0) + 5e-8
    rho = 0.08 + 0.5 / (1 + np.exp(-(WL - 590.0) / 20.0))
    hs = np.array([10_000.0, 15_000.0, 25_000.0, 40_000.0, 60_000.0])

    def stack(h, a, r):
        return ls.Stack(1.0, [ls.Layer(ls.Cauchy(1.525, 0.0045), h, coherent=False, alpha=a, name="varnish")],
                        ls.LambertianBackground(1.5, r))

    forward = jax.jit(jax.vmap(lambda hh: ls.reflectance(stack(hh, alpha, rho), WL, geometry)))
    rng = np.random.default_rng(2)
    spectra = np.asarray(forward(hs)) + SIGMA * rng.standard_normal((hs.size, WL.size))
    bare = np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.LambertianBackground(1.5, rho)), WL, geometry))
    bare = bare + SIGMA * rng.standard_normal(WL.size)
    obj = fitting.calibration_series(stack(10_000.0, 1e-5, 0.5), WL, spectra, geometry, layer="varnish",
                                     thicknesses=[10_000.0, 12_000.0, 20_000.0, 30_000.0, 50_000.0],
                                     alpha_basis=Ba, rho_g_basis=Br if rho_free else None, background=bare,
                                     sigma=SIGMA)
    t0 = time.perf_counter()
    r = fitting.fit(obj, method)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    fitting.fit(obj, method)
    again = time.perf_counter() - t0
    h = r.values["thickness[varnish]"]
    what = ("joint calibration: 5 samples + bare background × 401 λ, α(λ), ρg(λ) on 20 B-splines, 4 free thicknesses"
            if rho_free else
            "as F2, ρg fixed to the inverted bare-background spectrum (α on 20 B-splines, 4 thicknesses)")
    return {"case": ("F2" if rho_free else "F2b") + f" ({method})", "what": what,
            "wall_s": first, "converged": f"{'yes' if r.converged else 'NO'} ({r.num_steps} steps)",
            "note": f"compiled re-run {again:.2f} s; reduced χ² {r.reduced_chi2:.3f}; "
                    f"max |h−h_true|/h {np.max(np.abs(h - hs) / hs):.1e}"}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n", type=int, default=1000, help="number of F1 fits (default 1000)")
    p.add_argument("--chunk", type=int, default=100, help="F1 chunk size (default 100)")
    p.add_argument("--f1-methods", default="lm,gauss-newton", help="solvers for F1, comma-separated")
    p.add_argument("--methods", default="lm,trf", help="solvers for F2/F2b, comma-separated (default lm,trf)")
    p.add_argument("--only", choices=("F1", "F2", "F2b"), help="run one case")
    a = p.parse_args(argv)
    rows = []
    if a.only in (None, "F1"):
        rows.extend(f1(a.n, a.chunk, m) for m in a.f1_methods.split(","))
    if a.only in (None, "F2"):
        rows.extend(f2(method=m) for m in a.methods.split(","))
    if a.only in (None, "F2b"):
        rows.extend(f2(rho_free=False, method=m) for m in a.methods.split(","))
    dev = jax.devices()[0]
    print(f"\nfitting benchmarks — {dev.platform} ({dev.device_kind}), {os.cpu_count()} CPUs visible, "
          f"load average {os.getloadavg()[0]:.1f}\n")
    print("| case | problem | wall time (s, compile included) | converged | notes |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['case']} | {r['what']} | {r['wall_s']:.1f} | {r['converged']} | {r['note']} |")


if __name__ == "__main__":
    main()
