"""float32 accuracy, as stated in the README ("Precision").

The float32 path runs in a subprocess with ``jax_enable_x64`` off (how a GPU user runs it) and is
compared with the float64 path of this process, itself held to ≤ 1e-12 against ``tmm`` and the
scipy-quad references elsewhere in the suite. The bounds below are the README's statement: a
test failure means the statement is wrong, not that the tolerance needs loosening.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls

#: README, "Precision": max |ΔR| of float32 against float64
BOUNDS = {
    "coherent_10_layers": 2e-5,  # P1-like: 10 films on glass, 0–80°
    "coherent_10um_film": 5e-4,  # interference phase 4π n d cosθ/λ ~ 300 rad carries ~1e-5 relative error
    "radiometric_sphere": 1e-6,  # P2: 3 Beer layers over a background, diffuse quadrature
    "radiometric_45_0": 1e-6,
}

_PROGRAM = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    import jax.numpy as jnp
    sys.path.insert(0, {tests!r})
    from test_precision import cases
    out = {{name: np.asarray(f(), dtype=float).tolist() for name, f in cases().items()}}
    import jax
    out["x64"] = bool(jax.config.read("jax_enable_x64"))
    out["dtype"] = str(cases()["radiometric_sphere"]().dtype)
    print(json.dumps(out))
    """
)


def cases() -> dict:
    """The compared computations; each returns a real array (dtype follows the x64 setting)."""
    rng = np.random.default_rng(1)
    wl = jnp.asarray(np.linspace(400.0, 1000.0, 120))
    angles = jnp.asarray(np.deg2rad(np.linspace(0.0, 80.0, 9)))
    d = rng.uniform(50.0, 200.0, 10)
    p1 = ls.Stack(1.0, [ls.Layer(2.35 if i % 2 == 0 else 1.46, d[i]) for i in range(10)], ls.Substrate(1.52))
    thick = ls.Stack(1.0, [ls.Layer(1.5, 10_000.0), ls.Layer(0.2 + 3j, 30.0)], ls.Substrate(1.52))
    wl2 = np.linspace(380.0, 780.0, 81)
    alpha = [2e-5 * (1.0 + np.sin(wl2 / 50.0 + i)) for i in range(3)]
    rho = 0.3 + 0.5 * np.exp(-(((wl2 - 550.0) / 80.0) ** 2))
    layers = [ls.Layer(n, h, coherent=False, alpha=a) for n, h, a in zip((1.5, 1.6, 1.45), (1e4, 2e4, 5e3), alpha)]
    p2 = ls.Stack(1.0, layers, ls.LambertianBackground(1.52, rho))
    return {
        "coherent_10_layers": lambda: ls.specular(p1, wl, angle_rad=angles).R_front,
        "coherent_10um_film": lambda: ls.specular(thick, wl, angle_rad=angles).R_front,
        "radiometric_sphere": lambda: ls.reflectance(p2, jnp.asarray(wl2), ls.Sphere(8.0)),
        "radiometric_45_0": lambda: ls.reflectance(p2, jnp.asarray(wl2), ls.Directional(45.0, 0.0)),
    }


@pytest.fixture(scope="module")
def float32_results():
    env = dict(os.environ, JAX_ENABLE_X64="0", JAX_PLATFORMS="cpu")
    tests = os.path.dirname(os.path.abspath(__file__))
    proc = subprocess.run(
        [sys.executable, "-c", _PROGRAM.format(tests=tests)], env=env, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["x64"] is False and out["dtype"] == "float32"
    return out


@pytest.mark.parametrize("name", sorted(BOUNDS))
def test_float32_accuracy_statement(float32_results, name):
    single = np.asarray(float32_results[name])
    double = np.asarray(cases()[name]())
    assert double.dtype == np.float64
    assert np.all(np.isfinite(single))
    err = float(np.max(np.abs(single - double)))
    assert err <= BOUNDS[name], f"{name}: float32 error {err:.2e} > stated {BOUNDS[name]:.0e}"
