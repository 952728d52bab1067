"""MEMORY: peak resident memory predicting 100,000 P2-like spectra in chunks.

    python -m benchmarks._sections MEMORY --out mem.json [--quick]

The P2 stack (3 incoherent absorbing layers over a Lambertian background, 401 λ, sphere SCE;
:func:`benchmarks.radiometric.build`), one set of three thicknesses per sample.  The batch is
chunked with ``jax.lax.map(model, H, batch_size=chunk)`` inside one ``jax.jit``: XLA vmaps the
model over blocks of ``chunk`` samples and loops over the blocks (a ``scan``), so the
intermediates scale with ``chunk``, not with the batch; the output ``(N, 401)`` float64 (321 MB
for N = 100,000) is returned as one array and is part of the peak.

The headline figure is N = 100,000 at chunk 10; the chunk sweep (10, 100, 1000, 10000) uses
N = 2,000 (to keep the run short on a shared 2-core machine: the intermediates, hence the peak,
depend on the chunk; N adds only the output array).  Each run is its own process (``python -m benchmarks.memory --child ...``) so its
``VmHWM`` is its own.  The parent polls the child's resident memory and kills it above
``RSS_CAP`` (a chunk that big is reported as "over cap", never allowed to swap the machine).
Reported per chunk: peak RSS of the whole process (imports and the XLA runtime included),
resident memory after compilation (the baseline), wall time of one pass over N spectra after
compilation, spectra/s.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

from . import _harness
from ._sections import contention_note, figure, save

N_FULL = 100_000  # the headline run, at chunk CHUNK_FULL
CHUNK_FULL = 10
N_SWEEP = 2_000  # the chunk-size sweep (peak memory is set by the chunk, not by N, beyond the output)
CHUNKS_SWEEP = (10, 100, 1000, 10_000)
QUICK = {"n": 1_000, "chunk": 10, "n_sweep": 200, "chunks": (10, 100)}
RSS_CAP = 6 * 2**30  # kill a child above this resident size (shared 2-core / 23 GiB machine)
TARGET = 2 * 2**30


def _rss_bytes(pid) -> int | None:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def child(n: int, chunk: int) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    import layerstack_jax as ls

    from .radiometric import build

    model, *_ = build(ls.DEFAULT_NODES, jnp.float64)
    H = jnp.asarray(np.random.default_rng(0).uniform(2e3, 3e4, (n, 3)))
    fn = jax.jit(lambda H: jax.lax.map(model, H, batch_size=chunk))
    t0 = time.perf_counter()
    compiled = fn.lower(H).compile()
    compile_s = time.perf_counter() - t0
    rss_before = _rss_bytes("self")
    with _harness.CpuContention() as c:
        t0 = time.perf_counter()
        out = jax.block_until_ready(compiled(H))
        wall = time.perf_counter() - t0
    finite = bool(jnp.all(jnp.isfinite(out)))
    return {"n": n, "chunk": chunk, "compile_s": compile_s, "wall_s": wall, "spectra_per_s": n / wall,
            "rss_after_compile_bytes": rss_before, "peak_rss_bytes": _harness.peak_rss_bytes(),
            "output_bytes": int(out.size * out.dtype.itemsize), "finite": finite, "foreign_cpu_frac": c.foreign_frac}


def _run_child(n: int, chunk: int, timeout: float) -> dict:
    import subprocess

    with tempfile.TemporaryDirectory(prefix="layerstack-mem-") as td:
        out = Path(td) / "r.json"
        root = Path(__file__).resolve().parent.parent
        proc = subprocess.Popen([sys.executable, "-m", "benchmarks.memory", "--child", "--n", str(n),
                                 "--chunk", str(chunk), "--out", str(out)], cwd=root, env=dict(os.environ),
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        t0, peak, killed = time.perf_counter(), 0, None
        while proc.poll() is None:
            rss = _rss_bytes(proc.pid) or 0
            peak = max(peak, rss)
            if rss > RSS_CAP:
                proc.kill()
                killed = f"killed: resident memory passed the {RSS_CAP / 2**30:.0f} GiB cap"
            elif time.perf_counter() - t0 > timeout:
                proc.kill()
                killed = f"killed: timed out after {timeout:.0f} s"
            time.sleep(0.05)
        err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
        if killed or not out.exists():
            return {"n": n, "chunk": chunk, "status": killed or f"failed: {err.strip().splitlines()[-1:] or ''}",
                    "peak_rss_polled_bytes": peak}
        r = json.loads(out.read_text())
        r["status"] = "ok" if r["finite"] else "failed: non-finite output"
        return r


def run(quick: bool = False, out_dir=None) -> dict:
    n, chunk = (QUICK["n"], QUICK["chunk"]) if quick else (N_FULL, CHUNK_FULL)
    n_sweep, chunks = (QUICK["n_sweep"], QUICK["chunks"]) if quick else (N_SWEEP, CHUNKS_SWEEP)
    timeout = 300 if quick else 900
    headline = _run_child(n, chunk, 300 if quick else 1200)
    rows = [_run_child(n_sweep, c, timeout) for c in chunks]
    res = {"n": n, "chunk": chunk, "headline": headline, "n_sweep": n_sweep, "chunks": list(chunks), "rows": rows,
           "method": "jax.lax.map(model, H, batch_size=chunk) in one jit", "rss_cap_bytes": RSS_CAP, "target_bytes": TARGET}
    res["bounded"] = headline["status"] == "ok" and headline["peak_rss_bytes"] < TARGET
    ok = [r for r in rows if r["status"] == "ok"]
    res["contention"] = contention_note([(f"MEMORY/{r['n']} spectra, chunk {r['chunk']}", r.get("foreign_cpu_frac"))
                                         for r in [headline, *ok] if r["status"] == "ok"])
    if out_dir is not None and ok:
        fig = figure(9.0, 3.6)
        ax1, ax2 = fig.subplots(1, 2)
        x = [r["chunk"] for r in ok]
        ax1.plot(x, [r["peak_rss_bytes"] / 2**20 for r in ok], "o-", label="peak RSS (process)")
        ax1.plot(x, [r["rss_after_compile_bytes"] / 2**20 for r in ok], "s--", label="RSS after compile")
        ax1.axhline(TARGET / 2**20, color="r", lw=0.8, label="2 GiB target")
        over = [r["chunk"] for r in rows if r["status"] != "ok"]
        for c in over:
            ax1.axvline(c, color="gray", ls=":", lw=1)
        ax1.set(xscale="log", yscale="log", xlabel="chunk (samples per vmapped block)", ylabel="MiB",
                title=f"{n_sweep:,} P2 spectra (401 λ), float64" + (f"; chunk {over} over the cap" if over else ""))
        ax1.legend(fontsize=8)
        ax2.plot(x, [r["spectra_per_s"] for r in ok], "o-")
        ax2.set(xscale="log", xlabel="chunk", ylabel="spectra / s", title="throughput (one pass, after compile)")
        res["plot"] = save(fig, Path(out_dir) / "memory_chunks.png")
    return res


def _md_row(x: dict) -> str:
    if x["status"] == "ok":
        return (f"| {x['n']:,} | {x['chunk']} | ok | {x['peak_rss_bytes'] / 2**20:.0f} | {x['rss_after_compile_bytes'] / 2**20:.0f} | "
                f"{x['wall_s']:.1f} | {x['spectra_per_s']:.0f} | {x['compile_s']:.2f} | {100 * (x['foreign_cpu_frac'] or 0):.0f}% |")
    return (f"| {x['n']:,} | {x['chunk']} | {x['status']} | ≥ {x.get('peak_rss_polled_bytes', 0) / 2**20:.0f} (polled) "
            "| — | — | — | — | — |")


def markdown(r: dict) -> list[str]:
    h = r["headline"]
    lines = [f"P2-like spectra (3 incoherent layers over a Lambertian background, sphere SCE, 401 λ, float64), chunked with "
             f"`{r['method']}` (XLA loops over blocks of `chunk` samples, each block vmapped). One process per row; "
             f"peak RSS is the process's VmHWM (imports, XLA runtime and the output array included). "
             f"Headline: {r['n']:,} spectra at chunk {r['chunk']}; the chunk sweep uses {r['n_sweep']:,} spectra "
             f"(beyond the output array, {r['n_sweep'] * 401 * 8 / 2**20:.0f} MiB, peak memory is set by the chunk, not by N).", "",
             "| spectra | chunk | status | peak RSS (MiB) | RSS after compile (MiB) | one pass (s) | spectra/s | compile (s) | foreign CPU |",
             "|---|---|---|---|---|---|---|---|---|", _md_row(h)]
    lines += [_md_row(x) for x in r["rows"]]
    lines.append("")
    if h["status"] == "ok":
        lines.append(f"Bounded memory (< 2 GiB) for {r['n']:,} spectra at chunk {r['chunk']}: "
                     f"{'met' if r['bounded'] else 'NOT met'} ({h['peak_rss_bytes'] / 2**20:.0f} MiB peak).")
    big = [x for x in r["rows"] if x["status"] != "ok" or x["peak_rss_bytes"] >= r["target_bytes"]]
    if big:
        lines.append("Chunks over 2 GiB: " + ", ".join(str(x["chunk"]) for x in big)
                     + " — intermediates grow as chunk × quadrature nodes × 2 pol × 401 λ × 8 B; keep chunks small on CPU.")
    if r.get("plot"):
        lines.append(f"![memory vs chunk]({r['plot']})")
    if r.get("contention"):
        lines.append(f"**{r['contention']}**")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.memory")
    ap.add_argument("--child", action="store_true")
    ap.add_argument("--n", type=int, default=N_FULL)
    ap.add_argument("--chunk", type=int, default=1000)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    if a.child:
        _harness.write_json(child(a.n, a.chunk), a.out)
    else:
        _harness.write_json(run(quick=a.n < N_FULL, out_dir=_harness.RESULTS_DIR), a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
