"""P2: 3 incoherent layers over a Lambertian background, 401 wavelengths, sphere geometry.

    python -m benchmarks.radiometric [--quick] [--batch 10000]

Measures, in one process (float64 unless --float32):
  * compile time of the batched forward (first call minus steady state),
  * spectra per second for a batch of samples (each with its own 3 thicknesses),
    evaluated with ``lax.map`` over small vmapped blocks (bounded memory),
  * the cost of the gradient of a least-squares loss w.r.t. the 3 thicknesses, forward mode
    (``jax.jacfwd``, what Levenberg–Marquardt uses) and reverse mode (``jax.grad``),
  * quadrature error of the sphere reflectance against an adaptive scipy reference
    (tests/reference.py) for several node counts.
Writes benchmarks/results/p2.md and p2.json.
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


def timed(fn, *args, repeats=3):
    import jax

    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        runs.append(time.perf_counter() - t0)
    return first, min(runs), float(np.median(runs))


def run(batch: int, block: int, nodes: int, float32: bool, accuracy: bool) -> dict:
    jax = _setup(float32)
    import jax.numpy as jnp

    dtype = jnp.float32 if float32 else jnp.float64
    model, wl, alpha, rho, indices = build(nodes, dtype)
    rng = np.random.default_rng(0)
    H = jnp.asarray(rng.uniform(2e3, 3e4, (batch, 3)), dtype)
    data = model(H[0] * 1.05)

    forward = jax.jit(lambda H: jax.lax.map(model, H, batch_size=block))
    loss = lambda h: jnp.sum((model(h) - data) ** 2)  # noqa: E731
    grad_fwd = jax.jit(lambda H: jax.lax.map(jax.jacfwd(loss), H, batch_size=block))
    grad_rev = jax.jit(lambda H: jax.lax.map(jax.grad(loss), H, batch_size=block))

    out = {"batch": batch, "block": block, "nodes_per_segment": nodes, "dtype": "float32" if float32 else "float64"}
    first, best, med = timed(forward, H)
    out["forward"] = {"first_call_s": first, "min_s": best, "median_s": med, "compile_s": first - med,
                      "spectra_per_s": batch / best}
    for name, fn in (("grad_jacfwd", grad_fwd), ("grad_reverse", grad_rev)):
        first, best, med = timed(fn, H)
        out[name] = {"first_call_s": first, "min_s": best, "median_s": med, "ratio_to_forward": best / out["forward"]["min_s"]}

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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.radiometric")
    p.add_argument("--quick", action="store_true", help="batch 200, no accuracy sweep")
    p.add_argument("--batch", type=int, default=10_000)
    p.add_argument("--block", type=int, default=4, help="samples per vmapped block inside lax.map")
    p.add_argument("--nodes", type=int, default=None, help="nodes per segment (default: library default)")
    p.add_argument("--float32", action="store_true")
    a = p.parse_args(argv)
    import layerstack_jax as ls

    nodes = a.nodes or ls.DEFAULT_NODES
    batch = 200 if a.quick else a.batch
    res = run(batch, a.block, nodes, a.float32, accuracy=not a.quick)
    import jax

    res["machine"] = {"cpu_count": os.cpu_count(), "python": platform.python_version(), "jax": jax.__version__,
                      "backend": jax.default_backend(), "load_1min": os.getloadavg()[0]}
    RESULTS.mkdir(exist_ok=True)
    tag = "p2_quick" if a.quick else ("p2_float32" if a.float32 else "p2")
    (RESULTS / f"{tag}.json").write_text(json.dumps(res, indent=2))
    f = res["forward"]
    lines = [
        f"# P2 radiometric ({res['dtype']}, {nodes} nodes/segment, batch {batch}, blocks of {a.block})",
        "",
        "| quantity | value | target |",
        "| --- | --- | --- |",
        f"| forward spectra/s | {f['spectra_per_s']:.0f} | ≥ 1000 |",
        f"| first-call compile | {f['compile_s']:.2f} s | ≤ 5 s |",
        f"| gradient (jacfwd, 3 thicknesses) / forward | {res['grad_jacfwd']['ratio_to_forward']:.2f} | ≤ 3 |",
        f"| gradient (reverse mode) / forward | {res['grad_reverse']['ratio_to_forward']:.2f} | ≤ 3 |",
    ]
    if "accuracy_vs_nodes" in res:
        lines += ["", "| nodes/segment | abs error of sphere R at 580 nm vs scipy quad |", "| --- | --- |"]
        lines += [f"| {r['nodes_per_segment']} | {r['abs_error']:.1e} |" for r in res["accuracy_vs_nodes"]]
    lines += ["", f"machine: {res['machine']}"]
    (RESULTS / f"{tag}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
