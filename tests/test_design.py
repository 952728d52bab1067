"""Coating design (fitting/_design.py) against closed forms, tmm and colour-science.

References: quarter-wave AR and (HL)^N H reflector closed forms (Macleod, *Thin-Film Optical
Filters*, ch. 4 and 6), ``tmm.coh_tmm`` on the designed stacks, colour-science's own
``sd_to_XYZ`` / ``delta_E`` for the colour target, and a Gaussian-probability yield computed from
``tmm`` with scipy root finding.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
import tmm
from scipy.optimize import brentq
from scipy.stats import norm

import layerstack_jax as ls
from fitting import _design as D
from fitting import _design_targets as T
from fitting import _needle as N

INF = np.inf


def _tmm_R(n_list, d_list, wl, angle_rad=0.0):
    """Natural-light reflectance from tmm.coh_tmm (independent reference)."""
    return 0.5 * sum(tmm.coh_tmm(p, n_list, d_list, angle_rad, wl)["R"] for p in "sp")


def test_quarter_wave_single_layer_ar():
    """MgF2 (Li 1980, database) on glass n_s = 1.52: d = λ0/(4 n1) within 0.1 nm and
    R_min = ((n0 n_s − n1²)/(n0 n_s + n1²))²."""
    mgf2 = ls.material("MgF2", "Li-o")
    lam0, ns = 550.0, 1.52
    n1 = float(np.real(mgf2(np.array([lam0]))[0]))
    stack = ls.Stack(1.0, [ls.Layer(mgf2, 80.0)], ls.Substrate(ns))
    target = T.SpectralTarget(jnp.array([lam0]), 0.0, 0.01)
    res = D.optimize_thicknesses(stack, [target], bounds_nm=(0.0, 180.0))
    assert res.converged, res.message
    assert abs(res.thickness_nm[0] - lam0 / (4 * n1)) < 0.1
    R_min = ((ns - n1**2) / (ns + n1**2)) ** 2
    R = float(target.evaluate(res.stack)[0, 0])
    assert abs(R - R_min) < 1e-9
    assert abs(_tmm_R([1.0, n1, ns], [INF, res.thickness_nm[0], INF], lam0) - R_min) < 1e-9


@pytest.mark.parametrize("pairs", [1, 3, 6])
def test_quarter_wave_high_reflector_peak_closed_form(pairs):
    """(HL)^N H on glass at λ0: R = ((1 − Y)/(1 + Y))², Y = (n_H/n_L)^(2N) n_H²/n_s."""
    lam0, nH, nL, ns = 600.0, 2.35, 1.46, 1.52
    layers = []
    for _ in range(pairs):
        layers += [ls.Layer(nH, lam0 / (4 * nH)), ls.Layer(nL, lam0 / (4 * nL))]
    layers.append(ls.Layer(nH, lam0 / (4 * nH)))
    stack = ls.Stack(1.0, layers, ls.Substrate(ns))
    Y = (nH / nL) ** (2 * pairs) * nH**2 / ns
    R_closed = ((1 - Y) / (1 + Y)) ** 2
    R = float(T.SpectralTarget(jnp.array([lam0]), 1.0).evaluate(stack)[0, 0])
    assert abs(R - R_closed) < 1e-12


def test_design_recovers_quarter_wave_reflector_from_a_perturbed_start():
    """Maximising R at λ0 ('above' target) from ±15 % thickness errors returns to the quarter waves."""
    lam0, nH, nL, ns = 600.0, 2.35, 1.46, 1.52
    qw = np.array([lam0 / (4 * nH), lam0 / (4 * nL), lam0 / (4 * nH)])
    start = qw * np.array([1.15, 0.87, 1.1])
    stack = ls.Stack(1.0, [ls.Layer(n, d) for n, d in zip((nH, nL, nH), start)], ls.Substrate(ns))
    res = D.optimize_thicknesses(stack, [T.SpectralTarget(jnp.array([lam0]), 1.0, 0.01, kind="above")],
                                 bounds_nm=(20.0, 150.0))
    assert res.converged, res.message
    assert np.max(np.abs(res.thickness_nm - qw)) < 0.05


def test_needle_function_is_the_derivative_of_the_merit():
    """Needle function against a one-sided 2nd-order finite difference in the needle thickness."""
    wl = jnp.linspace(450.0, 650.0, 21)
    target = T.SpectralTarget(wl, 0.0, 0.005)
    stack = ls.Stack(1.0, [ls.Layer(1.38, 95.6), ls.Layer(2.35, 113.1)], ls.Substrate(1.52))
    materials = [1.38, 2.35]
    scan = N.needle_function(stack, [target], materials, points_per_layer=4)
    assert scan.derivative.shape == (2, 1 + 2 * 4)
    h = 1e-3
    for m, p in [(0, 0), (1, 3), (0, 6), (1, 8)]:
        j, f = int(scan.layer[p]), float(scan.fraction[p])
        M = [float(T.merit(N._split_with_needle(stack, j, f, materials[m], k * h), [target])) for k in range(3)]
        fd = (-3 * M[0] + 4 * M[1] - M[2]) / (2 * h)
        assert abs(scan.derivative[m, p] - fd) <= 1e-5 * max(1.0, abs(fd))


def test_broadband_ar_with_database_materials_and_needles():
    """Mean R < 0.5 % over 450–650 nm at normal incidence with <= 6 layers of SiO2 / TiO2
    (database); needles improve the 2-layer start. R of the final design checked with tmm."""
    sio2, tio2 = ls.material("SiO2", "Malitson"), ls.material("TiO2", "Devore-o")
    wl = jnp.linspace(450.0, 650.0, 21)
    target = T.SpectralTarget(wl, 0.0, 0.005)
    start = ls.Stack(1.0, [ls.Layer(sio2, 100.0), ls.Layer(tio2, 100.0)], ls.Substrate(1.52))
    # host L-BFGS-B: one compile of merit + gradient per layout instead of one jaxopt solver
    # each (the jaxopt path is exercised by the other tests of this file)
    two = D.optimize_thicknesses(start, [target], bounds_nm=(0.0, 400.0), method="scipy")
    result, history = N.needle_design(start, [target], [sio2, tio2], iterations=2, max_layers=6,
                                      bounds_nm=(0.0, 400.0), points_per_layer=16, method="scipy")
    assert len(result.stack.layers) <= 6
    assert result.merit < 0.5 * two.merit  # the needles helped
    merits = [h["merit"] for h in history if "removed_thin_layers" not in h]  # needle steps only
    assert merits == sorted(merits, reverse=True)
    assert not [layer for layer in result.stack.layers if float(layer.thickness) < 0.5]  # min_thickness_nm
    wls = np.asarray(wl)
    Rs = []
    for lam in wls:
        n = [1.0] + [complex(np.asarray(layer.index(np.array([lam])))[0]) for layer in result.stack.layers] + [1.52]
        d = [INF] + [float(layer.thickness) for layer in result.stack.layers] + [INF]
        Rs.append(_tmm_R(n, d, lam))
    assert np.mean(Rs) < 0.005, np.mean(Rs)


def test_colour_target_dielectric_metal_dielectric():
    """Hirayama et al. Table 1 teapot stack (n = 1.4 / Ag 5 nm / n = 1.4 on Al), dielectric
    thicknesses designed to a Lab colour within ΔE2000 < 0.5 — checked with colour-science."""
    colour = pytest.importorskip("colour")
    ag, al = ls.material("Ag", "Johnson"), ls.material("Al", "Rakic")
    wl = np.arange(380.0, 781.0, 5.0)
    cs = ls.ColourSpace(wl)
    d65 = colour.SDS_ILLUMINANTS["D65"]

    def lab_colour_science(stack):
        R = np.asarray(ls.specular(stack, jnp.asarray(wl), 0.0).natural().R_front)
        XYZ = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(wl, R))), illuminant=d65, method="Integration") / 100
        white = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(wl, np.ones_like(wl)))), illuminant=d65,
                                method="Integration")
        return colour.XYZ_to_Lab(XYZ, colour.XYZ_to_xy(white / 100))

    def teapot(d1, d2):
        return ls.Stack(1.0, [ls.Layer(1.4, d1), ls.Layer(ag, 5.0), ls.Layer(1.4, d2)], ls.Substrate(al))

    # a colour this stack can show (computed with colour-science), approached from elsewhere
    target_lab = lab_colour_science(teapot(180.0, 320.0))
    target = T.ColourTarget(cs, target_lab, 0.0, tolerance=0.5)
    res = D.optimize_thicknesses(teapot(250.0, 250.0), [target], free=[0, 2], bounds_nm=(50.0, 600.0),
                                 n_starts=16, seed=1)
    lab = lab_colour_science(res.stack)
    dE = float(colour.delta_E(lab, target_lab, method="CIE 2000"))
    assert dE < 0.5, (dE, lab, res.thickness_nm)


def test_yield_matches_gaussian_probability_from_tmm():
    """Single-layer AR, spec R(550 nm) <= 1.27 %, thickness error N(0, 3 nm): the Monte-Carlo
    yield equals Φ(b/σ) − Φ(a/σ), with [a, b] the in-spec thickness interval found on tmm."""
    n1, ns, lam, Rmax, sigma = 1.38, 1.52, 550.0, 0.0127, 3.0
    d0 = lam / (4 * n1)
    stack = ls.Stack(1.0, [ls.Layer(n1, d0)], ls.Substrate(ns))
    spec = T.SpectralTarget(jnp.array([lam]), Rmax, 1e-9, kind="below")

    def excess(delta):
        return _tmm_R([1.0, n1, ns], [INF, d0 + delta, INF], lam) - Rmax

    a, b = brentq(excess, -40.0, 0.0, xtol=1e-10), brentq(excess, 0.0, 40.0, xtol=1e-10)
    expected = norm.cdf(b / sigma) - norm.cdf(a / sigma)
    y = D.thickness_yield(stack, [spec], D.RobustSpec(sigma_nm=sigma, samples=4000, seed=3))
    se = math.sqrt(expected * (1 - expected) / 4000)
    assert 0.05 < expected < 0.95
    assert abs(y.fraction - expected) < 4 * se, (y.fraction, expected)


def test_robust_design_lowers_the_expected_merit():
    """Optimising the expected merit under 3 nm errors gives a design whose expected merit (on
    fresh draws) is lower than that of the nominal optimum."""
    wl = jnp.linspace(450.0, 650.0, 11)
    target = T.SpectralTarget(wl, 0.0, 0.005)
    stack = ls.Stack(1.0, [ls.Layer(1.38, 95.0), ls.Layer(2.1, 30.0), ls.Layer(1.38, 90.0)], ls.Substrate(1.52))
    errors = D.RobustSpec(sigma_nm=3.0, samples=32, seed=0)
    nominal = D.optimize_thicknesses(stack, [target], bounds_nm=(0.0, 300.0))
    robust = D.optimize_thicknesses(nominal.stack, [target], bounds_nm=(0.0, 300.0), robust=errors)
    fresh = D.RobustSpec(sigma_nm=3.0, samples=400, seed=99)
    m_nom = D.thickness_yield(nominal.stack, [target], fresh).merits.mean()
    m_rob = D.thickness_yield(robust.stack, [target], fresh).merits.mean()
    assert m_rob < m_nom


def test_bad_design_input():
    wl = jnp.array([500.0, 600.0])
    stack = ls.Stack(1.0, [ls.Layer(1.38, 100.0)], ls.Substrate(1.52))
    ok = T.SpectralTarget(wl, 0.0)
    with pytest.raises(ls.LayerstackError, match="tolerance"):
        T.SpectralTarget(wl, 0.0, 0.0)
    with pytest.raises(ls.LayerstackError, match="quantity"):
        T.SpectralTarget(wl, 0.0, quantity="X")
    with pytest.raises(ls.LayerstackError, match="angle_deg"):
        T.SpectralTarget(wl, 0.0, angle_deg=95.0)
    with pytest.raises(ls.LayerstackError, match="broadcast"):
        T.SpectralTarget(wl, np.zeros(3))
    with pytest.raises(ls.LayerstackError, match="inverted"):
        D.optimize_thicknesses(stack, [ok], bounds_nm=(200.0, 100.0))
    with pytest.raises(ls.LayerstackError, match="out of range"):
        D.optimize_thicknesses(stack, [ok], free=[3])
    with pytest.raises(ls.LayerstackError, match="outside the bounds"):
        D.optimize_thicknesses(stack, [ok], bounds_nm=(0.0, 50.0))
    with pytest.raises(ls.LayerstackError, match="at least one target"):
        T.merit(stack, [])


# ------------------------------------------------------------------ issue 18, row 10
def _readme_needle_case():
    """The user guide's call (docs/guide/fitting.md): 2 layers (SiO2 / TiO2, database), a 27-wavelength AR target."""
    sio2, tio2 = ls.material("SiO2", "Malitson"), ls.material("TiO2", "Devore-o")
    wl = jnp.linspace(450.0, 650.0, 27)
    stack = ls.Stack(1.0, [ls.Layer(sio2, 100.0), ls.Layer(tio2, 100.0)], ls.Substrate(1.52))
    return stack, [T.SpectralTarget(wl, 0.0, 0.005)], [sio2, tio2]


def _thin(stack, min_nm):
    return [float(layer.thickness) for layer in stack.layers if layer.coherent and float(layer.thickness) < min_nm]


def test_min_thickness_holds_on_the_final_design():
    """A refined design that still holds layers of 0.16 and 0.67 nm (what the user got with
    min_thickness_nm = 0.5): the final design drops them and is refined again."""
    wl = jnp.linspace(450.0, 650.0, 5)
    targets = [T.SpectralTarget(wl, 0.0, 0.005)]
    thin = ls.Stack(1.0, [ls.Layer(1.46, 90.0), ls.Layer(2.35, 0.16), ls.Layer(1.46, 0.67), ls.Layer(2.35, 20.0)],
                    ls.Substrate(1.52))

    def refine(st):
        return D.optimize_thicknesses(st, targets, bounds_nm=(0.0, 400.0), method="scipy")

    history = []
    start = refine(thin)._replace(stack=thin)
    final = N._enforce_min_thickness(start, 0.5, refine, history)
    assert not _thin(final.stack, 0.5)
    assert len(final.stack.layers) <= 3 and history and history[0]["removed_thin_layers"] >= 1


def test_needle_design_shows_progress_and_keeps_min_thickness(capsys):
    """A short needle design (constant indices, host L-BFGS-B): a progress bar on stderr, no
    layer thinner than min_thickness_nm in the result."""
    wl = jnp.linspace(450.0, 650.0, 9)
    stack = ls.Stack(1.0, [ls.Layer(1.46, 100.0), ls.Layer(2.35, 100.0)], ls.Substrate(1.52))
    result, history = N.needle_design(stack, [T.SpectralTarget(wl, 0.0, 0.005)], [1.46, 2.35], iterations=1,
                                      points_per_layer=4, bounds_nm=(0.0, 400.0), min_thickness_nm=0.5,
                                      method="scipy")
    assert not _thin(result.stack, 0.5)
    assert result.merit <= history[0]["merit"]
    err = capsys.readouterr().err
    assert "needle design" in err and "merit" in err


@pytest.mark.slow
def test_needle_design_readme_call_as_the_user_made_it(capsys):
    """Exactly the guide's call (2 database layers, 27 λ; compiled L-BFGS-B, 5 iterations, 32
    points per layer): minutes of compilation, now with a progress bar, and the final design
    keeps min_thickness_nm."""
    stack, targets, materials = _readme_needle_case()
    result, _ = N.needle_design(stack, targets, materials)
    assert not _thin(result.stack, 0.5)
    assert "needle design" in capsys.readouterr().err


def test_targets_at_oblique_angles_are_evaluated_at_those_angles():
    """Targets take degrees (``angle_deg``), evaluated by tmm at the same angles: an AR target at
    30° was once evaluated at 30° read as radians (0.52°), silently designing for normal incidence."""
    import warnings

    wl = np.array([450.0, 550.0, 650.0])
    angles = np.array([0.0, 30.0, 60.0])
    stack = ls.Stack(1.0, [ls.Layer(2.1, 70.0), ls.Layer(1.38, 95.0)], ls.Substrate(1.52))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "radians given?" warning
        R = np.asarray(T.SpectralTarget(jnp.asarray(wl), 0.0, 0.01, angle_deg=angles).evaluate(stack))
    ref = np.array([[_tmm_R([1.0, 2.1, 1.38, 1.52], [INF, 70.0, 95.0, INF], lam, math.radians(a)) for lam in wl]
                    for a in angles])
    np.testing.assert_allclose(R, ref, rtol=1e-12)
    # the colour target too: CIELAB of tmm's reflectance at 45°
    cs = ls.ColourSpace(np.linspace(380.0, 780.0, 41))
    lab = np.asarray(T.ColourTarget(cs, np.zeros(3), 45.0).evaluate(stack))[0]
    R45 = np.array([_tmm_R([1.0, 2.1, 1.38, 1.52], [INF, 70.0, 95.0, INF], lam, math.radians(45.0))
                    for lam in np.asarray(cs.wavelength_nm)])
    np.testing.assert_allclose(lab, np.asarray(cs.Lab(jnp.asarray(R45))), atol=1e-9)
