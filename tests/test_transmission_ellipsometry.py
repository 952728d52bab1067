"""Transmission ellipsometry (issue 15): ρ_t = t_p/t_s = tan ψ_t e^{−iΔ_t}, the same Δ sign as
in reflection (Δ_t = −arg(t_p/t_s)), read by ``Ellipsometric(..., mode="transmission")``.

References: ``tmm.coh_tmm``'s t_s, t_p (independent transfer-matrix code), the closed form of a
single interface (t_p/t_s = (n_i cos θ_i + n_f cos θ_f)/(n_f cos θ_i + n_i cos θ_f), real:
Δ_t = 0, ψ_t ≥ 45°; 45° at normal incidence) and, for a thick slab, the explicit beam-by-beam
sum of tests/test_ellipsometry_backside.py.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tmm

import layerstack_jax as ls
from test_ellipsometry_backside import explicit_sum, reading_of

INF = np.inf
WL = np.array([380.0, 450.0, 520.0, 600.0, 700.0, 820.0])
ANGLES = np.array([0.0, 15.0, 35.0, 50.0, 65.0, 80.0])


def _read(quantity, stack, angles=ANGLES, wl=WL, **kw):
    g = ls.Ellipsometric(jnp.asarray(angles), quantity, mode="transmission", **kw)
    return jax.jit(lambda st: g.measure(st, jnp.asarray(wl)))(stack)


def _reading(stack, angles=ANGLES, wl=WL, **kw):
    g = ls.Ellipsometric(jnp.asarray(angles), "psi", mode="transmission", **kw)
    return jax.jit(lambda st: g.reading(st, jnp.asarray(wl)))(stack)


COHERENT = {
    # (ambient, [(n, d)], exit)
    "AR coating on glass": (1.0, [(1.38, 99.0)], 1.52),
    "absorbing films into glass": (1.0, [(2.3 + 0.05j, 60.0), (1.46, 140.0), (0.15 + 3.2j, 8.0)], 1.52),
    "film in water on glass": (1.33, [(1.9 + 0.01j, 210.0)], 1.46),
    "free-standing film": (1.0, [(2.02 + 0.002j, 350.0)], 1.0),
}


def _tmm_ratio(ambient, films, exit_n, angles, wl):
    n_list = [ambient, *(n for n, _ in films), exit_n]
    d_list = [INF, *(d for _, d in films), INF]
    out = np.empty((len(angles), len(wl)), complex)
    for i, a in enumerate(angles):
        for j, lam in enumerate(wl):
            ts = tmm.coh_tmm("s", n_list, d_list, np.deg2rad(a), lam)["t"]
            tp = tmm.coh_tmm("p", n_list, d_list, np.deg2rad(a), lam)["t"]
            out[i, j] = tp / ts
    return out


@pytest.mark.parametrize("case", sorted(COHERENT))
def test_coherent_transmission_matches_tmm(case):
    ambient, films, exit_n = COHERENT[case]
    stack = ls.Stack(ambient, [ls.Layer(n, d) for n, d in films], ls.Substrate(exit_n))
    rho = _tmm_ratio(ambient, films, exit_n, ANGLES, WL)
    got = np.asarray(_read("rho_re", stack)) + 1j * np.asarray(_read("rho_im", stack))
    np.testing.assert_allclose(np.asarray(got), rho, rtol=1e-10, atol=0)
    r = _reading(stack)
    np.testing.assert_allclose(np.asarray(r.psi_deg), np.rad2deg(np.arctan(np.abs(rho))), rtol=0, atol=1e-9)
    d = np.asarray(r.delta_deg) + np.rad2deg(np.angle(rho))  # Δ_t = −arg ρ_t
    np.testing.assert_allclose((d + 180.0) % 360.0 - 180.0, 0.0, atol=1e-9)
    psi, delta = np.arctan(np.abs(rho)), -np.angle(rho)
    for q, want in (("N", np.cos(2 * psi)), ("C", np.sin(2 * psi) * np.cos(delta)),
                    ("S", np.sin(2 * psi) * np.sin(delta))):
        np.testing.assert_allclose(np.asarray(getattr(r, q)), want, atol=1e-10, err_msg=q)
    assert np.all(np.asarray(r.depolarization) == 0)


def test_single_interface_closed_form():
    """t_p/t_s of one interface is real and ≥ 1: Δ_t = 0, tan ψ_t = (n_i c_i + n_f c_f)/(n_f c_i + n_i c_f);
    ψ_t = 45° at normal incidence."""
    n_i, n_f = 1.0, 1.52
    th = np.deg2rad(ANGLES)[:, None]
    c_i = np.cos(th)
    c_f = np.sqrt(1 - (n_i * np.sin(th) / n_f) ** 2)
    want = np.rad2deg(np.arctan((n_i * c_i + n_f * c_f) / (n_f * c_i + n_i * c_f))) + 0 * WL
    r = _reading(ls.Stack(n_i, [], ls.Substrate(n_f)))
    np.testing.assert_allclose(np.asarray(r.psi_deg), want, atol=1e-10)
    np.testing.assert_allclose(np.asarray(r.delta_deg), 0.0, atol=1e-10)
    np.testing.assert_allclose(np.asarray(r.psi_deg)[0], 45.0, atol=1e-12)
    assert np.all(np.asarray(r.psi_deg)[1:] > 45.0)


SLABS = {
    "bare glass slab": (1.0, [], (1.515, 1.0e6, 0.0), [], 1.0),
    "coated absorbing slab": (1.0, [(2.02 + 0.001j, 120.0)], (1.6 + 2e-7j, 3.0e5, 0.0), [(1.38, 99.0)], 1.0),
}


@pytest.mark.parametrize("case", sorted(SLABS))
def test_thick_slab_transmission_matches_explicit_beam_sum(case):
    ambient, front, (n, D, alpha), back, exit_n = SLABS[case]
    layers = [ls.Layer(m, d) for m, d in front] + [ls.Layer(n, D, coherent=False)] + [ls.Layer(m, d) for m, d in back]
    r = _reading(ls.Stack(ambient, layers, ls.Substrate(exit_n)))
    want = reading_of(explicit_sum(*SLABS[case], ANGLES, WL, transmission=True))
    for q in ("N", "C", "S", "depolarization"):
        np.testing.assert_allclose(np.asarray(getattr(r, q)), want[q], rtol=0, atol=1e-12, err_msg=q)
    dep = np.asarray(r.depolarization)
    assert np.all((dep >= 0) & (dep <= 1)) and np.max(dep) > 1e-6
    # normal incidence: t_p = t_s for every beam, nothing to tell s from p
    np.testing.assert_allclose(np.asarray(r.psi_deg)[0], 45.0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(r.delta_deg)[0], 0.0, atol=1e-9)
    np.testing.assert_allclose(dep[0], 0.0, atol=1e-12)


def test_spelling_label_and_refusals():
    g = ls.Ellipsometric.parse("ellipsometry:30:delta:transmission")
    assert g.mode == "transmission" and g.quantity == "delta" and g.label == "ellipsometry:30:delta:transmission"
    assert ls.Ellipsometric.parse(g.label) == g
    assert ls.Ellipsometric.parse("ellipsometry:70:psi").mode == "reflection"
    assert ls.Ellipsometric.parse("ellipsometry:70:N:reflection").label == "ellipsometry:70:N"
    assert "transmission" in g.quantity_label
    with pytest.raises(ls.LayerstackError, match="transmission"):
        ls.Ellipsometric.parse("ellipsometry:70:psi:transmitted")
    with pytest.raises(ls.LayerstackError, match="mode"):
        ls.Ellipsometric(30.0, "psi", mode="both")
    g = ls.Ellipsometric(30.0, "psi", mode="transmission")
    with pytest.raises(ls.LayerstackError, match="exit index must be transparent"):
        g.measure(ls.Stack(1.0, [ls.Layer(1.5, 100.0)], ls.Substrate(3.9 + 0.02j)), WL)
    with pytest.raises(Exception, match="exit index must be transparent"):  # traced: equinox.error_if at run time
        jax.jit(lambda k: g.measure(ls.Stack(1.0, [ls.Layer(1.5, 100.0)], ls.Substrate(ls.Index(3.9, k))), WL))(0.02)
    slab = ls.Stack(1.0, [ls.Layer(1.5, 1e5, coherent=False)], ls.Substrate(3.9 + 0.02j))
    with pytest.raises(ls.LayerstackError, match="exit index must be transparent"):
        g.measure(slab, WL)
    with pytest.raises(ls.LayerstackError, match="LambertianBackground"):
        g.measure(ls.Stack(1.0, [ls.Layer(1.5, 100.0)], ls.LambertianBackground(1.5, 0.8)), WL)


def test_transmission_fit_recovers_a_free_standing_film():
    """ψ_t/Δ_t of a free-standing film (made by tmm) fitted: thickness and index recovered."""
    import fitting as ft

    wl = np.linspace(400.0, 800.0, 17)
    angles = np.array([30.0, 50.0, 70.0])
    rho = _tmm_ratio(1.0, [(2.02, 350.0)], 1.0, angles, wl)
    data = {"psi": np.rad2deg(np.arctan(np.abs(rho))), "delta": -np.rad2deg(np.angle(rho))}
    start = ls.Stack(1.0, [ls.Layer(ls.Cauchy(1.95, 0.0), 330.0, name="film")], ls.Substrate(1.0))
    datasets = [ft.Dataset(ls.Ellipsometric(jnp.asarray(angles), q, mode="transmission"), data[q], sigma=0.01)
                for q in ("psi", "delta")]
    params = [ft.thickness("film", lower=100.0, upper=600.0), ft.dispersion("film", "A", lower=1.5, upper=2.5)]
    result = ft.fit(ft.Objective(start, wl, datasets, params))
    assert result.converged, result.report()
    d, A = (float(np.squeeze(v)) for v in result.values.values())
    assert abs(d - 350.0) < 1e-5 and abs(A - 2.02) < 1e-7
