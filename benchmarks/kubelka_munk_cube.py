"""K2: a varnished painting's cube into pigment maps — ``fit_cube`` (zarr on disk) vs ``fit_batch``
(in memory) on the same pixels (issue 28, Performance: ratio ≤ 1.3).

    python -m benchmarks.kubelka_munk_cube [--size 100 100] [--region 25 25] [--chunk-size 125] [--float32]
    python -m benchmarks.kubelka_munk_cube --quick      # a 40 × 40 cube

The pixel model and its 6 free parameters are K1's (``benchmarks/kubelka_munk_fit.py``: three
pigment concentrations in a 10 µm Kubelka–Munk body over a ground, under a varnish of fitted
thickness and α(λ) on 3 B-splines with one coefficient known; 401 λ, 45°/0°; SYNTHETIC). The
cube (``size`` pixels × 401 λ, smooth concentration and varnish maps plus per-pixel scatter, noise
σ = 0.002) is made with ``ls.predict`` and written with ``ls.write_zarr_cube`` (float32 on disk,
chunked by ``--region``). Then, after the compiles (``fit_batch`` on one chunk of fits, and
``fit_cube`` on a one-row cube: its rank check at the start compiles once per objective):

* ``fit_batch``: every pixel, read into memory beforehand (the read not timed), one call;
* ``fit_cube``: the same job from the zarr store, region by region, the maps and standard errors
  written to a zarr store (``resume=False``: a fresh store).

Reported: both wall times, their ratio (target ≤ 1.3), pixels/s, the maps' agreement with
``fit_batch``, the status counts, and the load. Writes ``benchmarks/results/kubelka_munk_cube.md``
and ``.json`` (a ``--quick`` run: ``kubelka_munk_cube_quick.*``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from . import kubelka_munk_fit as k1

RESULTS = Path(__file__).resolve().parent / "results"
TARGET_RATIO = 1.3


def painting(ny: int, nx: int, seed: int = 2) -> np.ndarray:
    """``(ny, nx, 6)`` true free parameters: smooth fields (a red left, a blue right, the varnish
    thicker at the bottom, its α varying across) with 5 % per-pixel scatter, inside K1's box."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:ny, 0:nx] / np.array([max(ny - 1, 1), max(nx - 1, 1)])[:, None, None]
    jitter = lambda: rng.uniform(0.95, 1.05, (ny, nx))  # noqa: E731
    return np.stack([(0.4 + 0.2 * yy) * jitter(),
                     (0.05 + 0.3 * np.clip(1.4 - 1.8 * xx, 0, 1)) * jitter(),
                     (0.05 + 0.3 * np.clip(1.8 * xx - 0.4, 0, 1)) * jitter(),
                     (12_000.0 + 25_000.0 * yy) * jitter(),
                     k1.ALPHA_COEFFS[1] * (0.8 + 0.4 * xx) * jitter(),
                     k1.ALPHA_COEFFS[2] * (1.2 - 0.4 * yy) * jitter()], -1)


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, nargs=2, default=[100, 100])
    p.add_argument("--quick", action="store_true", help="a 40 x 40 cube (results: kubelka_munk_cube_quick.*)")
    p.add_argument("--region", type=int, nargs=2, default=[25, 25], help="fit_cube's regions and the store's chunks")
    p.add_argument("--chunk-size", type=int, default=125, help="fits per compiled fit_batch call (both paths)")
    p.add_argument("--float32", action="store_true", help="run with jax_enable_x64 off")
    p.add_argument("--dir", default=None, help="where to write the cube and the maps (default: a temporary dir)")
    p.add_argument("--out-dir", default=str(RESULTS))
    a = p.parse_args(argv)
    if a.quick:
        a.size = [40, 40]

    import jax

    jax.config.update("jax_enable_x64", not a.float32)
    import fitting
    import layerstack_jax as ls

    ny, nx = a.size
    res = {"when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           "git": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip(),
           "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs",
           "cpus_used": sorted(os.sched_getaffinity(0)), "uptime": k1._uptime(),
           "versions": {"python": platform.python_version(), "jax": jax.__version__, "numpy": np.__version__},
           "size": [ny, nx], "wavelengths": int(k1.WL.size), "region": a.region, "chunk_size": a.chunk_size,
           "precision": "float32" if a.float32 else "float64"}
    truth = painting(ny, nx)
    t0 = time.perf_counter()
    clean = k1.clean_spectra(truth.reshape(-1, 6)).reshape(ny, nx, -1)
    res["data_s"] = time.perf_counter() - t0
    cube = (clean + k1.SIGMA * np.random.default_rng(3).standard_normal(clean.shape)).astype(np.float32)
    work = Path(a.dir) if a.dir else Path(tempfile.mkdtemp(prefix="km_cube_bench_"))
    work.mkdir(parents=True, exist_ok=True)
    store = work / "cube.zarr"
    shutil.rmtree(store, ignore_errors=True)
    ls.write_zarr_cube(cube, store, k1.WL, chunks=(a.region[0], a.region[1], -1))
    pixels = np.asarray(cube, dtype=float).reshape(-1, k1.WL.size)
    del cube, clean

    obj = k1.objective()
    t0 = time.perf_counter()
    fitting.fit_batch(obj, pixels[: a.chunk_size], chunk_size=a.chunk_size, progress=False)
    res["compile_s"] = time.perf_counter() - t0

    # fit_cube's own once-per-objective compile (the rank check at the start) on a small cube apart
    warm_store = work / "warm.zarr"
    shutil.rmtree(warm_store, ignore_errors=True)
    ls.write_zarr_cube(pixels[:a.region[1]].reshape(1, a.region[1], -1).astype(np.float32), warm_store, k1.WL,
                       chunks=(1, a.region[1], -1))
    t0 = time.perf_counter()
    fitting.fit_cube(obj, ls.read_zarr(warm_store), out=work / "warm_maps.zarr", chunk=tuple(a.region),
                     chunk_size=a.chunk_size, resume=False, progress=False).load()
    res["fit_cube_warmup_s"] = time.perf_counter() - t0

    res["uptime_batch"], res["load_batch_start"] = k1._uptime(), k1._load()
    t0 = time.perf_counter()
    ref = fitting.fit_batch(obj, pixels, chunk_size=a.chunk_size, progress=False)
    res["fit_batch_s"] = time.perf_counter() - t0
    res["load_batch_end"] = k1._load()

    out = work / "maps.zarr"
    shutil.rmtree(out, ignore_errors=True)
    res["uptime_cube"], res["load_cube_start"] = k1._uptime(), k1._load()
    t0 = time.perf_counter()
    maps = fitting.fit_cube(obj, ls.read_zarr(store), out=out, chunk=tuple(a.region), chunk_size=a.chunk_size,
                            resume=False, progress=False).load()
    res["fit_cube_s"] = time.perf_counter() - t0
    res["load_cube_end"] = k1._load()
    res["uptime_end"] = k1._uptime()

    names = json.loads(maps.attrs["parameter_variables"])
    diff = 0.0
    for k, name in enumerate(names):
        m = maps[name].values.ravel()
        diff = max(diff, float(np.max(np.abs(m - ref.x[:, k]) / np.abs(ref.x[:, k]))))
    z = (ref.x - truth.reshape(-1, 6)) / ref.stderr
    status, counts = np.unique(maps["status"].values, return_counts=True)
    res.update(pixels=ny * nx, ratio=res["fit_cube_s"] / res["fit_batch_s"],
               fit_batch_fits_per_s=ny * nx / res["fit_batch_s"], fit_cube_fits_per_s=ny * nx / res["fit_cube_s"],
               max_rel_diff_maps_vs_fit_batch=diff, map_names=names,
               status_counts={str(int(s)): int(c) for s, c in zip(status, counts)},
               fit_batch_converged=int(ref.converged.sum()),
               within_3sigma_of_truth=float(np.mean(np.abs(z) <= 3)), dir=str(work))
    if not a.dir:
        shutil.rmtree(work, ignore_errors=True)

    stem = "kubelka_munk_cube_quick" if a.quick else "kubelka_munk_cube"
    outdir = Path(a.out_dir)
    outdir.mkdir(parents=True, exist_ok=True)
    (outdir / f"{stem}.json").write_text(json.dumps(res, indent=1))
    md = "\n".join([
        "# K2: a varnished painting's cube into pigment maps — fit_cube (zarr) vs fit_batch (memory) (issue 28)",
        "",
        f"Run {res['when']} (git {res['git']}), {res['machine']}, Python {res['versions']['python']}, "
        f"jax {res['versions']['jax']} CPU, {res['precision']}. CPUs available: {res['cpus_used']} (not pinned). "
        f"`uptime` at the start: `{res['uptime']}`.",
        "",
        f"K1's pixel model (6 free parameters: 3 concentrations, varnish thickness, 2 α coefficients; SYNTHETIC), "
        f"a {ny} × {nx} × {k1.WL.size} cube written as float32 zarr chunked {a.region[0]} × {a.region[1]} × 401; "
        f"fit_cube regions {a.region[0]} × {a.region[1]}, {a.chunk_size} fits per compiled call on both paths; "
        f"compile done before both timings (fit_batch on one chunk: {res['compile_s']:.1f} s; fit_cube on a "
        f"1 × {a.region[1]} cube: {res['fit_cube_warmup_s']:.1f} s, its rank check at the start compiled once per "
        "objective); the in-memory read not timed.",
        "",
        "| cube | fit_batch (memory) | fit_cube (zarr on disk) | ratio (target ≤ 1.3) | maps vs fit_batch | "
        "load fit_batch | load fit_cube |",
        "| --- | --- | --- | --- | --- | --- | --- |",
        f"| {ny}×{nx}×{k1.WL.size} | {res['fit_batch_s']:.1f} s = {res['fit_batch_fits_per_s']:.0f} fits/s | "
        f"{res['fit_cube_s']:.1f} s = {res['fit_cube_fits_per_s']:.0f} fits/s | **{res['ratio']:.2f}** "
        f"({'met' if res['ratio'] <= TARGET_RATIO else 'missed'}) | {diff:.1e} relative | "
        f"{res['load_batch_start'][0]:.2f} → {res['load_batch_end'][0]:.2f} | "
        f"{res['load_cube_start'][0]:.2f} → {res['load_cube_end'][0]:.2f} |",
        "",
        f"fit_batch: {res['fit_batch_converged']}/{ny * nx} converged; fit_cube status counts {res['status_counts']} "
        f"(0 = trustworthy); fitted values within ±3σ of the truth: {100 * res['within_3sigma_of_truth']:.1f} %.",
    ]) + "\n"
    (outdir / f"{stem}.md").write_text(md)
    print(json.dumps(res, indent=1))
    print(md)
    return res


if __name__ == "__main__":
    main()
