"""Ellipsometer non-idealities (issue 15): angle-of-incidence offset, spectral bandwidth,
thickness non-uniformity and the depolarization they cause — values, gradients and fits.

References are independent of the averaging code under test: a one-film Airy formula written
here in numpy (itself checked against ``tmm.ellips``), averaged by dense trapezoidal quadrature
over the Gaussian (1601 points over ±8σ), and ψ, Δ, depolarization recomputed from those
averages with the formulas of the module docstring written here in numpy. Nothing expected is
computed by ``Ellipsometric`` or ``averaged_ncs``.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tmm

import fitting as ft
import layerstack_jax as ls

N_AMB, N_FILM, N_SUB = 1.0, 1.46, complex(3.88, 0.02)  # non-dispersive: the reference needs no tables
D_FILM = 100.0  # nm
WL = np.array([400.0, 500.0, 633.0])
ANGLES = np.array([65.0, 70.0, 75.0])
FWHM = 2.0 * math.sqrt(2.0 * math.log(2.0))  # FWHM / sigma of a Gaussian


def _stack(d=D_FILM):
    return ls.Stack(ambient=ls.Index(N_AMB, 0.0),
                    layers=[ls.Layer(ls.Index(N_FILM, 0.0), d, name="film")],
                    exit=ls.Substrate(ls.Index(N_SUB.real, N_SUB.imag)))


# ------------------------------------------------------------------ numpy reference
def _airy(d, wl, theta_deg):
    """(r_s, r_p) of ambient | film d | substrate (numpy, e^{-iωt}, n + ik, Born & Wolf signs),
    broadcast over d, wl (nm) and theta (degrees)."""
    kx = N_AMB * np.sin(np.deg2rad(theta_deg))
    n = [complex(N_AMB), complex(N_FILM), N_SUB]
    q = [np.sqrt(m * m - kx * kx + 0j) for m in n]
    q = [np.where(np.imag(x) < 0, -x, x) for x in q]

    def rs(i, j):
        return (q[i] - q[j]) / (q[i] + q[j])

    def rp(i, j):
        return (n[j] ** 2 * q[i] - n[i] ** 2 * q[j]) / (n[j] ** 2 * q[i] + n[i] ** 2 * q[j])

    phase = np.exp(2j * (2 * np.pi * np.asarray(d) * q[1] / np.asarray(wl)))
    film = lambda r01, r12: (r01 + r12 * phase) / (1 + r01 * r12 * phase)  # noqa: E731
    return film(rs(0, 1), rs(1, 2)), film(rp(0, 1), rp(1, 2))


def _ncs(r_s, r_p):
    """N, C, S from psi = atan|rho|, Delta = -arg(rho) (the instruments' Delta)."""
    rho = r_p / r_s
    psi, delta = np.arctan(np.abs(rho)), -np.angle(rho)
    return np.cos(2 * psi), np.sin(2 * psi) * np.cos(delta), np.sin(2 * psi) * np.sin(delta)


def _gauss_mean(values, axis):
    """Mean over a standard normal variable sampled on X_DENSE along ``axis`` (trapezoid)."""
    w = np.exp(-X_DENSE ** 2 / 2) / math.sqrt(2 * math.pi) * (X_DENSE[1] - X_DENSE[0])
    shape = [1] * values.ndim
    shape[axis] = -1
    return np.sum(values * w.reshape(shape), axis=axis)


X_DENSE = np.linspace(-8.0, 8.0, 1601)


def _reported(N, C, S):
    """psi, Delta (degrees) and depolarization from averaged N, C, S (module docstring)."""
    psi = 0.5 * np.degrees(np.arctan2(np.hypot(C, S), N))
    delta = np.degrees(np.arctan2(S, C))
    return psi, delta, 1.0 - np.sqrt(N * N + C * C + S * S)


def _reference(bandwidth_nm=0.0, spread=0.0, angles=ANGLES):
    """Dense-quadrature reference reading, each field (angle, wl)."""
    sig = bandwidth_nm / FWHM
    # axes: (thickness node, wavelength node, angle, wl)
    d = D_FILM * (1 + spread * X_DENSE)[:, None, None, None]
    wl = WL[None, None, None, :] + sig * X_DENSE[None, :, None, None]
    if bandwidth_nm == 0:
        wl = wl[:, :1]
    if spread == 0:
        d = d[:1]
    ncs = _ncs(*_airy(d, wl, np.asarray(angles)[None, None, :, None]))
    out = []
    for v in ncs:
        v = _gauss_mean(v, 1) if bandwidth_nm else v[:, 0]
        v = _gauss_mean(v, 0) if spread else v[0]
        out.append(v)
    return tuple(out)


def test_airy_reference_matches_tmm_ellips():
    """The numpy reference itself: psi equal to tmm.ellips, Delta = 180 deg - Delta_tmm."""
    r_s, r_p = _airy(D_FILM, WL[:, None], ANGLES[None, :])
    rho = r_p / r_s
    for i, wl in enumerate(WL):
        for j, a in enumerate(ANGLES):
            e = tmm.ellips([N_AMB, N_FILM, N_SUB], [np.inf, D_FILM, np.inf], np.deg2rad(a), wl)
            assert np.arctan(abs(rho[i, j])) == pytest.approx(e["psi"], abs=1e-12)
            d = np.angle(np.exp(1j * (np.pi - e["Delta"])))
            assert np.angle(np.exp(1j * (-np.angle(rho[i, j]) - d))) == pytest.approx(0.0, abs=1e-12)


# ------------------------------------------------------------------ physics
@pytest.mark.parametrize("quantity", ["psi", "delta", "N", "C", "S", "rho_re", "rho_im"])
def test_defaults_read_exactly_as_ellipsometry(quantity):
    """The default geometry (no offset, bandwidth or spread) is bit-identical to ls.ellipsometry."""
    st = _stack()
    e = ls.ellipsometry(st, WL, ANGLES)
    want = {"psi": e.psi_deg, "delta": e.delta_deg, "N": e.N, "C": e.C, "S": e.S,
            "rho_re": jnp.real(e.rho), "rho_im": jnp.imag(e.rho)}[quantity]
    got = ls.Ellipsometric(ANGLES, quantity).measure(st, WL)
    assert np.array_equal(np.asarray(got), np.asarray(want))
    assert np.array_equal(np.asarray(ls.Ellipsometric(ANGLES, "depolarization").measure(st, WL)),
                          np.zeros((3, 3)))


def test_angle_offset_is_the_model_at_the_shifted_angle():
    """Offset δθ: every reading is the ideal one at θ + δθ (closed form, and the numpy Airy)."""
    st = _stack()
    e = ls.ellipsometry(st, WL, ANGLES + 0.3)
    for q, want in (("psi", e.psi_deg), ("delta", e.delta_deg), ("N", e.N), ("S", e.S)):
        got = ls.Ellipsometric(ANGLES, q, angle_offset_deg=0.3).measure(st, WL)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    N, C, S = _reference(angles=ANGLES + 0.3)
    np.testing.assert_allclose(ls.Ellipsometric(ANGLES, "C", angle_offset_deg=0.3).measure(st, WL), C,
                               atol=1e-12)
    assert not np.allclose(ls.Ellipsometric(ANGLES, "psi").measure(st, WL), e.psi_deg, atol=1e-3)


def _check_against_reference(geometry_kw, bandwidth_nm, spread):
    st = _stack()
    N, C, S = _reference(bandwidth_nm, spread)
    psi, delta, dep = _reported(N, C, S)
    for q, want, tol in (("N", N, 1e-6), ("C", C, 1e-6), ("S", S, 1e-6), ("psi", psi, 1e-6),
                         ("delta", delta, 1e-6), ("depolarization", dep, 1e-6),
                         ("rho_re", np.tan(np.deg2rad(psi)) * np.cos(np.deg2rad(delta)), 1e-6)):
        got = ls.Ellipsometric(ANGLES, q, **geometry_kw).measure(st, WL)
        np.testing.assert_allclose(np.asarray(got), want, rtol=0, atol=tol, err_msg=q)
    return dep


def test_bandwidth_matches_dense_quadrature():
    """FWHM 20 nm Gaussian band: averaged N, C, S, reported psi, Delta, depolarization ≤ 1e-6."""
    dep = _check_against_reference(dict(bandwidth_nm=20.0), 20.0, 0.0)
    assert dep.max() > 1e-4  # the band does depolarize


@pytest.mark.parametrize("layer", ["film", 0])
def test_thickness_spread_matches_dense_quadrature(layer):
    """5 % Gaussian thickness spread of the film (by name or position) ≤ 1e-6."""
    dep = _check_against_reference(dict(thickness_spread=0.05, nonuniform_layer=layer), 0.0, 0.05)
    assert dep.max() > 1e-3


def test_bandwidth_and_spread_together_match_dense_quadrature():
    """Both at once (a 2-D average over wavelength and thickness), with an angle offset."""
    st = _stack()
    N, C, S = _reference(10.0, 0.04, angles=ANGLES + 0.2)
    got = ls.Ellipsometric(ANGLES, "psi", angle_offset_deg=0.2, bandwidth_nm=10.0, thickness_spread=0.04,
                           nonuniform_layer="film").reading(st, WL)
    for g, w in zip((got.N, got.C, got.S, got.psi_deg, got.delta_deg), (N, C, S) + _reported(N, C, S)[:2]):
        np.testing.assert_allclose(np.asarray(g), w, rtol=0, atol=1e-6)


def test_depolarization_is_a_fraction_that_grows_with_the_spread():
    st = _stack()
    spreads = [0.0, 0.01, 0.03, 0.05, 0.1, 0.12]
    deps = np.stack([np.asarray(ls.Ellipsometric(ANGLES, "depolarization", thickness_spread=s,
                                                 nonuniform_layer="film").measure(st, WL)) for s in spreads])
    assert np.all((deps >= 0) & (deps <= 1))
    assert np.all(deps[0] == 0)
    assert np.all(np.diff(deps, axis=0) > 0)


def test_bad_non_ideality_inputs_are_named():
    with pytest.raises(ls.LayerstackError, match="nonuniform_layer"):
        ls.Ellipsometric(70.0, "psi", thickness_spread=0.05)
    with pytest.raises(ls.LayerstackError, match="thickness_spread"):
        ls.Ellipsometric(70.0, "psi", thickness_spread=0.3, nonuniform_layer="film")
    with pytest.raises(Exception, match="bandwidth_nm"):
        ls.Ellipsometric(70.0, "psi", bandwidth_nm=-1.0)
    with pytest.raises(ls.LayerstackError, match="no_such"):
        ls.Ellipsometric(70.0, "psi", thickness_spread=0.05, nonuniform_layer="no_such").measure(_stack(), WL)
    assert ls.parse_geometry("ellipsometry:70:depolarization").quantity == "depolarization"


@pytest.mark.parametrize("field, value", [("angle_offset_deg", 0.3), ("bandwidth_nm", 12.0),
                                          ("thickness_spread", 0.05)])
def test_gradients_of_psi_equal_finite_differences(field, value):
    """d psi / d (offset, bandwidth, spread) by JAX vs central differences, rel 1e-5."""
    st = _stack()
    base = dict(angle_offset_deg=0.1, bandwidth_nm=5.0, thickness_spread=0.03)

    @jax.jit
    def psi(v):
        kw = dict(base, **{field: v})
        return ls.Ellipsometric(ANGLES, "psi", nonuniform_layer="film", **kw).measure(st, WL)

    g = np.asarray(jax.jacfwd(psi)(jnp.asarray(value)))
    h = 1e-4 * value
    fd = (np.asarray(psi(jnp.asarray(value + h))) - np.asarray(psi(jnp.asarray(value - h)))) / (2 * h)
    assert np.all(np.isfinite(g)) and np.abs(g).min() > 0
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-9 * np.abs(fd).max())


# ------------------------------------------------------------------ fitting
def _synthetic(wl, offset=0.3, spread=0.05, d=D_FILM):
    st = _stack(d)
    out = []
    for a in ANGLES:
        for q in ("psi", "delta"):
            g = ls.Ellipsometric(float(a), q, angle_offset_deg=offset, thickness_spread=spread, nonuniform_layer="film")
            out.append((float(a), q, np.asarray(g.measure(st, wl))))
    return out


def test_fit_recovers_angle_offset_and_thickness_spread():
    """One angle offset shared by the datasets of three angles, the spread and the thickness,
    fitted from noise-free synthetic psi/Delta: recovered to rel 1e-3."""
    wl = np.linspace(400.0, 700.0, 6)
    data = _synthetic(wl)
    # starts: offset 0 and spread 0.03 (from the geometries), thickness 98 nm. The spread starts
    # above 0: the reading is even in it, so its derivative vanishes at 0 (from 0.02 with a
    # 95 nm start, lm drives it onto its lower bound 0 and stops at offset 0.48).
    datasets = [ft.Dataset(ls.Ellipsometric(a, q, thickness_spread=0.03, nonuniform_layer="film"), y, sigma=0.01)
                for a, q, y in data]
    params = [ft.instrument("angle_offset_deg", lower=-2.0, upper=2.0),
              ft.instrument("thickness_spread", lower=0.0, upper=0.12),
              ft.thickness("film", value=98.0, lower=50.0, upper=150.0)]
    obj = ft.Objective(_stack(98.0), wl, datasets, params)
    assert obj.layout.params[0].path == ("datasets", tuple(range(6)), "angle_offset_deg")
    res = ft.fit(obj)
    assert res.converged
    assert res.values["angle_offset_deg"] == pytest.approx(0.3, rel=1e-3)
    assert res.values["thickness_spread"] == pytest.approx(0.05, rel=1e-3)
    assert res.values["thickness[film]"] == pytest.approx(D_FILM, rel=1e-3)


def test_instrument_parameter_on_chosen_datasets_and_errors():
    wl = np.array([450.0, 600.0])
    data = _synthetic(wl, offset=0.0, spread=0.0)
    datasets = [ft.Dataset(ls.Ellipsometric(a, q), y) for a, q, y in data]
    # one offset on datasets 0 and 1 only: the prediction equals the model at 65.4 deg there
    obj = ft.Objective(_stack(), wl, datasets, [ft.instrument("angle_offset_deg", (0, 1), value=0.4)])
    pred = obj.predict(jnp.asarray(obj.layout.x0))
    e = ls.ellipsometry(_stack(), wl, 65.4)
    np.testing.assert_allclose(pred[0][0], e.psi_deg, atol=1e-12)
    np.testing.assert_allclose(pred[1][0], e.delta_deg, atol=1e-12)
    np.testing.assert_allclose(pred[2][0], data[2][2], atol=1e-12)  # dataset 2 untouched
    with pytest.raises(ls.LayerstackError, match="no_field"):
        ft.Objective(_stack(), wl, datasets, [ft.instrument("no_field")])
    with pytest.raises(ls.LayerstackError, match="no dataset 9"):
        ft.Objective(_stack(), wl, datasets, [ft.instrument("angle_offset_deg", 9)])
    with pytest.raises(ls.LayerstackError, match="freed twice"):
        ft.Objective(_stack(), wl, datasets, [ft.instrument("angle_offset_deg", 0),
                                              ft.instrument("angle_offset_deg", (0, 1))])
    mixed = [ft.Dataset(ls.Ellipsometric(65.0, "psi", angle_offset_deg=0.1), data[0][2]), datasets[2]]
    with pytest.raises(ls.LayerstackError, match="give value="):
        ft.Objective(_stack(), wl, mixed, [ft.instrument("angle_offset_deg")])


def test_bandwidth_beyond_a_material_table_is_refused_when_the_objective_is_built():
    """The bandwidth average reads λ ± 7.85 σ_λ (21 Gauss–Hermite nodes): a table ending at the
    model grid's edge is refused when the Objective is built, naming the dataset and the span —
    for a fixed bandwidth, and for a free one at its upper bound — not inside the solve."""
    table = ls.Tabulated(np.array([400.0, 600.0, 800.0]), np.array([3.9, 3.9, 3.7]), np.array([0.02, 0.02, 0.01]),
                         name="tab")
    stack = ls.Stack(N_AMB, [ls.Layer(N_FILM, D_FILM, coherent=True, name="film")], ls.Substrate(table))
    grid = np.array([420.0, 600.0, 780.0])  # 20 nm inside the table at both ends
    data = np.zeros(grid.size)
    params = [ft.thickness("film")]

    def build(geometry, extra=()):
        return ft.Objective(stack, grid, ft.Dataset(geometry, data), params + list(extra))

    build(ls.Ellipsometric(70.0, "psi"))  # ideal: reads the grid only
    build(ls.Ellipsometric(70.0, "psi", bandwidth_nm=2.0))  # reach 6.7 nm: inside the table
    with pytest.raises(ls.LayerstackError, match=r"ellipsometry:70:psi.*reads 353.*846.*tab.*400–800 nm") as info:
        build(ls.Ellipsometric(70.0, "psi", bandwidth_nm=20.0))  # reach 66.7 nm
    assert "bandwidth" in str(info.value)
    build(ls.Ellipsometric(70.0, "psi", bandwidth_nm=1.0), [ft.instrument("bandwidth_nm", lower=0.0, upper=2.0)])
    with pytest.raises(ls.LayerstackError, match="bandwidth"):
        build(ls.Ellipsometric(70.0, "psi", bandwidth_nm=1.0), [ft.instrument("bandwidth_nm", lower=0.0, upper=20.0)])
