"""Two-constant Kubelka–Munk calibration from drawdowns (fitting/_drawdown.py, issue 28).

A paint of known K(λ), S(λ) is drawn down over a black and a white ground; its readings (through
the binder's interface, by the library's forward model, itself checked against the two-flux ODE
in tests/test_kubelka_munk.py) are fitted back: the K, S that made them are recovered, the
standard errors of noisy replicates cover the truth as often as they say, and the fit names
what a set of drawdowns cannot determine.
"""

from __future__ import annotations

import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls

WL = np.linspace(400.0, 700.0, 11)
K_TRUE = 1e-5 * (1.0 + 3.0 * np.exp(-0.5 * ((WL - 500.0) / 40.0) ** 2))  # 1/nm: a yellow-ish absorber
S_TRUE = 1e-4 * (550.0 / WL) ** 1.5  # 1/nm: scattering falling with λ
BLACK = 0.03 + 0.01 * (WL - 400.0) / 300.0  # a black card's reflectance under the paint
WHITE = 0.85 - 0.05 * ((WL - 550.0) / 150.0) ** 2


def _readings(geometry, grounds, thickness, K=K_TRUE, S=S_TRUE, wl=WL):
    return np.stack([np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.KubelkaMunk(1.5, ls.Paint(K, S), x, rg)),
                                               wl, geometry)) for rg, x in zip(grounds, thickness)])


@pytest.mark.parametrize("geometry", [ls.Sphere(8.0, "included"), ls.Directional(45.0, 0.0)],
                         ids=["sphere SCI", "45/0"])
def test_noise_free_drawdowns_give_back_k_and_s(geometry):
    grounds, thickness = [BLACK, WHITE, WHITE], [20_000.0, 20_000.0, 35_000.0]
    data = _readings(geometry, grounds, thickness)
    obj = ft.drawdown_calibration(WL, geometry, data, grounds, thickness)
    r = ft.fit(obj)
    assert r.converged, r.reason
    np.testing.assert_allclose(r.values["K"], K_TRUE, rtol=1e-6)
    np.testing.assert_allclose(r.values["S"], S_TRUE, rtol=1e-6)


def test_standard_errors_of_noisy_replicates_are_calibrated():
    """100 replicates of three drawdowns (black and white at 20 µm, black at 40 µm) with
    σ = 0.002: the truth lies within ±2σ of the fitted K and S in 90–98 % of the cases (95.4 %
    for a calibrated Gaussian estimate)."""
    geometry = ls.Sphere(8.0, "included")
    grounds, thickness, sigma = [BLACK, WHITE, BLACK], [20_000.0, 20_000.0, 40_000.0], 0.002
    clean = _readings(geometry, grounds, thickness)
    obj = ft.drawdown_calibration(WL, geometry, clean, grounds, thickness, sigma=sigma)
    rng = np.random.default_rng(28)
    noisy = clean + sigma * rng.standard_normal((100,) + clean.shape)
    b = ft.fit_batch(obj, noisy, chunk_size=50, progress=False)
    assert np.all(b.converged)
    x = np.concatenate([b.values["K"], b.values["S"]], axis=1)
    err = np.concatenate([b.errors["K"], b.errors["S"]], axis=1)
    inside = np.abs(x - np.concatenate([K_TRUE, S_TRUE])) <= 2.0 * err
    assert 0.90 <= inside.mean() <= 0.98, inside.mean()


def test_one_ground_cannot_separate_k_and_s_and_the_report_says_so():
    """Two drawdowns of the same thickness over the same white ground hold one number per
    wavelength: the fit names K and S as not separated."""
    geometry = ls.Directional(45.0, 0.0)
    grounds, thickness = [WHITE, WHITE], [20_000.0, 20_000.0]
    r = ft.fit(ft.drawdown_calibration(WL, geometry, _readings(geometry, grounds, thickness), grounds, thickness))
    assert "NOT SEPARATED" in r.report() or "NOT IDENTIFIABLE" in r.report()
    assert r.not_separated or not r.identifiable


def test_bad_drawdowns_are_refused_naming_the_field():
    g = ls.Sphere(8.0)
    data = np.full((2, WL.size), 0.3)
    with pytest.raises(ls.LayerstackError, match="at least two drawdowns"):
        ft.drawdown_calibration(WL, g, data[:1], [0.03], 20_000.0)
    with pytest.raises(ls.LayerstackError, match=r"readings must be \(drawdowns, 11\)"):
        ft.drawdown_calibration(WL, g, data[:, :5], [0.03, 0.85], 20_000.0)
    with pytest.raises(ls.LayerstackError, match=r"grounds must lie in \[0, 1\]"):
        ft.drawdown_calibration(WL, g, data, [3.0, 85.0], 20_000.0)  # percent given
    with pytest.raises(ls.LayerstackError, match="grounds must be a number, one per drawdown"):
        ft.drawdown_calibration(WL, g, data, [0.03, 0.5, 0.85], 20_000.0)
    with pytest.raises(ls.LayerstackError, match="thickness_nm must be > 0"):
        ft.drawdown_calibration(WL, g, data, [0.03, 0.85], [20_000.0, 0.0])


def test_tints_with_a_known_white_calibrate_a_strong_absorber():
    """A pigment too dark to read alone in its absorption band (K X ≈ 6): drawdowns of its masstone
    and of tints with a white of known K, S (Duncan's rule) give back its K and S."""
    wl = np.linspace(400.0, 700.0, 16)
    white = ls.Paint(np.full(wl.size, 2e-6), 3e-3 * (550.0 / wl), name="white")
    red = ls.Paint(4e-4 * np.exp(-0.5 * ((wl - 490.0) / 50.0) ** 2) + 2e-6, 2e-4 * (550.0 / wl), name="red")
    geometry = ls.Sphere(8.0, "included")
    grounds = [np.full(wl.size, 0.03), np.full(wl.size, 0.86)] * 2
    fractions = np.array([1.0, 1.0, 0.1, 0.1])
    data = np.stack([np.asarray(ls.reflectance(ls.Stack(1.0, [], ls.KubelkaMunk(
        1.5, ls.Mixture(np.array([f, 1.0 - f]), [red, white]), 15_000.0, g)), wl, geometry))
        for g, f in zip(grounds, fractions)])
    r = ft.fit(ft.drawdown_calibration(wl, geometry, data, grounds, 15_000.0, white=white, fractions=fractions))
    assert r.converged, r.reason
    np.testing.assert_allclose(r.values["K"], red.absorption, rtol=1e-6)
    np.testing.assert_allclose(r.values["S"], red.scattering, rtol=1e-6)
    with pytest.raises(ls.LayerstackError, match="tints need white="):
        ft.drawdown_calibration(wl, geometry, data, grounds, 15_000.0, fractions=fractions)
    with pytest.raises(ls.LayerstackError, match=r"in \(0, 1\]"):
        ft.drawdown_calibration(wl, geometry, data, grounds, 15_000.0, white=white, fractions=[1.0, 1.0, 10.0, 10.0])
