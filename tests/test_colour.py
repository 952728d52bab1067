"""Colour (layerstack_jax._instruments.colour) against colour-science's own functions and Sharma's published
CIEDE2000 test data; gradients against central finite differences.

Exact comparison (≤ 1e-10): on the ColorChecker's own grid (380–780 nm, 5 nm) and on colour-science's
1 nm CMF grid (360–830 nm), against ``colour.sd_to_XYZ(..., method="Integration")``, which integrates
on the same resampled tables with the same rectangle rule. colour-science's default "ASTM E308"
method uses different (ASTM E2022) weights: the difference is measured, not hidden.
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

colour = pytest.importorskip("colour")

from layerstack_jax import (  # noqa: E402
    ColourSpace,
    LayerstackError,
    delta_e_2000,
    delta_e_ab,
    srgb_encode,
    xyz_to_lab,
    xyz_to_xyy,
)

warnings.filterwarnings("ignore", module="colour")

# compiled once for the module (eager op-by-op dispatch is slow on a busy machine)
de00 = jax.jit(delta_e_2000)
de76 = jax.jit(delta_e_ab)

SHAPE_5NM = colour.SpectralShape(380, 780, 5)
SHAPE_1NM = colour.SpectralShape(360, 830, 1)
CHECKER = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]


def _checker_on(shape):
    """The 24 ColorChecker spectra resampled onto ``shape`` by colour-science itself."""
    return np.array([sd.copy().align(shape).values for sd in CHECKER.values()])


def _colour_xyz(R, shape, observer, illuminant):
    return colour.sd_to_XYZ(R, colour.MSDS_CMFS[observer], colour.SDS_ILLUMINANTS[illuminant],
                            method="Integration", shape=shape)


@pytest.mark.parametrize("observer", ["CIE 1931 2 Degree Standard Observer", "CIE 1964 10 Degree Standard Observer"])
@pytest.mark.parametrize("illuminant", ["D65", "D50", "A", "FL2"])
def test_xyz_lab_xyy_srgb_match_colour_science_on_5nm_checker(observer, illuminant):
    R = _checker_on(SHAPE_5NM)
    cs = ColourSpace(SHAPE_5NM.wavelengths, observer, illuminant)
    ref = _colour_xyz(R, SHAPE_5NM, observer, illuminant)
    np.testing.assert_allclose(np.asarray(cs.XYZ(R)), ref, rtol=0, atol=1e-10)

    # the white is the perfect reflector under the same tables
    white = np.asarray(cs.white_XYZ)
    np.testing.assert_allclose(white, _colour_xyz(np.ones(SHAPE_5NM.wavelengths.size), SHAPE_5NM, observer, illuminant),
                               rtol=0, atol=1e-10)
    xy_w = colour.XYZ_to_xy(white / 100)
    np.testing.assert_allclose(np.asarray(cs.Lab(R)), colour.XYZ_to_Lab(ref / 100, xy_w), rtol=0, atol=1e-10)
    xyY_ref = colour.XYZ_to_xyY(ref / 100) * [1, 1, 100]
    np.testing.assert_allclose(np.asarray(cs.xyY(R)), xyY_ref, rtol=0, atol=1e-10)
    for encode in (True, False):
        srgb_ref = colour.XYZ_to_sRGB(ref / 100, xy_w, apply_cctf_encoding=encode)
        np.testing.assert_allclose(np.asarray(cs.sRGB(R, encode=encode)), srgb_ref, rtol=0, atol=1e-12)


def test_1nm_cmf_grid_matches_colour_science():
    R = _checker_on(SHAPE_1NM)
    cs = ColourSpace(SHAPE_1NM.wavelengths, "10", "D65")
    ref = _colour_xyz(R, SHAPE_1NM, "CIE 1964 10 Degree Standard Observer", "D65")
    np.testing.assert_allclose(np.asarray(cs.XYZ(R)), ref, rtol=0, atol=1e-10)


def test_default_astm_e308_method_differs_by_its_weights_only():
    """colour-science's default method (ASTM E308 weights) is not the Integration method: on the
    5 nm checker the difference stays below 3e-3 (Y = 100 scale)."""
    R = _checker_on(SHAPE_5NM)
    cs = ColourSpace(SHAPE_5NM.wavelengths)
    cmfs, ill = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"], colour.SDS_ILLUMINANTS["D65"]
    astm = np.array([colour.sd_to_XYZ(sd, cmfs, ill) for sd in CHECKER.values()])
    diff = np.abs(np.asarray(cs.XYZ(R)) - astm).max()
    assert 0 < diff < 3e-3


def test_short_grid_raises_unless_constant_extrapolation_is_asked():
    shape = colour.SpectralShape(400, 700, 5)
    with pytest.raises(LayerstackError, match="380–780"):
        ColourSpace(shape.wavelengths)
    cs = ColourSpace(shape.wavelengths, extrapolate="constant")
    R = _checker_on(shape)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(SHAPE_5NM)
    ill = colour.SDS_ILLUMINANTS["D65"].copy().align(SHAPE_5NM)
    # colour-science holds the spectrum constant (its default extrapolator) on the CMF grid
    ref = np.array([colour.sd_to_XYZ(colour.SpectralDistribution(r, shape.wavelengths), cmfs, ill, method="Integration")
                    for r in R])
    np.testing.assert_allclose(np.asarray(cs.XYZ(R)), ref, rtol=0, atol=1e-10)
    with pytest.raises(LayerstackError, match="extrapolate"):
        ColourSpace(shape.wavelengths, extrapolate="linear")


def test_non_uniform_grid_integrates_close_to_the_1nm_result():
    """Cell-width quadrature on a non-uniform grid (1 nm below 550, 2 nm above, all nodes on the 1 nm grid so the spectra are the same numbers):
    within 0.01 ΔE00 of the 1 nm integration."""
    wl = np.concatenate([np.arange(380, 550, 1.0), np.arange(550, 781, 2.0)])
    fine = colour.SpectralShape(380, 780, 1)
    R_fine = _checker_on(fine)
    R = R_fine[:, np.searchsorted(fine.wavelengths, wl)]
    lab = ColourSpace(wl).Lab(R)
    lab_fine = ColourSpace(fine.wavelengths).Lab(R_fine)
    assert float(jnp.max(delta_e_2000(lab, lab_fine))) < 0.01


def test_names_and_errors():
    assert ColourSpace(SHAPE_5NM.wavelengths, illuminant="F11").illuminant == "FL11"
    with pytest.raises(LayerstackError, match="unknown illuminant"):
        ColourSpace(SHAPE_5NM.wavelengths, illuminant="D66")
    with pytest.raises(LayerstackError, match="unknown observer"):
        ColourSpace(SHAPE_5NM.wavelengths, observer="CIE 2015")
    with pytest.raises(LayerstackError, match="strictly increasing"):
        ColourSpace(SHAPE_5NM.wavelengths[::-1])
    with pytest.raises(LayerstackError, match="81"):
        ColourSpace(SHAPE_5NM.wavelengths).XYZ(np.ones(80))


def test_illuminant_as_spectral_distribution_and_inside_jit():
    sd = colour.SDS_ILLUMINANTS["D50"].copy()
    a = ColourSpace(SHAPE_5NM.wavelengths, illuminant=sd)
    b = ColourSpace(SHAPE_5NM.wavelengths, illuminant="D50")
    np.testing.assert_array_equal(np.asarray(a.weights), np.asarray(b.weights))
    with pytest.raises(LayerstackError, match="outside jit"):
        jax.jit(lambda w: ColourSpace(w).white_XYZ)(jnp.asarray(SHAPE_5NM.wavelengths))


def test_clip_and_black():
    cs = ColourSpace(SHAPE_5NM.wavelengths)
    XYZ = jnp.array([[80.0, 20.0, 5.0], [0.0, 0.0, 0.0]])  # a saturated red out of gamut; black
    rgb = cs.XYZ_to_sRGB(XYZ, encode=False)
    assert float(jnp.min(rgb[0])) < 0 and float(jnp.max(rgb[0])) > 1
    clipped = cs.XYZ_to_sRGB(XYZ, clip=True)
    np.testing.assert_allclose(clipped, srgb_encode(jnp.clip(rgb, 0, 1)), rtol=0, atol=1e-15)
    # black: xy of the white (colour-science's convention), L* = 0
    xyY = xyz_to_xyy(XYZ[1], cs.white_XYZ)
    np.testing.assert_allclose(xyY[:2], colour.XYZ_to_xy(np.asarray(cs.white_XYZ) / 100), atol=1e-14)
    assert float(xyz_to_lab(XYZ[1], cs.white_XYZ)[0]) == 0.0


def test_delta_e_match_colour_science_on_checker_pairs():
    cs = ColourSpace(SHAPE_5NM.wavelengths)
    lab = np.asarray(cs.Lab(_checker_on(SHAPE_5NM)))
    i, j = np.triu_indices(len(lab), 1)
    np.testing.assert_allclose(np.asarray(de00(lab[i], lab[j])),
                               colour.delta_E(lab[i], lab[j], method="CIE 2000"), rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.asarray(de76(lab[i], lab[j])),
                               colour.delta_E(lab[i], lab[j], method="CIE 1976"), rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.asarray(delta_e_2000(lab[i], lab[j], k_L=2.0)),
                               colour.delta_E(lab[i], lab[j], method="CIE 2000", textiles=True), rtol=0, atol=1e-10)


# Sharma, G., Wu, W., Dalal, E. N. (2005). "The CIEDE2000 color-difference formula: implementation
# notes, supplementary test data, and mathematical observations." Color Research & Application
# 30(1), 21-30, Table 1: L1 a1 b1, L2 a2 b2, ΔE00 (published to 4 decimals).
SHARMA_2005_TABLE_1 = [
    (50.0000, 2.6772, -79.7751, 50.0000, 0.0000, -82.7485, 2.0425),
    (50.0000, 3.1571, -77.2803, 50.0000, 0.0000, -82.7485, 2.8615),
    (50.0000, 2.8361, -74.0200, 50.0000, 0.0000, -82.7485, 3.4412),
    (50.0000, -1.3802, -84.2814, 50.0000, 0.0000, -82.7485, 1.0000),
    (50.0000, -1.1848, -84.8006, 50.0000, 0.0000, -82.7485, 1.0000),
    (50.0000, -0.9009, -85.5211, 50.0000, 0.0000, -82.7485, 1.0000),
    (50.0000, 0.0000, 0.0000, 50.0000, -1.0000, 2.0000, 2.3669),
    (50.0000, -1.0000, 2.0000, 50.0000, 0.0000, 0.0000, 2.3669),
    (50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0009, 7.1792),
    (50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0010, 7.1792),
    (50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0011, 7.2195),
    (50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0012, 7.2195),
    (50.0000, -0.0010, 2.4900, 50.0000, 0.0009, -2.4900, 4.8045),
    (50.0000, -0.0010, 2.4900, 50.0000, 0.0010, -2.4900, 4.8045),
    (50.0000, -0.0010, 2.4900, 50.0000, 0.0011, -2.4900, 4.7461),
    (50.0000, 2.5000, 0.0000, 50.0000, 0.0000, -2.5000, 4.3065),
    (50.0000, 2.5000, 0.0000, 73.0000, 25.0000, -18.0000, 27.1492),
    (50.0000, 2.5000, 0.0000, 61.0000, -5.0000, 29.0000, 22.8977),
    (50.0000, 2.5000, 0.0000, 56.0000, -27.0000, -3.0000, 31.9030),
    (50.0000, 2.5000, 0.0000, 58.0000, 24.0000, 15.0000, 19.4535),
    (50.0000, 2.5000, 0.0000, 50.0000, 3.1736, 0.5854, 1.0000),
    (50.0000, 2.5000, 0.0000, 50.0000, 3.2972, 0.0000, 1.0000),
    (50.0000, 2.5000, 0.0000, 50.0000, 1.8634, 0.5757, 1.0000),
    (50.0000, 2.5000, 0.0000, 50.0000, 3.2592, 0.3350, 1.0000),
    (60.2574, -34.0099, 36.2677, 60.4626, -34.1751, 39.4387, 1.2644),
    (63.0109, -31.0961, -5.8663, 62.8187, -29.7946, -4.0864, 1.2630),
    (61.2901, 3.7196, -5.3901, 61.4292, 2.2480, -4.9620, 1.8731),
    (35.0831, -44.1164, 3.7933, 35.0232, -40.0716, 1.5901, 1.8645),
    (22.7233, 20.0904, -46.6940, 23.0331, 14.9730, -42.5619, 2.0373),
    (36.4612, 47.8580, 18.3852, 36.2715, 50.5065, 21.2231, 1.4146),
    (90.8027, -2.0831, 1.4410, 91.1528, -1.6435, 0.0447, 1.4441),
    (90.9257, -0.5406, -0.9208, 88.6381, -0.8985, -0.7239, 1.5381),
    (6.7747, -0.2908, -2.4247, 5.8714, -0.0985, -2.2286, 0.6377),
    (2.0776, 0.0795, -1.1350, 0.9033, -0.0636, -0.5514, 0.9082),
]


def test_delta_e_2000_sharma_published_pairs():
    t = np.array(SHARMA_2005_TABLE_1)
    assert t.shape == (34, 7)
    lab1, lab2, expected = t[:, :3], t[:, 3:6], t[:, 6]
    for a, b in ((lab1, lab2), (lab2, lab1)):  # ΔE00 is symmetric
        got = np.asarray(de00(a, b))
        # published to 4 decimals: |error| <= half a unit in the last place
        np.testing.assert_allclose(got, expected, rtol=0, atol=0.5e-4 + 1e-12)


# ----------------------------------------------------------------------------- gradients
def _central_fd(f, x, h=1e-6):
    x = np.asarray(x, dtype=float)
    g = np.zeros_like(x)
    for i in range(x.size):
        e = np.zeros_like(x)
        e.flat[i] = h
        g.flat[i] = (float(f(x + e)) - float(f(x - e))) / (2 * h)
    return g


@pytest.mark.parametrize(
    "lab1, lab2",
    [
        ([52.0, 20.0, -30.0], [50.0, 18.0, -27.0]),  # ordinary pair
        ([50.0, 0.3, -0.2], [52.0, 2.0, 1.5]),  # near the neutral axis
        ([50.0, 2.4, -0.5], [50.0, -2.5, 0.3]),  # hues nearly opposite
        ([60.0, -34.0, 36.0], [60.5, -34.2, 39.4]),  # Sharma pair 25 region
    ],
)
def test_delta_e_2000_gradient_matches_finite_differences(lab1, lab2):
    lab2 = jnp.asarray(lab2)
    for f in (de00, de76):
        g = np.asarray(jax.grad(f)(jnp.asarray(lab1), lab2))
        np.testing.assert_allclose(g, _central_fd(lambda x: f(x, lab2), lab1), rtol=1e-6, atol=1e-8)


def test_gradients_finite_at_neutral_grey_and_identical_colours():
    grey = jnp.array([50.0, 0.0, 0.0])
    other = jnp.array([55.0, 3.0, -4.0])
    grey60 = jnp.array([60.0, 0.0, 0.0])
    x = jnp.stack([grey, grey, grey, other, other])
    y = jnp.stack([other, grey60, grey, other, grey])
    for f in (delta_e_2000, delta_e_ab):
        grads = jax.jit(jax.vmap(jax.grad(f, argnums=(0, 1))))(x, y)
        for g in grads:
            assert np.all(np.isfinite(np.asarray(g))), (f.__name__, g)
        # identical colours: ΔE = 0 and the zero sub-gradient (central differences of the cone are 0 too)
        assert float(f(other, other)) == 0.0
        np.testing.assert_array_equal(np.asarray(grads[0][3]), 0.0)
        np.testing.assert_array_equal(np.asarray(grads[0][2]), 0.0)
    # along L*, the grey-to-grey difference is smooth: gradient vs central differences
    g = jax.grad(lambda v: de00(v, grey60))(grey)
    fd = _central_fd(lambda v: de00(v, grey60), grey)
    np.testing.assert_allclose(g[0], fd[0], rtol=1e-7)


def test_gradient_through_spectrum_jit_and_vmap():
    cs = ColourSpace(SHAPE_5NM.wavelengths)
    R = jnp.asarray(_checker_on(SHAPE_5NM))
    target = cs.Lab(R[3])

    @jax.jit
    def loss(r):
        return delta_e_2000(cs.Lab(r), target) + jnp.sum(cs.sRGB(r, clip=True))

    grad = jax.jit(jax.grad(loss))
    g = np.asarray(grad(R[4]))
    idx = [0, 20, 40, 60, 80]
    r4 = np.asarray(R[4])

    def loss_at(v):
        r = r4.copy()
        r[idx] = v
        return loss(jnp.asarray(r))

    fd = _central_fd(loss_at, r4[idx], h=1e-7)
    np.testing.assert_allclose(g[idx], fd, rtol=1e-5, atol=1e-7)
    # a neutral grey spectrum and a black one: finite gradients of Lab and ΔE00
    for r in (jnp.full(R.shape[-1], 0.4), jnp.zeros(R.shape[-1])):
        assert np.all(np.isfinite(np.asarray(grad(r))))
        assert np.all(np.isfinite(np.asarray(jax.jit(jax.jacobian(cs.Lab))(r))))
    np.testing.assert_allclose(jax.vmap(cs.Lab)(R), cs.Lab(R), rtol=0, atol=1e-12)
