"""Smoke test: the benchmark runners work on a tiny case (timings are not asserted)."""

import numpy as np
import pytest
import tmm

from benchmarks import _ours
from benchmarks import radiometric


def test_radiometric_runner_tiny():
    res = radiometric.run(batch=4, block=2, nodes=8, float32=False, accuracy=False)
    assert res["forward"]["spectra_per_s"] > 0
    assert np.isfinite(res["grad_jacfwd"]["ratio_to_forward"])


def test_coherent_adapter_matches_tmm():
    import jax.numpy as jnp

    n = np.array([[1.0], [2.35], [1.46 + 0.1j], [1.52]], complex)
    d = np.array([80.0, 120.0])
    wl = np.array([550.0])
    th = np.array([0.0, 0.7])
    R, T = _ours.coherent_rt(jnp.asarray(n), jnp.asarray(d), jnp.asarray(wl), jnp.asarray(th))
    assert R.shape == (2, 2, 1)
    for ip, pol in enumerate("sp"):
        for ia, a in enumerate(th):
            ref = tmm.coh_tmm(pol, list(n[:, 0]), [np.inf, *d, np.inf], a, 550.0)
            assert float(R[ip, ia, 0]) == pytest.approx(ref["R"], abs=1e-12)
            assert float(T[ip, ia, 0]) == pytest.approx(ref["T"], abs=1e-12)
