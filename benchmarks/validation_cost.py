"""Cost of the traced validation (issue 18): P1 and P2 forward and F1 fits with this tree against
a tree without it, side by side, alternating runs in fresh processes.

``python -m benchmarks.validation_cost --before PATH [--rounds 3]``: ``PATH`` is a checkout of
the code before the change (e.g. ``git worktree add /tmp/before b28ade3``). Each round runs the
worker once in each tree (order alternating); the figure per tree is the best time over rounds.
The worker uses only API present in both trees: ``ls.reflectance`` with ``ls.Sphere`` (P2) and
``ls.specular`` (P1; radians positional before, ``angle_rad=`` after).

P2: 3 Beer layers over a Lambertian background, sphere 8° SCE, 401 λ, 1000 stacks by
``lax.map`` in blocks of 4. P1: 10 coherent films, 1000 λ × 64 angles, s + p. F1: 200
per-pixel fits of ``benchmarks.fitting_cases``' F1 problem (top thickness + 3 α coefficients,
401 λ, sphere) by one ``fitting.fit_batch`` call after a compiling call, best of 2. E1: the
ψ/Δ fit of ``benchmarks.ellipsometry_fit`` (3 angles × 700 λ, film thickness and Cauchy A, B free)
on data made by the tree's own forward model plus noise, median of 7 further fits of one
objective after a compiling one.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

WORKER = r'''
import json, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np
import layerstack_jax as ls

def best(f, *a, n=5):
    jax.block_until_ready(f(*a))
    t = []
    for _ in range(n):
        t0 = time.perf_counter(); jax.block_until_ready(f(*a)); t.append(time.perf_counter() - t0)
    return min(t)

wl = jnp.linspace(380.0, 780.0, 401)
def p2_stack(h):
    layers = [ls.Layer(1.5, h[i], coherent=False, alpha=1e-5 * (i + 1)) for i in range(3)]
    return ls.Stack(1.0, layers, ls.LambertianBackground(1.52, 0.7))
p2 = jax.jit(lambda H: jax.lax.map(lambda h: ls.reflectance(p2_stack(h), wl, ls.Sphere(8.0)), H, batch_size=4))
H = jnp.asarray(np.random.default_rng(0).uniform(5e3, 5e4, (1000, 3)))
t_p2 = best(p2, H, n=3)

wl1 = jnp.linspace(400.0, 1400.0, 1000)
ang = jnp.linspace(0.0, 1.4, 64)
film = ls.Stack(1.0, [ls.Layer(1.46 if i % 2 else 2.3, 80.0 + 7 * i) for i in range(10)], ls.Substrate(1.52))
try:
    ls.specular(film, wl1[:2], angle_rad=ang[:2])
    p1 = jax.jit(lambda a: ls.specular(film, wl1, angle_rad=a, both_sides=False).R_front)
except TypeError:
    p1 = jax.jit(lambda a: ls.specular(film, wl1, a, both_sides=False).R_front)
t_p1 = best(p1, ang)

import fitting
from benchmarks.fitting_cases import WL as WLF, _f1_stack as f1_stack  # the same in both trees
B = fitting.bspline_basis(WLF, 3)
rng = np.random.default_rng(1)
n = 200
hc = np.column_stack([rng.uniform(15_000.0, 30_000.0, n), rng.uniform(0.5e-5, 4e-5, (n, 3))])
one = lambda v: ls.reflectance(f1_stack(v[0], B @ v[1:]), WLF, ls.Sphere(8.0))
data = np.asarray(jax.jit(lambda v: jax.lax.map(one, v, batch_size=50))(hc)) + 0.002 * rng.standard_normal((n, WLF.size))
obj = fitting.Objective(f1_stack(20_000.0, B @ np.full(3, 1e-5)), WLF, fitting.Dataset(ls.Sphere(8.0), data[0], sigma=0.002),
                        [fitting.thickness("top"), fitting.alpha("ink", basis=B, value=np.full(3, 1e-5))])
fitting.fit_batch(obj, data[:100], chunk_size=100)  # compile
t = []
for _ in range(2):
    t0 = time.perf_counter(); b = fitting.fit_batch(obj, data, chunk_size=100); t.append(time.perf_counter() - t0)
assert b.converged.all()

from benchmarks import ellipsometry_fit as E  # E1, the same problem in both trees
wle = E.wavelengths(700)
truth = E.objective(wle, np.zeros((3, wle.size)), np.zeros((3, wle.size)))
x_true = np.array([E.TRUTH["d"], E.TRUTH["A"], E.TRUTH["B"]])
clean = [np.asarray(v)[0] for v in truth.predict(jnp.asarray(x_true))]
rng = np.random.default_rng(2)
noisy = lambda: [(c + E.SIGMA_DEG * rng.standard_normal(c.shape))[None] for c in clean]
obj_e = E.objective(wle, np.asarray(clean[0::2]), np.asarray(clean[1::2]))
fitting.fit(obj_e, data=noisy())  # compile
te = []
for _ in range(7):
    d = noisy()
    t0 = time.perf_counter(); r = fitting.fit(obj_e, data=d); te.append(time.perf_counter() - t0)
print(json.dumps({"p2_s": t_p2, "p1_s": t_p1, "f1_s": min(t), "e1_s": float(np.median(te))}))
'''


QUANTITIES = ("p1_s", "p2_s", "f1_s", "e1_s")


def _run(tree: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, "-c", WORKER], cwd=tree, env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, type=Path, help="checkout of the code to compare with (e.g. an issue's base commit)")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)
    after = Path(__file__).resolve().parent.parent
    runs = {"before": [], "after": []}
    for r in range(args.rounds):
        order = (("before", args.before), ("after", after)) if r % 2 == 0 else (("after", after), ("before", args.before))
        for name, tree in order:
            runs[name].append(_run(tree))
            print(name, runs[name][-1], f"load {os.getloadavg()[0]:.1f}", flush=True)
    best = {k: {q: min(x[q] for x in v) for q in QUANTITIES if q in v[0]} for k, v in runs.items()}
    for q, label in (("p1_s", "P1 forward (10 films, 1000 λ × 64 angles)"), ("p2_s", "P2 forward (1000 spectra)"),
                     ("f1_s", "F1 fits (200 per-pixel fits, compiled)"), ("e1_s", "E1 ψ/Δ fit (3 × 700, compiled)")):
        if q not in best["before"] or q not in best["after"]:
            continue
        b, a = best["before"][q], best["after"][q]
        print(f"{label}: before {b * 1e3:.1f} ms, after {a * 1e3:.1f} ms, cost {100 * (a / b - 1):+.1f} %")
    print(json.dumps({"runs": runs, "best": best, "when": time.strftime("%Y-%m-%d %H:%M")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
