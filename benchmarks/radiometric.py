"""P2: 3 incoherent layers over a Lambertian background, 401 wavelengths, sphere geometry.

    python -m benchmarks.radiometric [--quick] [--batch 10000]

Measures, in one process (float64 unless --float32), through ``benchmarks._sections.timed``:
  * compile time of the batched forward (ahead of time: trace + lower + XLA compile),
  * spectra per second for a batch of samples (each with its own 3 thicknesses),
    evaluated with ``lax.map`` over small vmapped blocks (bounded memory),
  * the cost of the gradient of a least-squares loss w.r.t. the 3 thicknesses, forward mode
    (``jax.jacfwd``) and reverse mode (``jax.value_and_grad``), and of the full 401 x 3
    Jacobian of the spectrum (``jax.jacfwd``, what Levenberg–Marquardt uses),
  * quadrature error of the sphere reflectance against an adaptive scipy reference
    (tests/reference.py) for several node counts.
Standalone it writes benchmarks/results/p2.md and p2.json; ``python -m benchmarks`` runs it as
its P2 section (``run_section``) and puts it in latest.md / latest.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).parent / "results"


def _setup(float32: bool):
    import jax

    jax.config.update("jax_enable_x64", not float32)
    return jax


def build(nodes: int, dtype):
    import jax.numpy as jnp

    import layerstack_jax as ls

    wl = jnp.linspace(380.0, 780.0, 401, dtype=dtype)
    alpha = [jnp.asarray(2e-5 * (1.0 + np.sin(np.asarray(wl) / 50.0 + i)), dtype) for i in range(3)]
    rho = jnp.asarray(0.3 + 0.5 * np.exp(-(((np.asarray(wl) - 550.0) / 80.0) ** 2)), dtype)
    indices = (1.5, 1.6, 1.45)

    def model(h):
        layers = [ls.Layer(n, hh, coherent=False, alpha=a) for n, hh, a in zip(indices, h, alpha)]
        stack = ls.Stack(1.0, layers, ls.LambertianBackground(1.52, rho))
        return ls.reflectance(stack, wl, ls.Sphere(8.0, "excluded"), nodes=nodes)

    return model, wl, alpha, rho, indices


def run(batch: int, block: int, nodes: int, float32: bool, accuracy: bool, quick: bool = False) -> dict:
    jax = _setup(float32)
    import jax.numpy as jnp

    from ._sections import contention_note, timed

    dtype = jnp.float32 if float32 else jnp.float64
    model, wl, alpha, rho, indices = build(nodes, dtype)
    rng = np.random.default_rng(0)
    H = jnp.asarray(rng.uniform(2e3, 3e4, (batch, 3)), dtype)
    data = model(H[0] * 1.05)

    forward = jax.jit(lambda H: jax.lax.map(model, H, batch_size=block))
    loss = lambda h: jnp.sum((model(h) - data) ** 2)  # noqa: E731
    grad_fwd = jax.jit(lambda H: jax.lax.map(jax.jacfwd(loss), H, batch_size=block))
    grad_rev = jax.jit(lambda H: jax.lax.map(jax.value_and_grad(loss), H, batch_size=block))
    jac = jax.jit(lambda H: jax.lax.map(jax.jacfwd(model), H, batch_size=block))

    out = {"case": "P2", "batch": batch, "block": block, "nodes_per_segment": nodes,
           "dtype": "float32" if float32 else "float64", "wavelengths": int(wl.shape[0])}
    t, _ = timed(forward, H, quick=quick)
    out["forward"] = dict(t, spectra_per_s=batch / t["min_s"])
    for name, fn in (("grad_jacfwd", grad_fwd), ("value_and_grad", grad_rev), ("jacobian", jac)):
        t, _ = timed(fn, H, quick=quick)
        out[name] = dict(t, spectra_per_s=batch / t["min_s"], ratio_to_forward=t["min_s"] / out["forward"]["min_s"])
    out["contention"] = contention_note([(f"P2/{k}", out[k]["foreign_cpu_frac"])
                                         for k in ("forward", "grad_jacfwd", "value_and_grad", "jacobian")])

    if accuracy and not float32:
        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
        import reference as ref  # independent scipy/closed-form references

        i = 200  # one wavelength, 580 nm
        h = np.asarray(H[0])
        ah = [float(alpha[j][i]) * h[j] for j in range(3)]
        n_list = [1.0, *indices, 1.52]
        T = ref.beer_stack_R_T("u", n_list, ah, np.deg2rad(8.0))[1]
        r_b, t_b = ref.diffuse_beer_stack(n_list, ah, side="back")
        rg = float(rho[i])
        exact = t_b * rg * T / (1 - rg * r_b)
        rows = []
        for q in (8, 12, 16, 20, 24, 32, 48):
            m, *_ = build(q, dtype)
            rows.append({"nodes_per_segment": q, "abs_error": abs(float(m(H[0])[i]) - exact)})
        out["accuracy_vs_nodes"] = rows
    return out


BATCH_FULL = 1000
BLOCK = 4


def run_section(quick: bool = False, out_dir=None) -> dict:
    """The P2 section of ``python -m benchmarks`` (float64, library default nodes)."""
    import layerstack_jax as ls

    return run(200 if quick else BATCH_FULL, BLOCK, ls.DEFAULT_NODES, False, accuracy=not quick, quick=quick)


def markdown(r: dict) -> list[str]:
    f = r["forward"]
    lines = [f"3 incoherent absorbing layers (n = 1.5, 1.6, 1.45) over a Lambertian background (n_g = 1.52), "
             f"sphere 8° SCE, {r['wavelengths']} λ, batch {r['batch']} (each sample its own 3 thicknesses), "
             f"`jax.lax.map` over vmapped blocks of {r['block']}, {r['dtype']}, {r['nodes_per_segment']} nodes/segment.", "",
             "| quantity | min (s) | median (s) | spectra/s | / forward | compile (s) | CPU s / call | foreign CPU |",
             "|---|---|---|---|---|---|---|---|"]
    for name, key in (("forward", "forward"), ("gradient of LSQ loss, jacfwd (3 thicknesses)", "grad_jacfwd"),
                      ("value + gradient, reverse mode", "value_and_grad"), ("Jacobian 401 × 3, jacfwd", "jacobian")):
        t = r[key]
        lines.append(f"| {name} | {t['min_s']:.3g} | {t['median_s']:.3g} | {t['spectra_per_s']:.0f} | "
                     f"{t.get('ratio_to_forward', 1.0):.2f} | {t['compile_s']:.2f} | {t['cpu_s_per_call']:.3g} | "
                     f"{100 * (t['foreign_cpu_frac'] or 0):.0f}% |")
    if "accuracy_vs_nodes" in r:
        lines += ["", "| nodes/segment | abs error of sphere R at 580 nm vs scipy quad (tests/reference.py) |", "| --- | --- |"]
        lines += [f"| {x['nodes_per_segment']} | {x['abs_error']:.1e} |" for x in r["accuracy_vs_nodes"]]
    if r.get("contention"):
        lines.append(f"**{r['contention']}**")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.radiometric")
    p.add_argument("--quick", action="store_true", help="batch 200, one repeat, no accuracy sweep")
    p.add_argument("--batch", type=int, default=BATCH_FULL)
    p.add_argument("--block", type=int, default=BLOCK, help="samples per vmapped block inside lax.map")
    p.add_argument("--nodes", type=int, default=None, help="nodes per segment (default: library default)")
    p.add_argument("--float32", action="store_true")
    a = p.parse_args(argv)
    import layerstack_jax as ls

    nodes = a.nodes or ls.DEFAULT_NODES
    batch = 200 if a.quick else a.batch
    res = run(batch, a.block, nodes, a.float32, accuracy=not a.quick, quick=a.quick)
    import jax

    res["machine"] = {"cpu_count": os.cpu_count(), "python": platform.python_version(), "jax": jax.__version__,
                      "backend": jax.default_backend(), "load_1min": os.getloadavg()[0]}
    RESULTS.mkdir(exist_ok=True)
    tag = "p2_quick" if a.quick else ("p2_float32" if a.float32 else "p2")
    (RESULTS / f"{tag}.json").write_text(json.dumps(res, indent=2))
    lines = [f"# P2 radiometric ({res['dtype']}, {nodes} nodes/segment, batch {batch}, blocks of {a.block})", "",
             *markdown(res), "", f"machine: {res['machine']}"]
    (RESULTS / f"{tag}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
