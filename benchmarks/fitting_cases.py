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

F1 runs in float64 and again, on the same data, in float32 (a subprocess with
``JAX_ENABLE_X64=0``: how a GPU user runs) — with the default 48 quadrature nodes per segment
and with 24 (~1e-8 in R, docs/guide/accuracy.md, "Quadrature": below float32's own round-off) — with the largest
difference of each float32 fit's values from the float64 fit's in standard errors (the accuracy
statement of ``tests/test_precision.py``).

Data are synthetic (forward model with the true values, Gaussian noise σ = 0.002). Prints a
Markdown table. Figures depend on the machine and its load: report them with the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import jax

if os.environ.get("JAX_ENABLE_X64") != "0":  # float64, unless the float32 run of F1 (a subprocess)
    jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import fitting  # noqa: E402
import layerstack_jax as ls  # noqa: E402
from layerstack_jax import DEFAULT_NODES  # noqa: E402

WL = np.linspace(380.0, 780.0, 401)
SIGMA = 0.002


def _f1_stack(h_top, alpha_mid):
    band = 1e-6 + 3e-5 * np.exp(-(((WL - 550.0) / 25.0) ** 2))
    return ls.Stack(1.0, [
        ls.Layer(1.52, h_top, coherent=False, alpha=band, name="top"),
        ls.Layer(ls.Cauchy(1.50, 0.004), 15_000.0, coherent=False, alpha=alpha_mid, name="ink"),
        ls.Layer(1.45, 8_000.0, coherent=False, alpha=1e-6, name="primer"),
    ], ls.LambertianBackground(1.5, 0.15 + 0.6 / (1 + np.exp(-(WL - 560.0) / 25.0))))


def f1_data(n: int):
    """``(h, c, data)``: F1's true values and noisy spectra (float64 forward model)."""
    B = fitting.bspline_basis(WL, 3)
    rng = np.random.default_rng(1)
    h = rng.uniform(15_000.0, 30_000.0, n)
    c = rng.uniform(0.5e-5, 4e-5, (n, 3))
    one = lambda hc: ls.reflectance(_f1_stack(hc[0], B @ hc[1:]), WL, ls.Sphere(8.0))  # noqa: E731
    forward = jax.jit(lambda hc: jax.lax.map(one, hc, batch_size=50))  # bounded memory
    data = np.asarray(forward(np.column_stack([h, c]))) + SIGMA * rng.standard_normal((n, WL.size))
    return h, c, data


def f1(n: int, chunk: int, method: str = "lm", data_file: str | None = None, nodes: int = DEFAULT_NODES) -> dict:
    B = fitting.bspline_basis(WL, 3)
    geometry = ls.Sphere(8.0)
    t0 = time.perf_counter()
    if data_file is None:
        h, c, data = f1_data(n)
    else:  # the float32 run fits the float64 run's data
        saved = np.load(data_file)
        h, data = saved["h"], saved["data"]
    t_data = time.perf_counter() - t0
    obj = fitting.Objective(_f1_stack(20_000.0, B @ np.full(3, 1e-5)), WL, fitting.Dataset(geometry, data[0], sigma=SIGMA),
                            [fitting.thickness("top"), fitting.alpha("ink", basis=B, value=np.full(3, 1e-5))],
                            nodes=nodes)
    t0, c0 = time.perf_counter(), time.process_time()
    b = fitting.fit_batch(obj, data, method=method, chunk_size=chunk)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    # the same call again: the compiled solver is reused — the fits' own rate
    t0, c0 = time.perf_counter(), time.process_time()
    b2 = fitting.fit_batch(obj, data, method=method, chunk_size=chunk)
    wall2, cpu2 = time.perf_counter() - t0, time.process_time() - c0
    assert np.array_equal(b2.x, b.x, equal_nan=True)
    err_h = np.abs(b.values["thickness[top]"] - h) / b.errors["thickness[top]"]
    precision = "float64" if jax.config.read("jax_enable_x64") else "float32"
    row = {"case": f"F1 ({method}, {precision}" + (f", {nodes} nodes" if nodes != DEFAULT_NODES else "") + ")",
           "what": f"{n} independent fits, 401 λ, h + 3 α coefficients, 3 incoherent layers, sphere",
           "wall_s": wall, "converged": f"{int(b.converged.sum())}/{n}",
           "note": f"CPU {cpu:.1f} s; again (compiled): {wall2:.1f} s wall = **{n / wall2:.0f} fits/s**, CPU {cpu2:.1f} s = "
                   f"{n / cpu2:.0f} fits/CPU-s; median steps {np.median(b.num_steps):g} (mean {np.mean(b.num_steps):.2f}); "
                   f"|h−h_true|/σ_h median {np.median(err_h):.2f}; data generation {t_data:.1f} s (not counted)",
           "cpu_s": cpu, "again_wall_s": wall2, "again_cpu_s": cpu2, "fits_per_s": n / wall2,
           "x": b.x, "stderr": b.stderr}
    return row


def f1_float32(n: int, chunk: int, method: str, double: dict, nodes: int = DEFAULT_NODES) -> dict:
    """F1 again in float32 on the float64 run's data (a subprocess with x64 off), with ``nodes``
    quadrature nodes per segment, and the largest difference of its values from ``double``'s
    (the float64 row, default nodes) in standard errors."""
    h, _, data = f1_data(n)
    with tempfile.TemporaryDirectory() as tmp:
        np.savez(os.path.join(tmp, "f1.npz"), h=h, data=data)
        env = dict(os.environ, JAX_ENABLE_X64="0")
        proc = subprocess.run([sys.executable, "-m", "benchmarks.fitting_cases", "--only", "F1", "--f1-methods", method,
                               "--n", str(n), "--chunk", str(chunk), "--nodes", str(nodes),
                               "--data", os.path.join(tmp, "f1.npz"),
                               "--json", os.path.join(tmp, "row.json")], env=env, capture_output=True, text=True)
        if proc.returncode:
            raise RuntimeError(proc.stderr[-3000:])
        with open(os.path.join(tmp, "row.json")) as f:
            row = json.load(f)
    dev = np.abs(np.asarray(row["x"]) - double["x"]) / double["stderr"]
    row["note"] += (f"; same data as the float64 run: values within {np.nanmax(dev):.1e} standard errors of its "
                    f"(median {np.nanmedian(dev):.1e}); {row['fits_per_s'] / double['fits_per_s']:.2f}× its rate")
    return row


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
    p.add_argument("--no-float32", action="store_true", help="skip F1's float32 run")
    p.add_argument("--nodes", type=int, default=DEFAULT_NODES, help=argparse.SUPPRESS)  # the float32 subprocess
    p.add_argument("--data", help=argparse.SUPPRESS)  # the float32 subprocess: F1's data file
    p.add_argument("--json", help=argparse.SUPPRESS)  # the float32 subprocess: where its row goes
    a = p.parse_args(argv)
    rows = []
    if a.data:  # the float32 subprocess of f1_float32
        row = f1(a.n, a.chunk, a.f1_methods, a.data, a.nodes)
        with open(a.json, "w") as f:
            json.dump(dict(row, x=row["x"].tolist(), stderr=row["stderr"].tolist()), f)
        return
    if a.only in (None, "F1"):
        for m in a.f1_methods.split(","):
            rows.append(f1(a.n, a.chunk, m))
            if not a.no_float32 and m == "lm":
                double = rows[-1]
                rows.append(f1_float32(a.n, a.chunk, m, double))
                # the per-pixel set-up: quadrature matched to float32 (24 nodes: ~1e-8, docs/guide/accuracy.md)
                rows.append(f1_float32(a.n, a.chunk, m, double, nodes=24))
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
