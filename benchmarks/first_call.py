"""A new user's first answer: the README's first snippet in fresh processes.

    python -m benchmarks.first_call [--before PATH] [--rounds 2]

Each run is a new Python process that imports ``layerstack_jax``, builds the README's varnish over
a paint and calls ``ls.reflectance`` for 45°/0° (the first answer), then for the sphere (a second
call structure), then 45°/0° again with new values (no compilation expected). Counted: XLA
programs compiled (JAX's ``/jax/core/compile/backend_compile_duration`` events) and wall times,
with the persistent compilation cache off, cold (an empty cache directory) and warm (the same
directory again). ``--before PATH`` runs the same script against another checkout (e.g. a
``git worktree`` of an earlier commit) in alternation, for before/after figures. Writes
``benchmarks/results/first_call.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results"

SNIPPET = r'''
import json, time
t0 = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
compiles = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kw: compiles.append(duration) if event == "/jax/core/compile/backend_compile_duration" else None)
import numpy as np
import layerstack_jax as ls
t_import = time.perf_counter() - t0
wl = np.linspace(380.0, 780.0, 81)
stack = ls.Stack(1.0, [ls.Layer(1.54, 30_000.0, coherent=False, alpha=2e-6, name="varnish")],
                 ls.LambertianBackground(1.5, 0.6))
t = time.perf_counter(); n = len(compiles)
R = np.asarray(ls.reflectance(stack, wl, ls.Directional(45.0, 0.0)))
first, first_n = time.perf_counter() - t, len(compiles) - n
t = time.perf_counter(); n = len(compiles)
np.asarray(ls.reflectance(stack, wl, ls.Sphere(8.0, "excluded")))
sphere, sphere_n = time.perf_counter() - t, len(compiles) - n
other = ls.Stack(1.0, [ls.Layer(1.55, 20_000.0, coherent=False, alpha=3e-6, name="varnish")],
                 ls.LambertianBackground(1.5, 0.5))
t = time.perf_counter(); n = len(compiles)
np.asarray(ls.reflectance(other, wl, ls.Directional(45.0, 0.0)))
again, again_n = time.perf_counter() - t, len(compiles) - n
print(json.dumps({"import_s": t_import, "first_s": first, "first_compiles": first_n, "sphere_s": sphere,
                  "sphere_compiles": sphere_n, "new_values_s": again, "new_values_compiles": again_n,
                  "module": ls.__file__, "R_45_0_at_580nm": float(R[40])}))
'''


def _run(tree: Path, cache: str) -> dict:
    env = dict(os.environ, LAYERSTACK_CACHE_DIR=cache, PYTHONPATH=str(tree), JAX_PLATFORMS="cpu")
    r = subprocess.run([sys.executable, "-c", SNIPPET], capture_output=True, text=True, cwd=tree, env=env)
    if r.returncode:
        raise SystemExit(r.stderr[-3000:])
    out = json.loads(r.stdout.strip().splitlines()[-1])
    if not out["module"].startswith(str(tree)):
        raise SystemExit(f"{tree}: imported {out['module']} instead")
    return out


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--before", type=Path, help="another checkout to run in alternation (before/after)")
    p.add_argument("--rounds", type=int, default=2)
    a = p.parse_args(argv)
    trees = {"after": ROOT} if a.before is None else {"before": a.before.resolve(), "after": ROOT}
    runs = []
    for r in range(a.rounds):
        for label, tree in trees.items():
            with tempfile.TemporaryDirectory() as cache:
                for mode, where in (("off", ""), ("cold", cache), ("warm", cache)):
                    runs.append({"tree": label, "round": r, "cache": mode, **_run(tree, where)})
                    print(runs[-1], flush=True)
    out = {"case": "README first snippet (varnish over paint, 81 wavelengths)", "runs": runs,
           "loadavg": os.getloadavg()}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "first_call.json").write_text(json.dumps(out, indent=2))
    lines = ["| checkout | cache | first call s | programs compiled | sphere s (new structure) | programs | "
             "new values s | programs |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for x in runs:
        lines.append(f"| {x['tree']} | {x['cache']} | {x['first_s']:.2f} | {x['first_compiles']} | {x['sphere_s']:.2f} | "
                     f"{x['sphere_compiles']} | {x['new_values_s']:.3f} | {x['new_values_compiles']} |")
    lines.append(f"\nload average after the runs: {out['loadavg'][0]:.1f}")
    (RESULTS / "first_call.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return out


if __name__ == "__main__":
    main()
