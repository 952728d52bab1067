"""SCALING: time of the jitted public API against problem size.

    python -m benchmarks._sections SCALING --out scaling.json [--quick]

Four sweeps, each varying one size from a small base, float64, CPU:

* layers 1–200 — P1-like coherent stack (alternating n = 2.35 / 1.46, air | stack | glass),
  ``layerstack_jax.specular`` forward (s and p), 100 λ × 16 angles; compile time too, and
  value-and-gradient of mean(R) w.r.t. the thicknesses;
* wavelengths 10–10⁵ — the same 10-layer stack, 4 angles;
* angles 1–512 — the same 10-layer stack, 100 λ;
* batch 1–1000 — the P2 model (:func:`benchmarks.radiometric.build`, 401 λ, sphere SCE),
  ``jax.lax.map`` over vmapped blocks of ``min(batch, 8)`` samples.

Writes ``scaling.png`` (matplotlib object API, Agg canvas).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._sections import contention_note, figure, save, setup_jax, timed

FULL = {"layers": (1, 3, 10, 30, 100, 200), "wavelengths": (10, 100, 1000, 10_000, 100_000),
        "angles": (1, 8, 64, 512), "batch": (1, 10, 100, 1000)}
QUICK = {"layers": (1, 10, 50), "wavelengths": (10, 1000), "angles": (1, 16), "batch": (1, 10)}
BASE = {"layers": 10, "wavelengths": 100, "angles": 16}


def coherent_problem(layers: int, wavelengths: int, angles: int):
    """``(forward(d), value_and_grad(d), d)`` for the P1-like stack on the given grid."""
    import jax
    import jax.numpy as jnp

    import layerstack_jax as ls

    wl = jnp.linspace(400.0, 1000.0, wavelengths)
    th = jnp.deg2rad(jnp.linspace(0.0, 80.0, angles))
    d = jnp.asarray(np.random.default_rng(layers).uniform(50.0, 200.0, layers))

    def R(d):
        stack = ls.Stack(1.0, [ls.Layer(2.35 if i % 2 == 0 else 1.46, d[i]) for i in range(layers)], ls.Substrate(1.52))
        return ls.specular(stack, wl, angle_rad=th, both_sides=False).R_front

    return jax.jit(R), jax.jit(jax.value_and_grad(lambda d: jnp.mean(R(d)))), d


def _coherent_point(layers, wavelengths, angles, quick, grad=False):
    fwd, vg, d = coherent_problem(layers, wavelengths, angles)
    t, _ = timed(fwd, d, quick=quick, max_time=10.0)
    row = {"layers": layers, "wavelengths": wavelengths, "angles": angles, "points": 2 * wavelengths * angles, **t}
    if grad:
        tg, _ = timed(vg, d, quick=quick, max_time=10.0)
        row["grad_min_s"], row["grad_compile_s"] = tg["min_s"], tg["compile_s"]
        row["grad_foreign_cpu_frac"] = tg["foreign_cpu_frac"]
    return row


def run(quick: bool = False, out_dir=None) -> dict:
    jax = setup_jax(True)
    import jax.numpy as jnp

    import layerstack_jax as ls

    from .radiometric import build

    grid = QUICK if quick else FULL
    res: dict = {"grid": grid, "base": BASE}
    res["layers"] = [_coherent_point(L, BASE["wavelengths"], BASE["angles"], quick, grad=True) for L in grid["layers"]]
    res["wavelengths"] = [_coherent_point(BASE["layers"], W, 4, quick) for W in grid["wavelengths"]]
    res["angles"] = [_coherent_point(BASE["layers"], BASE["wavelengths"], A, quick) for A in grid["angles"]]
    model, *_ = build(ls.DEFAULT_NODES, jnp.float64)
    rows = []
    for b in grid["batch"]:
        H = jnp.asarray(np.random.default_rng(b).uniform(2e3, 3e4, (b, 3)))
        fn = jax.jit(lambda H, blk=min(b, 8): jax.lax.map(model, H, batch_size=blk))
        t, _ = timed(fn, H, quick=quick, max_time=10.0)
        rows.append({"batch": b, "block": min(b, 8), "spectra_per_s": b / t["min_s"], **t})
    res["batch"] = rows
    res["contention"] = contention_note(
        [(f"{k}={r[k]}", r["foreign_cpu_frac"]) for k in ("layers", "wavelengths", "angles", "batch") for r in res[k]])
    if out_dir is not None:
        fig = figure(10.0, 7.0)
        axs = fig.subplots(2, 2)
        L = res["layers"]
        ax = axs[0, 0]
        ax.plot([r["layers"] for r in L], [r["min_s"] for r in L], "o-", label="forward")
        ax.plot([r["layers"] for r in L], [r["grad_min_s"] for r in L], "s-", label="value + grad")
        ax.plot([r["layers"] for r in L], [r["compile_s"] for r in L], "^--", label="compile (forward)")
        ax.set(xscale="log", yscale="log", xlabel="coherent layers", ylabel="s",
               title=f"{BASE['wavelengths']} λ × {BASE['angles']} angles × 2 pol")
        ax.legend(fontsize=8)
        for ax, key, label, fixed in ((axs[0, 1], "wavelengths", "wavelengths", "10 layers × 4 angles × 2 pol"),
                                      (axs[1, 0], "angles", "angles", f"10 layers × {BASE['wavelengths']} λ × 2 pol")):
            rr = res[key]
            ax.plot([r[key] for r in rr], [r["min_s"] for r in rr], "o-", label="forward")
            ax.plot([r[key] for r in rr], [r["compile_s"] for r in rr], "^--", label="compile")
            ax.set(xscale="log", yscale="log", xlabel=label, ylabel="s", title=fixed)
            ax.legend(fontsize=8)
        ax = axs[1, 1]
        B = res["batch"]
        ax.plot([r["batch"] for r in B], [r["spectra_per_s"] for r in B], "o-")
        ax.axhline(1000, color="r", lw=0.8, label="P2 target 1000 /s")
        ax.set(xscale="log", xlabel="batch (samples)", ylabel="spectra / s", title="P2 sphere SCE, 401 λ, lax.map blocks ≤ 8")
        ax.legend(fontsize=8)
        fig.suptitle("layerstack_jax scaling (float64, CPU, min of repeats)")
        res["plot"] = save(fig, Path(out_dir) / "scaling.png")
    return res


def markdown(r: dict) -> list[str]:
    lines = ["Minimum time per call of the jitted public API (`specular` for the coherent sweeps, `reflectance` "
             "with `Sphere` for the batch sweep); compile = trace + lower + XLA compile.", "",
             "| sweep | size | points | forward (ms) | µs / point | compile (s) | value+grad (ms) | foreign CPU |",
             "|---|---|---|---|---|---|---|---|"]
    for key in ("layers", "wavelengths", "angles"):
        for x in r[key]:
            g = f"{x['grad_min_s'] * 1e3:.3g}" if "grad_min_s" in x else "—"
            lines.append(f"| {key} | {x[key]} | {x['points']} | {x['min_s'] * 1e3:.3g} | {x['min_s'] / x['points'] * 1e6:.3g} | "
                         f"{x['compile_s']:.2f} | {g} | {100 * (x['foreign_cpu_frac'] or 0):.0f}% |")
    for x in r["batch"]:
        lines.append(f"| batch (P2) | {x['batch']} | {x['batch']} spectra | {x['min_s'] * 1e3:.3g} | "
                     f"{x['spectra_per_s']:.0f} spectra/s | {x['compile_s']:.2f} | — | {100 * (x['foreign_cpu_frac'] or 0):.0f}% |")
    if r.get("plot"):
        lines += ["", f"![scaling]({r['plot']})"]
    if r.get("contention"):
        lines.append(f"**{r['contention']}**")
    return lines
