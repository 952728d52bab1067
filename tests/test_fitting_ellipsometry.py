"""ψ/Δ as fitting data: a variable-angle spectroscopic ellipsometry (VASE) data set of a Cauchy
film on silicon recovers the film thickness and Cauchy coefficients.

The synthetic data come from ``ls.ellipsometry`` with the true values (itself held to ≤ 1e-9
against ``tmm.ellips`` in tests/test_ellipsometry.py); they are checked once more against
``tmm.ellips`` here, so the fit is anchored to an independent model.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
import tmm

import fitting as ft
import layerstack_jax as ls

INF = np.inf


def _stack(d, A, B):
    film = ls.Layer(ls.Cauchy(A, B), d, name="film")
    return ls.Stack(1.0, [film], ls.Substrate(3.9 + 0.02j))


def test_vase_fit_recovers_thickness_and_cauchy_coefficients():
    wl = np.linspace(400.0, 800.0, 41)
    truth = dict(d=123.4, A=1.46, B=0.0042)
    angles = (55.0, 65.0, 75.0)
    geometries = [ls.Ellipsometric(a, q) for a in angles for q in ("N", "C", "S")]
    true_stack = _stack(**truth)
    data = [np.asarray(g.measure(true_stack, jnp.asarray(wl))) for g in geometries]
    # independent check of the synthetic data (tmm's Δ = ours − 180°)
    n_film = truth["A"] + truth["B"] / (wl[7] * 1e-3) ** 2
    e = tmm.ellips([1.0, n_film, 3.9 + 0.02j], [INF, truth["d"], INF], np.deg2rad(65.0), wl[7])
    psi, delta = e["psi"], e["Delta"] + np.pi
    assert abs(np.cos(2 * psi) - data[3][7]) < 1e-9
    assert abs(np.sin(2 * psi) * np.cos(delta) - data[4][7]) < 1e-9

    start = _stack(d=100.0, A=1.5, B=0.002)
    params = [ft.thickness("film", lower=0.0, upper=400.0), ft.dispersion("film", "A", lower=1.0, upper=2.5),
              ft.dispersion("film", "B", lower=0.0, upper=0.05)]
    datasets = [ft.Dataset(g, y, sigma=1e-3) for g, y in zip(geometries, data)]
    result = ft.fit(ft.Objective(start, wl, datasets, params))
    assert result.converged, result.report()
    values = np.array([float(np.squeeze(v)) for v in result.values.values()])
    expected = np.array([truth["d"], truth["A"], truth["B"]])
    np.testing.assert_allclose(values, expected, rtol=1e-6)


def test_ellipsometric_geometry_validates():
    with pytest.raises(ls.LayerstackError, match="quantity"):
        ls.Ellipsometric(70.0, "rho")
    with pytest.raises(ls.LayerstackError):
        ls.Ellipsometric(95.0, "psi")
