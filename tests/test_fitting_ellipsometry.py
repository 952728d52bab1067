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
    # independent check of the synthetic data (ours: Δ = 180° − Δ_tmm, the instruments' sign)
    n_film = truth["A"] + truth["B"] / (wl[7] * 1e-3) ** 2
    e = tmm.ellips([1.0, n_film, 3.9 + 0.02j], [INF, truth["d"], INF], np.deg2rad(65.0), wl[7])
    psi, delta = e["psi"], np.pi - e["Delta"]
    assert abs(np.cos(2 * psi) - data[3][7]) < 1e-9
    assert abs(np.sin(2 * psi) * np.cos(delta) - data[4][7]) < 1e-9
    assert abs(np.sin(2 * psi) * np.sin(delta) - data[5][7]) < 1e-9

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


# J. A. Woollam RC2 file of native SiO2 on Si at 70° (pyElli, examples/gallery/SiO2onSi.ellips.nxs,
# commit aa49502; the same rows as tests/test_ellipsometry.py): (wavelength nm, psi deg, Delta deg).
WOOLLAM_SIO2_SI_70 = np.array([
    (250.0, 35.11196, 110.37192), (300.0, 29.85667, 141.44139), (350.0, 26.16517, 147.30881),
    (400.0, 20.38003, 169.13811), (450.0, 15.80446, 171.10200), (500.0, 13.45709, 171.97935),
    (550.0, 12.01816, 172.61429), (600.0, 11.03281, 173.02867), (650.0, 10.32219, 173.40695),
    (700.0, 9.77915, 173.77614), (750.0, 9.36196, 174.15385), (800.0, 9.02136, 174.41823),
])


def test_measured_woollam_psi_delta_fit_inside_bounds():
    """Issue 15: fed as measured, a Woollam ψ/Δ file must fit to the native oxide's thickness
    (1–3 nm), not to a bound: the reported Δ has the instrument's sign. Residual ≤ 1° rms."""
    wl, psi_m, delta_m = WOOLLAM_SIO2_SI_70.T
    start = ls.Stack(1.0, [ls.Layer(ls.Cauchy(1.452, 0.0036), 10.0, name="oxide")], ls.Substrate(ls.material("Si", "Aspnes")))
    datasets = [ft.Dataset(ls.Ellipsometric(70.0, "psi"), psi_m, sigma=1.0),
                ft.Dataset(ls.Ellipsometric(70.0, "delta"), delta_m, sigma=1.0)]
    result = ft.fit(ft.Objective(start, wl, datasets, [ft.thickness("oxide", lower=0.0, upper=50.0)]))
    assert result.converged, result.report()
    d = float(np.squeeze(next(iter(result.values.values()))))
    assert 1.0 <= d <= 3.0
    e = ls.ellipsometry(ls.Stack(1.0, [ls.Layer(ls.Cauchy(1.452, 0.0036), d)], start.exit), wl, 70.0)
    res = np.concatenate([np.asarray(e.psi_deg) - psi_m, np.asarray(e.delta_deg) - delta_m])
    assert np.sqrt(np.mean(res**2)) <= 1.0


@pytest.mark.slow  # ~1-2 min on a shared 2-core machine (compiling the Jacobian of a 2-layer VASE model)
def test_oscillator_and_roughness_parameters_are_fittable():
    """Tauc–Lorentz film under a rough (Bruggeman, void + dense top material) layer on silicon:
    VASE (N, C, S at 60° and 70°) recovers thickness, band gap, amplitude of the film and the
    void fraction of the rough layer from a start 10–20 % off: the fitting objective reaches
    the leaves of the new materials."""
    from layerstack_jax._media.effective_medium import Bruggeman
    from layerstack_jax._media.oscillators import TaucLorentz

    def stack(d, Eg, A, void):
        tl = TaucLorentz(Eg=Eg, A=A, E0=4.5, C=1.5, eps_inf=1.8)
        rough = ls.Layer(Bruggeman([1.0, ls.Index(2.2, 0.05)], void), 4.0, name="rough")
        return ls.Stack(1.0, [rough, ls.Layer(tl, d, name="film")], ls.Substrate(3.9 + 0.02j))

    wl = np.linspace(250.0, 900.0, 14)
    truth = dict(d=48.0, Eg=3.1, A=150.0, void=0.5)
    geometries = [ls.Ellipsometric(a, q) for a in (60.0, 70.0) for q in ("N", "C", "S")]
    data = [np.asarray(g.measure(stack(**truth), jnp.asarray(wl))) for g in geometries]
    params = [ft.thickness("film", lower=0.0, upper=200.0),
              ft.dispersion("film", "Eg", lower=1.0, upper=4.0),
              ft.dispersion("film", "A", lower=10.0, upper=400.0),
              ft.dispersion("rough", "fractions", lower=0.0, upper=1.0)]
    datasets = [ft.Dataset(g, y, sigma=1e-3) for g, y in zip(geometries, data)]
    result = ft.fit(ft.Objective(stack(d=55.0, Eg=2.8, A=130.0, void=0.4), wl, datasets, params))
    assert result.converged, result.report()
    values = np.array([float(np.squeeze(v)) for v in result.values.values()])
    np.testing.assert_allclose(values, [truth["d"], truth["Eg"], truth["A"], truth["void"]], rtol=1e-5)
