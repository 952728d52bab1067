"""Fits and predictions split over several devices (issue 19): JAX sharding over the fits' (spectra') axis gives the same
results as one device.

CPU devices stand in for accelerators (``XLA_FLAGS=--xla_force_host_platform_device_count``);
each run is a fresh process, since the device count is fixed when JAX starts. The reference is
the same job on one device; the data are made by the public forward model (the transmittance of
an absorbing slab, known α), and the fitted α are also checked against those true values.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

JOB = r"""
import json
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import fitting as ft
import layerstack_jax as ls

wl = np.linspace(400.0, 700.0, 41)
t0 = ls.Specular(0.0, "T")
slab = lambda a: ls.Stack(1.0, [ls.Layer(1.5, 1e4, coherent=False, alpha=a, name="slab")], ls.Substrate(1.5))
T = lambda a: np.asarray(ls.reflectance(slab(a), wl, t0))
alphas = np.linspace(1e-6, 4e-5, 7)
obj = ft.Objective(slab(5e-6), wl, ft.Dataset(t0, T(2e-5), sigma=0.002), [ft.alpha("slab")])
b = ft.fit_batch(obj, np.stack([T(a) for a in alphas] + [1.02 * T(0.0)]), chunk_size=5, progress=False)
r = ft.fit(obj, starts=3)
print(json.dumps({"devices": len(jax.devices()), "x": b.x.tolist(), "stderr": b.stderr.tolist(),
                  "steps": b.num_steps.tolist(), "converged": b.converged.tolist(), "multistart": r.x.tolist()}))
"""


def _run(devices: int) -> dict:
    env = dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}", JAX_PLATFORMS="cpu",
               PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", JOB], cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_fits_on_two_devices_equal_one_device():
    one, two = _run(1), _run(2)
    assert (one["devices"], two["devices"]) == (1, 2)
    assert all(two["converged"])
    np.testing.assert_allclose(two["x"], one["x"], rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(two["stderr"], one["stderr"], rtol=1e-9)
    assert two["steps"] == one["steps"]
    np.testing.assert_allclose(two["multistart"], one["multistart"], rtol=1e-12)
    # and both are right: the true α of the data (0 for the last: brighter than any α >= 0 allows)
    np.testing.assert_allclose(np.ravel(two["x"])[:7], np.linspace(1e-6, 4e-5, 7), rtol=1e-6)
    assert np.ravel(two["x"])[7] == 0.0


PREDICT = r"""
import json
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import layerstack_jax as ls

wl = np.linspace(400.0, 700.0, 31)
h = np.linspace(1e3, 4e4, 37)[:, None]            # 37 spectra: not a multiple of chunk x devices
rho = np.linspace(0.1, 0.9, 37)[:, None]
stack = ls.Stack(1.0, [ls.Layer(1.6, 120.0, name="film"),
                       ls.Layer(1.5, h, coherent=False, alpha=2e-5, name="varnish")],
                 ls.LambertianBackground(1.5, rho))
seen = []
sphere = ls.predict(stack, wl, ls.Sphere(8.0), chunk=3, step=8, progress=lambda d, n: seen.append(d))
film = ls.predict(ls.Stack(1.0, [ls.Layer(1.6, np.linspace(50, 300, 37)[:, None], name="film")],
                           ls.Substrate(1.45)), wl, ls.Specular(np.array([0.0, 60.0])), chunk=2, step=4)
print(json.dumps({"devices": len(jax.local_devices()), "sphere": sphere.tolist(), "film": film.tolist(),
                  "seen": seen}))
"""


def test_predict_on_two_devices_equals_one_device():
    """``ls.predict`` splits each compiled call over every local device (shard_map over the
    spectra): two devices give one device's numbers, in the same order, for every spectrum."""
    def run(devices):
        env = dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}", JAX_PLATFORMS="cpu",
                   PYTHONPATH=str(ROOT))
        out = subprocess.run([sys.executable, "-c", PREDICT], cwd=ROOT, env=env, capture_output=True, text=True,
                             timeout=600)
        assert out.returncode == 0, out.stderr[-3000:]
        return json.loads(out.stdout.strip().splitlines()[-1])

    one, two = run(1), run(2)
    assert (one["devices"], two["devices"]) == (1, 2)
    assert np.shape(two["sphere"]) == (37, 31) and np.shape(two["film"]) == (37, 2, 31)
    np.testing.assert_allclose(two["sphere"], one["sphere"], rtol=1e-13, atol=0)
    np.testing.assert_allclose(two["film"], one["film"], rtol=1e-13, atol=0)
    # every spectrum really computed (not padding copies): the spectra differ from row to row
    assert np.all(np.abs(np.diff(np.asarray(two["sphere"])[:, 15])) > 1e-6)
    # step 8 rounded up to a multiple of chunk x devices: 9 (3 x 1) on one device, 12 (3 x 2) on two
    assert one["seen"] == [9, 18, 27, 36, 37] and two["seen"] == [12, 24, 36, 37]
