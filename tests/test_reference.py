"""Tests of the independent references in tests/reference.py (numpy / scipy / tmm only).

These check the yardstick itself: closed forms against quadrature, published values,
energy conservation, reciprocity, inversion round trips, special-case reductions, and the
tmm quirks the wrappers work around.
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np
import pytest
import tmm

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import reference as ref  # noqa: E402

INF = np.inf
LAM = 550.0


# ----------------------------------------------------------------------------- Fresnel
def test_fresnel_normal_incidence_and_tir():
    for n1, n2 in [(1.0, 1.5), (1.5, 1.0), (1.33, 2.0)]:
        Rs, Rp, Rn = ref.fresnel_natural_R(n1, n2, 0.0)
        r0 = ((n1 - n2) / (n1 + n2)) ** 2
        assert Rs == pytest.approx(r0, abs=1e-16)
        assert Rp == pytest.approx(r0, abs=1e-16)
        assert Rn == pytest.approx(r0, abs=1e-16)
    th_c = math.asin(1.0 / 1.5)
    Rs, Rp, Rn = ref.fresnel_natural_R(1.5, 1.0, np.array([th_c + 1e-9, 1.0, 1.5]))
    assert np.all(Rs == 1.0) and np.all(Rp == 1.0) and np.all(Rn == 1.0)
    # Brewster angle: R_p = 0
    assert ref.fresnel_natural_R(1.0, 1.5, math.atan(1.5))[1] < 1e-30
    # grazing external incidence reflects everything
    assert ref.fresnel_natural_R(1.0, 1.5, 0.5 * math.pi)[2] == pytest.approx(1.0, abs=1e-15)


def test_fresnel_matches_tmm_and_eqs_2_3_and_reciprocity():
    n1, n2 = 1.0, 1.5
    for th in [0.1, 0.5, 0.9, 1.3]:
        th2 = math.asin(n1 * math.sin(th) / n2)
        Rs, Rp, _ = ref.fresnel_natural_R(n1, n2, th)
        # tan / sin forms, eqs. (2)-(3)
        assert Rp == pytest.approx(math.tan(th - th2) ** 2 / math.tan(th + th2) ** 2, rel=1e-13)
        assert Rs == pytest.approx(math.sin(th - th2) ** 2 / math.sin(th + th2) ** 2, rel=1e-13)
        for pol, R in (("s", Rs), ("p", Rp)):
            Rt = tmm.interface_R(pol, n1, n2, th, th2)
            assert R == pytest.approx(Rt, abs=1e-15)
        # eq. (8): R_12(theta_1) = R_21(theta_2)
        back = ref.fresnel_natural_R(n2, n1, th2)
        assert back[0] == pytest.approx(Rs, abs=1e-15)
        assert back[1] == pytest.approx(Rp, abs=1e-15)


# ------------------------------------------------------------ diffuse interface (eq. 18)
@pytest.mark.parametrize("n", [1.33, 1.5, 2.0])
def test_closed_form_vs_quad(n):
    r_e, r_i = ref.diffuse_reflectance_interface_closed_form(n)
    for variable in ("mu", "theta"):
        assert abs(ref.diffuse_reflectance_interface(1.0, n, variable) - r_e) <= 1e-12
        assert abs(ref.diffuse_reflectance_interface(n, 1.0, variable) - r_i) <= 1e-12
    # the two quadratures (different variables, different maps) agree far below 1e-12
    a = ref.diffuse_reflectance_interface(n, 1.0, "mu")
    b = ref.diffuse_reflectance_interface(n, 1.0, "theta")
    assert abs(a - b) < 1e-14
    # scale invariance: only the ratio matters
    assert ref.diffuse_reflectance_interface(1.2, 1.2 * n) == pytest.approx(r_e, abs=1e-14)
    assert ref.diffuse_interface_closed(1.2 * n, 1.2) == pytest.approx(r_i, abs=1e-14)


def test_closed_form_wide_range():
    for m in [1.05, 1.2, 1.7, 2.5, 3.5]:
        r_e, r_i = ref.diffuse_reflectance_interface_closed_form(m)
        assert abs(ref.diffuse_reflectance_interface(1.0, m) - r_e) < 1e-13
        assert abs(ref.diffuse_reflectance_interface(m, 1.0) - r_i) < 1e-13


def test_judd_values_n15():
    r_e, r_i = ref.diffuse_reflectance_interface_closed_form(1.5)
    assert round(r_e, 4) == ref.JUDD_R_EXT_15
    assert round(r_i, 4) == ref.JUDD_R_INT_15
    assert abs(r_i - ref.R_INT_15_EXACT) < 1e-11
    assert abs(ref.diffuse_reflectance_interface(1.5, 1.0) - ref.R_INT_15_EXACT) < 1e-11


def test_quad_against_mpmath_50_digits():
    mp = pytest.importorskip("mpmath")
    mp.mp.dps = 40
    n1, n2 = mp.mpf("1.5"), mp.mpf(1)

    def R(mu):  # natural-light Fresnel as a function of mu = sin^2 theta
        c1 = mp.sqrt(1 - mu)
        c2sq = 1 - (n1 / n2) ** 2 * mu
        if c2sq <= 0:
            return mp.mpf(1)
        c2 = mp.sqrt(c2sq)
        rs = (n1 * c1 - n2 * c2) / (n1 * c1 + n2 * c2)
        rp = (n2 * c1 - n1 * c2) / (n2 * c1 + n1 * c2)
        return (rs**2 + rp**2) / 2

    mu_c = (n2 / n1) ** 2
    exact = mp.quad(R, [0, mu_c]) + (1 - mu_c)
    assert abs(float(exact) - ref.R_INT_15_EXACT) < 1e-12
    assert abs(ref.diffuse_reflectance_interface(1.5, 1.0) - float(exact)) < 1e-14
    assert abs(ref.diffuse_reflectance_interface_closed_form(1.5)[1] - float(exact)) < 1e-14


@pytest.mark.parametrize("n", [1.2, 1.33, 1.5, 2.0, 2.6])
def test_internal_external_relation(n):
    r_ext = ref.diffuse_reflectance_interface(1.0, n)
    r_int = ref.diffuse_reflectance_interface(n, 1.0)
    assert abs((1.0 - r_int) - (1.0 - r_ext) / n**2) < 1e-14


# ------------------------------------------------------------------- tmm wrappers
def test_inc_wrapper_normal_incidence_s_equals_p():
    n = [1.0, 1.5 + 1e-4j, 2.0 + 0.3j, 1.4, 1.33]
    d = [INF, 2e4, 80, 1e5, INF]
    c = ["i", "i", "c", "i", "i"]
    Rs, Ts = ref.inc_stack_R_T("s", n, d, c, 0.0, LAM)
    Rp, Tp = ref.inc_stack_R_T("p", n, d, c, 0.0, LAM)
    assert Rs == pytest.approx(Rp, abs=1e-15) and Ts == pytest.approx(Tp, abs=1e-15)
    Rs, Ts = ref.coh_stack_R_T("s", [1.0, 2.0 + 0.3j, 1.5], [INF, 80, INF], 0.0, LAM)
    Rp, Tp = ref.coh_stack_R_T("p", [1.0, 2.0 + 0.3j, 1.5], [INF, 80, INF], 0.0, LAM)
    assert Rs == pytest.approx(Rp, abs=1e-15) and Ts == pytest.approx(Tp, abs=1e-15)


def test_reciprocity_eq44():
    n = [1.0, 1.5 + 1e-4j, 2.0 + 0.5j, 1.4, 1.33]
    d = [INF, 2e4, 30, 1e5, INF]
    c = ["i", "i", "c", "i", "i"]
    for th in [0.1, 0.7, 1.2]:
        th2 = math.asin(math.sin(th) / 1.33)
        for pol in "sp":
            Tf = ref.inc_stack_R_T(pol, n, d, c, th, LAM)[1]
            Tb = ref.inc_stack_R_T(pol, n[::-1], d[::-1], c[::-1], th2, LAM)[1]
            assert abs(Tf - Tb) < 1e-14


def test_beer_recursion_matches_tmm_lossless_including_interior_tir():
    """Independent Simonot recursion (eqs. 59-60) vs tmm, with TIR inside the stack."""
    nl = [1.0, 1.5, 1.2, 1.6]
    d = [INF, 1e5, 1e5, INF]
    for nn in (nl, nl[::-1]):
        for pol in "spu":
            for th in np.linspace(0.0, 1.55, 63):
                a = ref.beer_stack_R_T(pol, nn, [0.0, 0.0], th)
                b = ref.inc_stack_R_T(pol, nn, d, ["i"] * 4, th, LAM)
                assert abs(a[0] - b[0]) < 1e-13 and abs(a[1] - b[1]) < 1e-13
                assert abs(b[0] + b[1] - 1.0) < 1e-14


def test_beer_vs_tmm_absorbing_is_first_order_in_k():
    """tmm's n + ik incoherent layer = Beer alpha = 4 pi k / lam up to O(k^2)."""
    d = 1e5
    k = 1e-7
    ah = 4 * math.pi * k * d / LAM
    for th in [0.0, 0.8, 1.3]:
        a = ref.beer_stack_R_T("u", [1.0, 1.5, 1.33], [ah], th)
        b = ref.inc_stack_R_T("u", [1.0, 1.5 + 1j * k, 1.33], [INF, d, INF], ["i"] * 3, th, LAM)
        assert abs(a[0] - b[0]) < 1e-13 and abs(a[1] - b[1]) < 1e-13


def test_tir_split_composition_reproduces_inc_tmm():
    """The algebra used past TIR (split at an incoherent medium) equals tmm where tmm works."""
    n = np.array([1.0, 1.5 + 1e-3j, 2.0 + 0.3j, 1.4, 1.33], dtype=complex)
    d = np.array([INF, 2e4, 80, 1e5, INF])
    c = ["i", "i", "c", "i", "i"]
    p = 3
    for pol in "sp":
        for th in [0.0, 0.4, 1.0, 1.4]:
            direct = tmm.inc_tmm(pol, n, d, c, th, LAM)["R"]
            th_p = tmm.list_snell(n, th)[p]
            R_last = tmm.inc_tmm(pol, n[p:], [INF, INF], ["i", "i"], th_p, LAM)["R"]
            comp = ref._compose_front(pol, n, d, c, p, R_last, th, LAM)
            assert abs(direct - comp) < 1e-15


def test_tir_continuity_and_frustrated_tir():
    # glass | thin low-index coherent film | air, light from the glass
    n, d, c = [1.5, 1.2, 1.0], [INF, 200.0, INF], ["i", "c", "i"]
    th_c = math.asin(1.0 / 1.5)
    below = ref.inc_stack_R_T("u", n, d, c, th_c - 1e-10, LAM)
    above = ref.inc_stack_R_T("u", n, d, c, th_c + 1e-10, LAM)
    assert above[1] == 0.0
    assert abs(below[0] - above[0]) < 1e-3  # sqrt-type approach to 1
    assert abs(above[0] - 1.0) < 1e-13
    # thin air gap between two glasses: frustrated TIR transmits past the critical angle
    R, T = ref.inc_stack_R_T("u", [1.5, 1.0, 1.5], [INF, 100.0, INF], ["i", "c", "i"], 0.9, LAM)
    assert T > 0.01 and abs(R + T - 1.0) < 1e-13
    # thick (incoherent) air gap: nothing gets through
    R, T = ref.inc_stack_R_T("u", [1.5, 1.0, 1.5], [INF, 1e5, INF], ["i", "i", "i"], 0.9, LAM)
    assert (R, T) == (1.0, 0.0)


def test_raw_tmm_quirks_documented():
    """What the wrappers protect against (tmm 0.2)."""
    # exit medium evanescent: T is O(1e-16), not 0
    out = tmm.inc_tmm("s", [1.5, 1.0], [INF, INF], ["i", "i"], 1.2, LAM)
    assert out["R"] == pytest.approx(1.0, abs=1e-15) and 0.0 < out["T"] < 1e-15
    # interior evanescent incoherent layer: growing branch -> unphysical R
    with np.errstate(all="ignore"):
        out = tmm.inc_tmm("s", [1.5, 1.0, 1.5], [INF, 100.0, INF], ["i"] * 3, 1.2, LAM)
    assert not (0.0 <= out["R"] <= 1.0)
    assert ref.inc_stack_R_T("s", [1.5, 1.0, 1.5], [INF, 100.0, INF], ["i"] * 3, 1.2, LAM) == (
        1.0,
        0.0,
    )


def test_tmm_is_clamped():
    # 1000 nm of n = 2 + 3i: Im(delta) = 2 pi 3 1000 / 500 >> 35 -> coh_tmm caps it
    assert ref.tmm_is_clamped([1, 2 + 3j, 1.5], [INF, 1000, INF], ["i", "c", "i"], 0.1, 500)
    assert not ref.tmm_is_clamped([1, 2 + 3j, 1.5], [INF, 100, INF], ["i", "c", "i"], 0.1, 500)
    assert ref.tmm_is_clamped([1, 2 + 3j, 1.5], [INF, 1000, INF], None, 0.1, 500)
    # incoherent: P = exp(-4 pi d Im(n cos)/lam) < 1e-30
    assert ref.tmm_is_clamped([1, 1.5 + 0.1j, 1.5], [INF, 1e5, INF], ["i"] * 3, 0.1, 500)
    assert not ref.tmm_is_clamped([1, 1.5 + 1e-4j, 1.5], [INF, 1e5, INF], ["i"] * 3, 0.1, 500)
    # evanescent interior incoherent layer is split off, never handed to tmm
    assert not ref.tmm_is_clamped([1.5, 1.0, 1.5], [INF, 1e6, INF], ["i"] * 3, 1.2, 500)


# --------------------------------------------------------- diffuse stack (eqs. 62-63)
LOSSLESS_STACKS = [
    ([1.0, 1.5, 1.33], [INF, 1e5, INF], ["i", "i", "i"]),
    ([1.0, 2.0, 1.5, 1.2, 1.5], [INF, 120.0, 1e5, 300.0, INF], ["i", "c", "i", "c", "i"]),
    ([1.0, 1.5, 1.0, 1.5], [INF, 1e5, 50.0, INF], ["i", "i", "c", "i"]),
]


@pytest.mark.parametrize("stack", LOSSLESS_STACKS)
@pytest.mark.parametrize("side", ["front", "back"])
def test_diffuse_lossless_r_plus_t_is_one(stack, side):
    r, t, er, et = ref.diffuse_stack_reference(*stack, LAM, side=side, return_error=True)
    assert abs(r + t - 1.0) < 1e-13
    assert er < 1e-13 and et < 1e-13
    assert 0.0 < r < 1.0


def test_diffuse_single_interface_equals_eq18():
    r, t = ref.diffuse_stack_reference([1.0, 1.5], [INF, INF], ["i", "i"], LAM)
    assert abs(r - ref.diffuse_reflectance_interface_closed_form(1.5)[0]) < 1e-13
    r, t = ref.diffuse_stack_reference([1.0, 1.5], [INF, INF], ["i", "i"], LAM, side="back")
    assert abs(r - ref.R_INT_15_EXACT) < 1e-11
    assert abs(t - (1.0 - ref.R_INT_15_EXACT)) < 1e-11


def test_diffuse_tmm_vs_beer_engine():
    n = [1.0, 1.5, 1.3, 1.6]
    for side in ("front", "back"):
        a = ref.diffuse_beer_stack(n, [0.0, 0.0], side)
        b = ref.diffuse_stack_reference(n, [INF, 1e5, 1e5, INF], ["i"] * 4, LAM, side=side)
        assert abs(a[0] - b[0]) < 1e-13 and abs(a[1] - b[1]) < 1e-13


def test_diffuse_absorbing_stack_reciprocal_t():
    """t_{0..k+1} n_0^2 = t_{k+1..0} n_{k+1}^2 (reciprocity of eq. 44 + eq. 10 / etendue)."""
    n = [1.0, 1.5 + 2e-4j, 1.6, 1.33]
    d = [INF, 1e4, 1e5, INF]
    c = ["i"] * 4
    rf, tf = ref.diffuse_stack_reference(n, d, c, LAM)
    rb, tb = ref.diffuse_stack_reference(n, d, c, LAM, side="back")
    assert abs(tf * 1.0**2 - tb * 1.33**2) < 1e-13
    assert rf + tf < 1.0 and rb + tb < 1.0


# ----------------------------------------------- Williams-Clapper, Shore-Spoonhower
def test_wc_lossless_white_background_conserves_energy():
    n0, n1 = 1.0, 1.5
    r110, t110 = ref.williams_clapper_integrals(n0, n1, 0.0)
    assert abs(r110 - ref.R_INT_15_EXACT) < 1e-11
    assert abs(r110 + t110 - 1.0) < 1e-14
    for th0 in [0.0, 0.5, 1.0, 1.4]:
        spec = ref.fresnel_natural_R(n0, n1, th0)[2]
        # integrating sphere: diffuse + specular = 1
        assert abs(ref.shore_spoonhower(n0, n1, 0.0, 1.0, th0) + spec - 1.0) < 1e-14
        # radiance detector: the eq. (82) factor integrated over the observation hemisphere
        diffuse = ref.hemispherical_integral(
            lambda mu: float(
                ref.williams_clapper_factor(n0, n1, 0.0, 1.0, th0, math.asin(math.sqrt(mu)))
            )
        )
        assert abs(diffuse + spec - 1.0) < 1e-14


@pytest.mark.parametrize("alpha_h,rho_g", [(0.3, 1.0), (0.3, 0.6), (1.5, 0.9)])
def test_wc_factor_integrates_to_shore_spoonhower(alpha_h, rho_g):
    n0, n1 = 1.0, 1.5
    for th0 in [0.0, 0.7, 1.3]:
        ss = ref.shore_spoonhower(n0, n1, alpha_h, rho_g, th0)
        wc = ref.hemispherical_integral(
            lambda mu: float(
                ref.williams_clapper_factor(n0, n1, alpha_h, rho_g, th0, math.asin(math.sqrt(mu)))
            )
        )
        assert abs(wc - ss) < 1e-14


def test_wc_integrals_equal_general_stack_with_matched_background():
    """Eqs. (80)-(81) = back-side eqs. (62)-(63) of [n0 | layer n1 | background n1]."""
    for ah in [0.0, 0.4]:
        r110, t110 = ref.williams_clapper_integrals(1.0, 1.5, ah)
        r, t = ref.diffuse_beer_stack([1.0, 1.5, 1.5], [ah], side="back")
        assert abs(r - r110) < 1e-14 and abs(t - t110) < 1e-14


# ------------------------------------------------------------ Saunderson (eqs. 84-87)
def test_saunderson_inversion_round_trip():
    for n in [1.33, 1.5, 1.8]:
        for th0 in [0.0, 0.6, 1.2]:
            rho_g = np.array([0.0, 0.1, 0.5, 0.9, 1.0])
            rho = ref.saunderson_sphere(n, rho_g, th0)
            np.testing.assert_allclose(ref.saunderson_invert(n, rho, th0), rho_g, atol=1e-15)
            Rf = ref.saunderson_radiance(n, rho_g, th0, 0.3)
            np.testing.assert_allclose(
                ref.saunderson_radiance_invert(n, Rf, th0, 0.3), rho_g, atol=1e-15
            )


def test_saunderson_special_cases():
    n = 1.5
    for th0 in [0.0, 0.8]:
        spec = ref.fresnel_natural_R(1.0, n, th0)[2]
        # white lossless background: diffuse + specular = 1
        assert abs(ref.saunderson_sphere(n, 1.0, th0) + spec - 1.0) < 1e-14
        # no layer = Williams-Clapper / Shore-Spoonhower with alpha h = 0
        for rho_g in (0.3, 0.8):
            assert abs(
                ref.saunderson_sphere(n, rho_g, th0) - ref.shore_spoonhower(1.0, n, 0.0, rho_g, th0)
            ) < 1e-15
            assert abs(
                ref.saunderson_radiance(n, rho_g, th0, 0.2)
                - ref.williams_clapper_factor(1.0, n, 0.0, rho_g, th0, 0.2)
            ) < 1e-15
        # general (tmm) route, eqs. (78)-(79), on a bare interface
        Rd, Rspec = ref.background_sphere([1.0, n], [INF, INF], ["i", "i"], LAM, 0.6, th0)
        assert abs(Rd - ref.saunderson_sphere(n, 0.6, th0)) < 1e-13
        assert abs(Rspec - spec) < 1e-15
        Rf = ref.background_radiance_factor([1.0, n], [INF, INF], ["i", "i"], LAM, 0.6, th0, 0.2)
        assert abs(Rf - ref.saunderson_radiance(n, 0.6, th0, 0.2)) < 1e-13
