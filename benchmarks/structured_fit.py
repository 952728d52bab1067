"""S1–S3: structured least squares (issue 31) — spectral parameters free at every wavelength.

    python -m benchmarks.structured_fit [--repeats 5] [--batch 100] [--dense] [--out-dir DIR]

* **S1** — two thick, free-standing acetate-like sheets (115 µm and 480 µm, both known) in
  transmittance at normal incidence, one shared n and α(λ) free at every one of 652
  wavelengths (380–1031 nm, 1 nm): 653 parameters, 1304 readings, σ = 0.002. Timed side by side
  in one process on the same data and start: ``fitting.fit`` (Levenberg–Marquardt; the
  structured Jacobian chosen automatically, :mod:`fitting._structured`) — first fit (trace,
  compile, solve, statistics) and further fits on new noise (min / median) — and scipy's
  ``least_squares`` (``method="trf"``, ``jac="2-point"`` with ``jac_sparsity``: finite
  differences over the grouped columns of the sparse Jacobian, LSMR steps) on the library's own
  compiled residual function (the same model, called from NumPy). ``--dense`` also times one
  further fit with ``structure="dense"`` (minutes at 652 wavelengths).
* **S2** — the joint calibration series of issue 31 (four varnish thicknesses over a Lambertian
  background, 45°/0°, one thickness known, α(λ) on 8 B-splines, ρg(λ) free at every wavelength,
  the bare background fitted with them) at 401 wavelengths: a single fit (first and further) and
  ``fitting.fit_batch`` of ``--batch`` fits (first call, then again), fits/s.
* **S3** — the further-fit time of S2's single fit against the number of wavelengths (51 … 801),
  structured, and dense up to 201: the structured time should grow about linearly.

Agreement checks (a benchmark must not time a wrong answer): the library and scipy agree on
S1's values within 1e-2 of the library's standard errors; S2's batch equals the single fit on
the same data. Writes ``benchmarks/results/structured_fit.md`` and ``.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import fitting as ft  # noqa: E402
import layerstack_jax as ls  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
SIGMA = 0.002


def _load() -> str:
    return "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


# ------------------------------------------------------------------------------------------ S1
def sheets_problem(n_wl: int = 652, seed: int = 0):
    wl = 380.0 + np.arange(n_wl, dtype=float)
    h = np.array([115_000.0, 480_000.0])
    alpha = 2e-6 * (1 + 0.5 * np.cos(np.linspace(0, 6, n_wl))) + 1e-6 * np.exp(-((wl - 450) / 30) ** 2)
    g = ls.Specular(0.0, "T")

    def stack(hh, a, n):
        return ls.Stack(1.0, [ls.Layer(n, hh, coherent=False, alpha=a, name="sheet")], ls.Substrate(1.0))

    clean = np.stack([np.asarray(ls.reflectance(stack(x, jnp.asarray(alpha), 1.49), wl, g)) for x in h])
    rng = np.random.default_rng(seed)
    obj = ft.Objective(stack(h[0], 1e-6, 1.45), wl, [ft.Dataset(g, clean + SIGMA * rng.standard_normal(clean.shape),
                                                                 sigma=SIGMA)],
                       [ft.thickness("sheet", value=h, per_sample=True, fixed=np.array([True, True])),
                        ft.index_n("sheet", value=1.45), ft.alpha("sheet", basis="free", value=np.full(n_wl, 1e-6))],
                       n_samples=2)
    return obj, clean, rng


def scipy_sparse_fit(obj, data, x0):
    """scipy ``least_squares`` (TRF, finite differences over ``jac_sparsity``) on the library's
    compiled residuals in physical units scaled by the parameters' scales."""
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    layout = obj.layout
    args = obj.args([data])
    scale = layout.scale
    res = jax.jit(lambda z: obj.residuals(z * jnp.asarray(scale), args, obj.optics))
    W = obj.wavelength.size
    M, P = 2 * W, layout.size
    sparsity = lil_matrix((M, P), dtype=int)
    sparsity[:, 0] = 1  # n: every reading
    for s in range(2):
        sparsity[s * W + np.arange(W), 1 + np.arange(W)] = 1  # α(λ_i): reading i of each sheet
    fun = lambda z: np.asarray(res(z))  # noqa: E731
    fun(x0 / scale)  # compile outside the timing
    t = time.perf_counter()
    sol = least_squares(fun, x0 / scale, jac="2-point", jac_sparsity=sparsity.tocsr(), method="trf",
                        bounds=(layout.lower / scale, layout.upper / scale), x_scale=1.0)
    return sol.x * scale, time.perf_counter() - t, sol.nfev


def s1(repeats: int, dense: bool) -> dict:
    obj, clean, rng = sheets_problem()
    out = {"wavelengths": obj.wavelength.size, "parameters": obj.n_parameters, "load_start": _load()}
    t = time.perf_counter()
    first = ft.fit(obj)
    out["first_fit_s"] = time.perf_counter() - t
    out["structure"] = repr(ft._fit_functions.structure_for(obj, "auto", "lm"))
    times, lib_x, sp_times, sp_x, nfev, steps = [], [], [], [], [], []
    for _ in range(repeats):
        data = clean + SIGMA * rng.standard_normal(clean.shape)
        t = time.perf_counter()
        r = ft.fit(obj, data=[data])
        times.append(time.perf_counter() - t)
        lib_x.append(r.x)
        steps.append(r.num_steps)
        xs, ts, nf = scipy_sparse_fit(obj, data, obj.layout.x0)
        sp_times.append(ts)
        sp_x.append(xs)
        nfev.append(nf)
        err = r.x_stderr
    diff = np.max([np.max(np.abs(a - b) / err) for a, b in zip(lib_x, sp_x)])
    out.update(further_fit_min_s=min(times), further_fit_median_s=float(np.median(times)), lm_steps=steps,
               scipy_min_s=min(sp_times), scipy_median_s=float(np.median(sp_times)), scipy_nfev=nfev,
               ratio_median=float(np.median(times) / np.median(sp_times)),
               agreement_stderr=float(diff), converged=bool(first.converged), load_end=_load())
    if dense:
        ft.fit(obj, structure="dense", max_steps=1)  # compile
        t = time.perf_counter()
        rd = ft.fit(obj, data=[data], structure="dense")
        out["dense_further_fit_s"] = time.perf_counter() - t
        out["dense_vs_structured_max_rel"] = float(np.max(np.abs(rd.x - r.x) / np.abs(r.x)))
    return out


# ------------------------------------------------------------------------------------------ S2
def calibration_problem(n_wl: int, seed: int = 0):
    wl = jnp.linspace(400.0, 700.0, n_wl)
    H = np.array([10000.0, 20000.0, 30000.0, 40000.0])
    alpha = 2e-6 * (1 + 0.5 * np.cos(np.linspace(0, 3, n_wl)))
    rho = 0.2 + 0.4 * np.linspace(0, 1, n_wl)

    def st(h, a, r):
        return ls.Stack(1.0, [ls.Layer(1.52, h, coherent=False, alpha=a, name="varnish")], ls.LambertianBackground(1.5, r))

    g = ls.Directional(45.0, 0.0)
    clean = np.stack([np.asarray(ls.reflectance(st(h, jnp.asarray(alpha), jnp.asarray(rho)), wl, g)) for h in H])
    bare = np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.LambertianBackground(1.5, jnp.asarray(rho))), wl, g))
    rng = np.random.default_rng(seed)
    obj = ft.calibration_series(st(H[0], 1e-5, 0.5), wl, clean + SIGMA * rng.standard_normal(clean.shape), g,
                                layer="varnish", thicknesses=H * 0.8 + 1000, known=(0,), alpha_basis=8,
                                rho_g_basis="free", background=bare + SIGMA * rng.standard_normal(bare.shape),
                                sigma=SIGMA)
    return obj, clean, bare, rng


#: A batched fit that has not returned after this many seconds is reported as hung (issue 31's
#: fit_batch hang: XLA never delivers the result, at 0 % CPU) and the run goes on without it.
WATCHDOG_S = 300.0
HUNG: list = []


def _watched(fn, *args, **kwargs):
    """``(result, seconds)`` of ``fn(*args, **kwargs)`` run in a daemon thread, or ``(None,
    seconds)`` when it has not returned within :data:`WATCHDOG_S` (noted in :data:`HUNG`)."""
    import threading

    box = {}

    def run():
        box["out"] = fn(*args, **kwargs)

    t0 = time.perf_counter()
    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(WATCHDOG_S)
    if th.is_alive():
        HUNG.append(getattr(fn, "__name__", "call"))
        return None, time.perf_counter() - t0
    return box.get("out"), time.perf_counter() - t0


def s2(batch: int, repeats: int) -> dict:
    obj, clean, bare, rng = calibration_problem(401)
    out = {"wavelengths": 401, "parameters": obj.n_parameters, "load_start": _load()}
    t = time.perf_counter()
    ft.fit(obj)
    out["first_fit_s"] = time.perf_counter() - t
    out["structure"] = repr(ft._fit_functions.structure_for(obj, "auto", "lm"))
    times = []
    for _ in range(repeats):
        data = [clean + SIGMA * rng.standard_normal(clean.shape), bare + SIGMA * rng.standard_normal(bare.shape)]
        t = time.perf_counter()
        single = ft.fit(obj, data=data)
        times.append(time.perf_counter() - t)
    out.update(further_fit_min_s=min(times), further_fit_median_s=float(np.median(times)))
    ys = [clean + SIGMA * rng.standard_normal((batch,) + clean.shape),
          bare + SIGMA * rng.standard_normal((batch,) + bare.shape)]
    out["batch"] = batch
    b, out["batch_first_s"] = _watched(ft.fit_batch, obj, ys, chunk_size=min(batch, 100), progress=False)
    if b is not None:
        b2, out["batch_s"] = _watched(ft.fit_batch, obj, ys, chunk_size=min(batch, 100), progress=False)
        if b2 is not None:
            b = b2
            out["fits_per_s"] = batch / out["batch_s"]
        else:
            out["batch_hung"] = "second call"
        out["batch_converged"] = int(b.converged.sum())
        one = ft.fit(obj, data=[ys[0][0], ys[1][0]])
        out["batch_vs_single_max_rel"] = float(np.max(np.abs(b.x[0] - one.x) / np.abs(one.x)))
    else:
        out["batch_hung"] = "first call"
    # the same fits one after the other with the single fit's compiled solver
    t = time.perf_counter()
    for k in range(batch):
        ft.fit(obj, data=[ys[0][k], ys[1][k]])
    out["sequential_s"] = time.perf_counter() - t
    out["sequential_fits_per_s"] = batch / out["sequential_s"]
    out["load_end"] = _load()
    return out


def s3(sizes, dense_up_to: int, repeats: int) -> list:
    rows = []
    for n in sizes:
        obj, clean, bare, rng = calibration_problem(n)
        row = {"wavelengths": n, "parameters": obj.n_parameters, "load": _load()}
        for mode in ("structured", "dense"):
            if mode == "dense" and n > dense_up_to:
                continue
            ft.fit(obj, structure=mode)
            ts = []
            for _ in range(repeats):
                data = [clean + SIGMA * rng.standard_normal(clean.shape), bare + SIGMA * rng.standard_normal(bare.shape)]
                t = time.perf_counter()
                r = ft.fit(obj, data=data, structure=mode)
                ts.append(time.perf_counter() - t)
            row[f"{mode}_median_s"] = float(np.median(ts))
            row[f"{mode}_steps"] = int(r.num_steps)
            # the compiled solve alone (solver and the statistics' Jacobian, no host statistics)
            from fitting import _compiled_fit, _solver_options

            o = _solver_options.SolverOptions(structure=mode)
            fn = _compiled_fit.compiled_fit(obj, o, batched=False)
            y0 = np.asarray(_solver_options.starting_point(obj, o, obj.layout.x0))
            ts = []
            for _ in range(repeats):
                data = [clean + SIGMA * rng.standard_normal(clean.shape), bare + SIGMA * rng.standard_normal(bare.shape)]
                args = obj.args(data)
                t = time.perf_counter()
                jax.block_until_ready(fn(y0, args, obj.optics))
                ts.append(time.perf_counter() - t)
            row[f"{mode}_solve_median_s"] = float(np.median(ts))
        rows.append(row)
    return rows


def markdown(res: dict) -> str:
    a, b = res["S1"], res["S2"]
    lines = [
        "# S1–S3: structured least squares (spectral parameters free per wavelength)",
        "",
        f"Run {res['when']} (git {res['git']}), {res['machine']}, jax {jax.__version__} CPU, float64. "
        f"`uptime` at the start: `{res['uptime']}`. Process pinned to CPU(s) {res['cpus_used']} "
        "(`taskset`): on this shared, overloaded machine XLA's CPU thread pool waits for its threads to be "
        "scheduled, and mid-sized solves ran up to 40× slower with both CPUs (S2's solve at 201 wavelengths: "
        "0.69 s on 2 CPUs at load 14, 16 ms pinned to one). Figures are wall times; load averages at each "
        "section's start and end are given: compare rows of one run.",
        "",
        "## S1: two sheets in transmittance, one n + α(λ) free at 652 wavelengths (653 parameters)",
        "",
        f"Load {a['load_start']} → {a['load_end']}. {a['structure']}.",
        "",
        "| quantity | library (`fit`, LM, structured) | scipy `least_squares` (TRF, `jac_sparsity`) |",
        "| --- | --- | --- |",
        f"| first fit (trace + compile + solve + statistics) | {a['first_fit_s']:.2f} s | — |",
        f"| further fit, new noise (min / median) | {a['further_fit_min_s'] * 1e3:.0f} / "
        f"{a['further_fit_median_s'] * 1e3:.0f} ms ({a['lm_steps']} LM steps) | {a['scipy_min_s'] * 1e3:.0f} / "
        f"{a['scipy_median_s'] * 1e3:.0f} ms ({a['scipy_nfev']} evaluations) |",
        f"| library / scipy (medians) | {a['ratio_median']:.2f}× | target ≤ 5× |",
    ]
    if "dense_further_fit_s" in a:
        lines.append(f"| further fit with `structure=\"dense\"` | {a['dense_further_fit_s']:.1f} s "
                     f"(values equal to {a['dense_vs_structured_max_rel']:.1e} relative) | |")
    lines += [
        "",
        f"Agreement: library and scipy values within {a['agreement_stderr']:.2e} standard errors (every repeat); "
        f"first fit converged: {a['converged']}. The library's time includes the full statistics "
        "(covariance by the structured inverse, correlations, identifiability, report ingredients); scipy's is the "
        "bare `least_squares` call.",
        "",
        "## S2: joint calibration series at 401 wavelengths, ρg(λ) free, α on 8 B-splines",
        "",
        f"Load {b['load_start']} → {b['load_end']}. {b['parameters']} parameters; {b['structure']}.",
        "",
        "| quantity | measured |",
        "| --- | --- |",
        f"| single fit, first (compile included) | {b['first_fit_s']:.2f} s |",
        f"| single fit, further (min / median) | {b['further_fit_min_s'] * 1e3:.0f} / {b['further_fit_median_s'] * 1e3:.0f} ms |",
        f"| `fit_batch` of {b['batch']} fits, first call (compile included) | {b['batch_first_s']:.1f} s"
        + (" — **did not return** (the fit_batch hang of issue 31; watchdog)" if b.get("batch_hung") == "first call"
           else "") + " |",
    ]
    if "fits_per_s" in b:
        lines.append(f"| `fit_batch` of {b['batch']} fits, again | {b['batch_s']:.2f} s = **{b['fits_per_s']:.1f} fits/s** "
                     f"({b['batch_converged']}/{b['batch']} converged) |")
    elif b.get("batch_hung") == "second call":
        lines.append(f"| `fit_batch` of {b['batch']} fits, again | **did not return** within {WATCHDOG_S:.0f} s (the "
                     "fit_batch hang of issue 31, fixed elsewhere; watchdog) |")
    if "batch_vs_single_max_rel" in b:
        lines.append(f"| batch row 0 vs a single fit on the same data | {b['batch_vs_single_max_rel']:.1e} relative |")
    lines += [
        f"| {b['batch']} single fits one after the other (`fit(objective, data=...)`) | {b['sequential_s']:.2f} s = "
        f"{b['sequential_fits_per_s']:.1f} fits/s |",
        "",
        "## S3: scaling with the number of wavelengths (S2's single fit, further fits, median)",
        "",
        "`fit`: the whole call (solve, then the statistics and the `FitResult` on the host — the P × P covariance "
        "and correlation it holds grow with P²); solve: the compiled solve alone (solver steps and the Jacobian).",
        "",
        "| wavelengths | parameters | structured `fit` | structured solve | LM steps | dense `fit` | dense solve "
        "| LM steps | load |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]

    def ms(r, key):
        return f"{r[key] * 1e3:.1f} ms" if key in r else "—"

    for r in res["S3"]:
        lines.append(f"| {r['wavelengths']} | {r['parameters']} | {ms(r, 'structured_median_s')} | "
                     f"{ms(r, 'structured_solve_median_s')} | {r['structured_steps']} | {ms(r, 'dense_median_s')} | "
                     f"{ms(r, 'dense_solve_median_s')} | {r.get('dense_steps', '—')} | {r['load']} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    import platform
    import subprocess

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--batch", type=int, default=100)
    p.add_argument("--dense", action="store_true", help="also time S1 with the dense Jacobian (slow)")
    p.add_argument("--sizes", default="51,101,201,401,801")
    p.add_argument("--dense-up-to", type=int, default=201)
    p.add_argument("--only", default="S1,S2,S3")
    p.add_argument("--out-dir", default=str(RESULTS))
    a = p.parse_args(argv)
    only = a.only.split(",")
    res = {"when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           "git": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip(),
           "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs",
           "cpus_used": sorted(os.sched_getaffinity(0)),
           "uptime": subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()}
    if "S1" in only:
        res["S1"] = s1(a.repeats, a.dense)
        print(json.dumps(res["S1"], indent=1), flush=True)
    if "S2" in only:
        res["S2"] = s2(a.batch, a.repeats)
        print(json.dumps(res["S2"], indent=1), flush=True)
    if "S3" in only:
        res["S3"] = s3([int(s) for s in a.sizes.split(",")], a.dense_up_to, max(1, a.repeats // 2 + 1))
        print(json.dumps(res["S3"], indent=1), flush=True)
    out = Path(a.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "structured_fit.json").write_text(json.dumps(res, indent=1))
    if all(k in res for k in ("S1", "S2", "S3")):
        (out / "structured_fit.md").write_text(markdown(res))
    if HUNG:  # a hung XLA call cannot be joined: leave without waiting for it
        sys.stdout.flush()
        os._exit(0)


if __name__ == "__main__":
    main()
