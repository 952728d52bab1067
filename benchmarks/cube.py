"""fit_cube on a zarr cube on disk vs fit_batch on the same pixels in memory, standalone:

    python -m benchmarks.cube [--size 100 100] [--chunk 25 25] [--client processes]
    python -m benchmarks.cube --workers 1 2 --memory-limit 1GB     # scaling over Dask worker processes

The pixel model is benchmark F1's (``benchmarks/fitting_cases.py``): 3 incoherent layers over a
Lambertian background, sphere 8° SCE, 401 λ; per pixel the top layer's thickness and 3 B-spline
coefficients of the ink's α(λ) are fitted (4 parameters, Levenberg–Marquardt). The cube
(``size`` pixels × 401 λ) is made by the forward model (:func:`layerstack_jax._instruments.batched.predict`)
with Gaussian noise σ = 0.002, plus 1 % pixels with a NaN band, and written to a zarr store (float32 on disk,
as instruments deliver). Then, each compiled once beforehand on one solver chunk so that compile
time is not counted:

* ``fit_batch``: the valid pixels read into memory, one call;
* ``fit_cube``: the same job out of core, region by region, maps written to zarr.

Reported: both wall times and their ratio (target <= 1.3), pixels/s, the peak RSS of the
process, agreement of the maps with fit_batch, and the machine's load. With ``--workers N ...``
the same ``fit_cube`` job also runs on a :class:`distributed.LocalCluster` of N single-threaded
worker processes, each limited to ``--memory-limit`` (a row per N: pixels/s, parallel efficiency
against the 1-worker row, the maps against fit_batch). Writes ``benchmarks/results/cube.json``
and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "results"


def _peak_rss() -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--size", type=int, nargs=2, default=[100, 100])
    p.add_argument("--chunk", nargs="+", default=["25", "25"],
                   help="region rows columns (also the zarr store's chunks), or 'auto': fit_cube sizes the regions "
                        "from the memory available (the store then chunked 25 x 25)")
    p.add_argument("--chunk-size", type=int, default=100, help="fits per compiled fit_batch call")
    p.add_argument("--client", default=None, help="None (this process), 'processes', or a scheduler address")
    p.add_argument("--dir", default=None, help="where to write the cube and the maps (default: a temporary dir)")
    p.add_argument("--workers", type=int, nargs="*", default=[], help="also run on LocalClusters of these many workers")
    p.add_argument("--memory-limit", default="1GB", help="memory limit of each worker process (Dask's spelling)")
    a = p.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import fitting
    import layerstack_jax as ls
    from fitting._cube import fit_cube
    from layerstack_jax._instruments.batched import predict
    from layerstack_jax._files.cubes import read_zarr, write_zarr_cube

    from .fitting_cases import SIGMA, WL, _f1_stack

    ny, nx = a.size
    region = "auto" if a.chunk == ["auto"] else tuple(int(v) for v in a.chunk)
    if region != "auto" and len(region) != 2:
        raise SystemExit("--chunk: two integers (rows columns) or 'auto'")
    a.region, a.chunk = region, ([25, 25] if region == "auto" else list(region))  # fit_cube's regions, the store's chunks
    rng = np.random.default_rng(1)
    B = fitting.bspline_basis(WL, 3)
    h = rng.uniform(15_000.0, 30_000.0, (ny, nx))
    c = rng.uniform(0.5e-5, 4e-5, (ny, nx, 3))
    geometry = ls.Sphere(8.0)
    t0 = time.perf_counter()
    clean = predict(_f1_stack(h[..., None], c @ B.T), WL, geometry, progress=False)
    t_data = time.perf_counter() - t0
    cube = (clean + SIGMA * rng.standard_normal(clean.shape)).astype(np.float32)
    bad = rng.random((ny, nx)) < 0.01
    cube[bad, 17] = np.nan
    work = Path(a.dir) if a.dir else Path(tempfile.mkdtemp(prefix="cube_bench_"))
    work.mkdir(parents=True, exist_ok=True)
    store = work / "cube.zarr"
    write_zarr_cube(cube, store, WL, chunks=(a.chunk[0], a.chunk[1], -1))
    del cube, clean
    lazy = read_zarr(store)
    obj = fitting.Objective(_f1_stack(20_000.0, B @ np.full(3, 1e-5)), WL,
                            fitting.Dataset(geometry, np.full(WL.size, 0.3), sigma=SIGMA),
                            [fitting.thickness("top"), fitting.alpha("ink", basis=B, value=np.full(3, 1e-5))])
    # compile once on one solver chunk (both paths then reuse the objective's compiled solver)
    warm = np.asarray(lazy.isel(y=0).values[: a.chunk_size], dtype=float)
    warm = warm[np.isfinite(warm).all(-1)]
    t0 = time.perf_counter()
    fitting.fit_batch(obj, np.resize(warm, (a.chunk_size, WL.size)), chunk_size=a.chunk_size)
    compile_s = time.perf_counter() - t0

    load0 = os.getloadavg()
    t0 = time.perf_counter()
    pixels = np.asarray(lazy.values, dtype=float).reshape(-1, WL.size)
    ok = np.isfinite(pixels).all(-1)
    ref = fitting.fit_batch(obj, pixels[ok], chunk_size=a.chunk_size)
    t_batch = time.perf_counter() - t0
    del pixels

    out = work / "maps.zarr"
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    maps = fit_cube(obj, lazy, out=out, chunk=a.region, chunk_size=a.chunk_size, client=a.client,
                    resume=False, progress=False).load()
    t_cube = time.perf_counter() - t0
    load1 = os.getloadavg()
    status = maps["status"].values.ravel()
    names = json.loads(maps.attrs["parameter_variables"])
    agree = _agreement(maps, names, ok, ref)
    res = {"size": [ny, nx], "wavelengths": int(WL.size), "chunk": a.chunk, "regions": json.loads(maps.attrs["chunk"]),
           "region_sizing": json.loads(maps.attrs.get("chunk_sizing", '"given"')), "chunk_size": a.chunk_size,
           "client": a.client, "pixels_fitted": int(ok.sum()), "pixels_nan": int((~ok).sum()),
           "nan_band_pixels_fitted": int(np.isin(status[~ok], fitting.FIT_MADE).sum()), "data_s": t_data,
           "compile_s": compile_s,
           "fit_batch_s": t_batch, "fit_cube_s": t_cube, "ratio": t_cube / t_batch,
           "fit_cube_pixels_per_s": ny * nx / t_cube, "max_rel_diff_maps_vs_fit_batch": agree,
           "converged_frac": float(ref.converged.mean()), "peak_rss_bytes": _peak_rss(),
           "loadavg_before": load0, "loadavg_after": load1, "cpu_count": os.cpu_count(), "dir": str(work)}
    res["workers"] = [_on_cluster(n, a.memory_limit, obj, lazy, work, a, ref, ny * nx, ok) for n in a.workers]
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "cube.json").write_text(json.dumps(res, indent=2))
    md = ("| cube | pixels fitted | fit_batch (memory) s | fit_cube (zarr) s | ratio | px/s | maps vs fit_batch | "
          "peak RSS MB | load avg |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n"
          f"| {ny}×{nx}×{WL.size} | {res['pixels_fitted']} | {t_batch:.1f} | {t_cube:.1f} | {res['ratio']:.2f} | "
          f"{res['fit_cube_pixels_per_s']:.1f} | {agree:.1e} | {res['peak_rss_bytes'] / 2**20:.0f} | "
          f"{load0[0]:.1f}–{load1[0]:.1f} |\n")
    md += (f"\nfit_cube regions: {res['regions'][0]} × {res['regions'][1]} pixels ("
           + ("given" if a.region != "auto" else f"chunk='auto': {res['region_sizing'].get('budget_source', '')}")
           + f"), {a.chunk_size} fits per solver call.\n")
    if res["workers"]:
        one = next((w for w in res["workers"] if w["n_workers"] == 1), None)
        md += ("\nThe same fit_cube on a LocalCluster of single-threaded worker processes "
               f"(memory limit {a.memory_limit} each; compile inside each worker included):\n\n"
               "| workers | fit_cube s | px/s | parallel efficiency vs 1 worker | maps vs fit_batch | "
               "worker peak RSS MB | load avg |\n| --- | --- | --- | --- | --- | --- | --- |\n")
        for w in res["workers"]:
            eff = "—" if one is None else f"{one['fit_cube_s'] / (w['n_workers'] * w['fit_cube_s']):.2f}"
            md += (f"| {w['n_workers']} | {w['fit_cube_s']:.1f} | {w['pixels_per_s']:.1f} | {eff} | "
                   f"{w['max_rel_diff_maps_vs_fit_batch']:.1e} | {w['worker_peak_rss_bytes'] / 2**20:.0f} | "
                   f"{w['loadavg_before'][0]:.1f}–{w['loadavg_after'][0]:.1f} |\n")
    (RESULTS / "cube.md").write_text(md)
    print(json.dumps(res, indent=2))
    print(md)
    if not a.dir:
        shutil.rmtree(work, ignore_errors=True)
    return res


def _agreement(maps, names, ok, ref) -> float:
    """Largest relative difference of the maps from ``ref`` (fit_batch of the pixels ``ok``, those
    without a NaN band) over the pixels whose fit was made (a pixel with a NaN band is fitted from
    its other bands: not in ``ref``)."""
    import numpy as np

    import fitting

    made = np.isin(maps["status"].values.ravel(), fitting.FIT_MADE)
    x = np.stack([maps[n].values.ravel()[made & ok] for n in names], axis=1)
    r = ref.x[made[ok]]
    return float(np.max(np.abs(x - r) / np.maximum(np.abs(r), 1e-300)))


def _on_cluster(n_workers: int, memory_limit: str, obj, lazy, work: Path, a, ref, pixels: int, ok) -> dict:
    """``fit_cube`` of the same job on a LocalCluster of ``n_workers`` single-threaded processes."""
    import json as _json

    import numpy as np
    from distributed import Client, LocalCluster

    from fitting._cube import fit_cube

    out = work / f"maps_{n_workers}w.zarr"
    shutil.rmtree(out, ignore_errors=True)
    with LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, memory_limit=memory_limit,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        load0 = os.getloadavg()
        t0 = time.perf_counter()
        maps = fit_cube(obj, lazy, out=out, chunk=a.region, chunk_size=a.chunk_size, client=client,
                        resume=False, progress=False).load()
        seconds = time.perf_counter() - t0
        load1 = os.getloadavg()
        rss = max(client.run(_peak_rss).values())
    names = _json.loads(maps.attrs["parameter_variables"])
    agree = _agreement(maps, names, ok, ref)
    return {"n_workers": n_workers, "memory_limit": memory_limit, "fit_cube_s": seconds, "pixels_per_s": pixels / seconds,
            "max_rel_diff_maps_vs_fit_batch": agree, "worker_peak_rss_bytes": rss, "loadavg_before": load0,
            "loadavg_after": load1}


if __name__ == "__main__":
    main()
