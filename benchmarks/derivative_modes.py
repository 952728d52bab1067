"""What a derivative costs, by mode, on P2 and P3 (cases: ``benchmarks/README.md``).

    python -m benchmarks.derivative_modes [--rounds 5] [--p3-batch 96]

For each case, in one process with the functions compiled first and timed in interleaved rounds
(best of the rounds): the forward spectra; one forward-mode tangent (``jax.jvp``); the 401 × 3
Jacobian (``jax.jacfwd``, what the least-squares solvers use); the gradient of a least-squares
loss by forward mode (``jax.jacfwd``) and by reverse mode (``jax.value_and_grad``); and one
reverse pass of the spectrum alone (``jax.vjp``). Each as a ratio to the forward, which is what
the targets "gradient ≤ 3× forward" read. Writes ``results/derivative_modes.md`` (``--out``).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

ROWS = (("forward", "forward spectra"), ("jvp_1dir", "one tangent (jvp)"),
        ("jacfwd_model", "Jacobian 401 × 3 (jacfwd)"), ("jacfwd_loss", "loss gradient, forward mode (jacfwd)"),
        ("value_and_grad_rev", "loss value + gradient, reverse mode"), ("vjp_model", "one reverse pass (vjp)"))


def _timings(jax, jnp, model, H, data, block: int, rounds: int) -> dict:
    def loss(h):
        return jnp.sum((model(h) - data) ** 2)

    e0 = jnp.zeros(H.shape[1], H.dtype).at[0].set(1.0)
    ones = jnp.ones_like(data)
    per_sample = {
        "forward": model,
        "jvp_1dir": lambda h: jax.jvp(model, (h,), (e0,)),
        "jacfwd_model": jax.jacfwd(model),
        "jacfwd_loss": jax.jacfwd(loss),
        "value_and_grad_rev": jax.value_and_grad(loss),
        "vjp_model": lambda h: jax.vjp(model, h)[1](ones)[0],
    }
    fns = {k: jax.jit(lambda H, f=f: jax.lax.map(f, H, batch_size=block)) for k, f in per_sample.items()}
    for f in fns.values():
        jax.block_until_ready(f(H))
    best = {k: np.inf for k in fns}
    for _ in range(rounds):
        for k, f in fns.items():
            t = time.perf_counter()
            jax.block_until_ready(f(H))
            best[k] = min(best[k], time.perf_counter() - t)
    return best


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.derivative_modes")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--p2-batch", type=int, default=200)
    p.add_argument("--p3-batch", type=int, default=96)
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "results" / "derivative_modes.md"))
    a = p.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from . import mixed, radiometric

    rng = np.random.default_rng(0)
    model, *_ = radiometric.build(48, jnp.float64)
    H2 = jnp.asarray(rng.uniform(2e3, 3e4, (a.p2_batch, 3)))
    p2 = _timings(jax, jnp, model, H2, model(H2[0] * 1.05), 4, a.rounds)
    wl = np.linspace(mixed.WAVELENGTHS[0], mixed.WAVELENGTHS[1], mixed.WAVELENGTHS[2])
    model3, _, _ = mixed.build(wl)
    H3 = jnp.asarray(mixed.samples(a.p3_batch))
    p3 = _timings(jax, jnp, model3, H3, model3(H3[0] * 1.03), mixed.BLOCK, a.rounds)

    load = os.getloadavg()[0]
    lines = [f"# Derivative cost by mode (`python -m benchmarks.derivative_modes --rounds {a.rounds}`)", "",
             f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} CPUs, load {load:.2f} at the end; "
             f"P2 batch {a.p2_batch} (blocks of 4), P3 batch {a.p3_batch} (blocks of {mixed.BLOCK}); "
             "best of interleaved rounds, float64.", "",
             "| | P2 ms | P2 / forward | P3 ms | P3 / forward |", "|---|---|---|---|---|"]
    for key, label in ROWS:
        lines.append(f"| {label} | {p2[key] * 1e3:.1f} | {p2[key] / p2['forward']:.2f} | "
                     f"{p3[key] * 1e3:.1f} | {p3[key] / p3['forward']:.2f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    Path(a.out).write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
