"""Honest pixels in :func:`fitting.fit_cube` (issue 27): readings below zero within k σ of zero
are data, a bad band is dropped from its pixel's fit (not the pixel), and a fit that is not to be
trusted — χ² implausible for its degrees of freedom, a parameter on a bound — is not "fitted".

The cube is made here by the public forward model (:func:`layerstack_jax.predict`): a varnish
(incoherent, absorbing, α falling with wavelength) over a Lambertian background seen at 45°/0°,
thickness 5 µm on the left and a ramp up to 24 µm on the right, with Gaussian noise
σ = 2e-3 (seeded). The thickest varnish is dark at short wavelengths, so most of its pixels
have readings below zero. Expected values come from the truth the cube is made from, from
scipy's χ² distribution and from counting the readings: never from the code under test.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("xarray")
pytest.importorskip("zarr")
pytest.importorskip("dask")

from scipy.stats import chi2 as chi2_distribution  # noqa: E402

import fitting  # noqa: E402
import layerstack_jax as ls  # noqa: E402

WL = np.arange(400.0, 701.0, 10.0)  # 31 bands, nm
ALPHA = 2e-4 * np.exp(-(WL - 400.0) / 60.0)  # 1/nm
RHO_G = np.full(WL.size, 0.6)
GEOMETRY = ls.Directional(45.0, 0.0)
SIGMA = 2e-3
NY, NX = 16, 12
LOWER, UPPER = 1e3, 4e4  # bounds of the fitted thickness, nm
STAINS = ((5, 2), (9, 0))  # a spectral feature the model cannot make: chi2 implausible
ON_BOUND = (3, 1)  # truth 980 nm, just below the lower bound 1000 nm
NAN_BAND = ((12, 10), 8)
SPIKE_BAND = ((2, 9), 3)  # -0.05 = -25 sigma: far below zero


def _stack(h):
    return ls.Stack(1.0, [ls.Layer(1.5, h, coherent=False, alpha=ALPHA, name="varnish")],
                    ls.LambertianBackground(1.52, RHO_G))


def _cube():
    truth = np.where(np.arange(NX) < 4, 5e3, np.linspace(6e3, 24e3, NX)) * np.ones((NY, 1))
    truth[ON_BOUND] = 980.0
    cube = np.asarray(ls.predict(_stack(truth[..., None]), WL, GEOMETRY))
    cube = cube + np.random.default_rng(2).normal(0.0, SIGMA, cube.shape)
    noisy = cube.copy()  # the readings as measured, before the defects below
    cube[STAINS[0] + (slice(10, 15),)] += 0.02
    cube[STAINS[1] + (slice(20, 24),)] -= 0.02
    cube[NAN_BAND[0] + (NAN_BAND[1],)] = np.nan
    cube[SPIKE_BAND[0] + (SPIKE_BAND[1],)] = -0.05
    return cube, noisy, truth


CUBE, NOISY, TRUTH = _cube()
THICK = TRUTH >= 18e3  # the thickest varnish: 4 columns of 16 pixels


@pytest.fixture(scope="module")
def objective():
    return fitting.Objective(_stack(1e4), WL, fitting.Dataset(GEOMETRY, NOISY[0, 0], sigma=SIGMA),
                             [fitting.thickness("varnish", value=1e4, lower=LOWER, upper=UPPER)])


@pytest.fixture(scope="module")
def maps(objective, tmp_path_factory):
    out = tmp_path_factory.mktemp("honest") / "maps.zarr"
    with pytest.warns(UserWarning, match=r"fit_cube: 3 pixel fit\(s\) not to be trusted as they are \(2 implausible "
                      r"chi2 \(status 5\), 1 parameter on a bound \(status 6\)\)"):
        maps = fitting.fit_cube(objective, CUBE, wavelength_nm=WL, out=out, chunk=(16, 6), chunk_size=96,
                                progress=False)
    return maps.load()


def test_thickest_region_mean_is_unbiased(maps):
    """Readings below zero (down to -5 sigma) are fitted: the map's mean over the thickest varnish
    is within 2 standard errors of the truth. Dropping every pixel with a reading below zero (the
    former rule) leaves the less dark pixels only, and a mean many standard errors too thin."""
    assert np.any(NOISY < 0, axis=-1)[THICK].mean() > 0.5  # most of the thickest pixels read below zero
    status = maps["status"].values
    d = maps["thickness_varnish"].values
    shown = THICK & (status == 0)
    assert shown.sum() >= THICK.sum() - 2  # every thick pixel is fitted (a χ² rejection at most by chance)
    err = d[shown] - TRUTH[shown]
    se = err.std(ddof=1) / np.sqrt(shown.sum())  # the standard error of the mean, from the scatter
    assert abs(d[shown].mean() - TRUTH[THICK].mean()) < 2.0 * se
    # the former rule on the same fits: only the pixels with no reading below zero are in the map
    former = shown & ~np.any(CUBE < 0, axis=-1)
    assert 0 < former.sum() < 0.5 * THICK.sum()
    se_former = (d[former] - TRUTH[former]).std(ddof=1) / np.sqrt(former.sum())
    assert d[former].mean() - TRUTH[THICK].mean() < -3.0 * se_former


def test_no_implausible_pixel_is_fitted(maps):
    """Status 0 only where χ² lies inside the central 99.9 % of χ²(ν), ν = bands used − 1 free
    parameter; the stained pixels are 'implausible chi2' (5) with their values kept; the pixel whose
    truth lies below the lower bound is 'parameter on a bound' (6)."""
    status = maps["status"].values
    made = np.isin(status, fitting.FIT_MADE)
    assert made.all()  # no pixel is dropped: bad bands are
    nu = maps["bands_used"].values - 1
    tail = chi2_distribution.sf(maps["chi2"].values, nu)
    assert np.all(tail[status == 0] >= 5e-4)
    assert np.all(status[tail < 5e-4] == 5) and np.all(maps["converged"].values == 1)
    for pixel in STAINS:
        assert status[pixel] == 5 and np.isfinite(maps["thickness_varnish"].values[pixel])
        assert maps["reduced_chi2"].values[pixel] > 10.0
    assert status[ON_BOUND] == 6
    np.testing.assert_allclose(maps["thickness_varnish"].values[ON_BOUND], LOWER, rtol=1e-5)
    assert (status == 0).sum() >= NY * NX - 5  # the 3 above and chance χ² rejections (1 in 2000)


def test_bad_band_is_dropped_not_the_pixel(maps):
    """A NaN band and a reading 25 σ below zero are left out of their pixel's fit: fitted from the
    30 other bands, within 4 standard errors of the truth."""
    d, err = maps["thickness_varnish"].values, maps["thickness_varnish_stderr"].values
    for pixel, _ in (NAN_BAND, SPIKE_BAND):
        assert maps["status"].values[pixel] == 0 and maps["bands_used"].values[pixel] == WL.size - 1
        assert abs(d[pixel] - TRUTH[pixel]) < 4.0 * err[pixel]
    bands = np.full((NY, NX), WL.size)
    bands[NAN_BAND[0]] = bands[SPIKE_BAND[0]] = WL.size - 1
    np.testing.assert_array_equal(maps["bands_used"].values, bands)  # no noisy reading is below -5 sigma
    assert maps.attrs["negative_sigmas"] == 5.0


def test_negative_sigmas_zero_drops_every_reading_below_zero(objective, tmp_path):
    """``negative_sigmas=0``: every reading below zero is a bad band of its pixel (counted here
    from the cube), the pixel is still fitted from the others."""
    maps = fitting.fit_cube(objective, CUBE, wavelength_nm=WL, out=tmp_path / "k0.zarr", chunk=(16, 6),
                            chunk_size=96, progress=False, negative_sigmas=0.0).load()
    good = np.sum(np.isfinite(CUBE) & (CUBE >= 0), axis=-1)
    np.testing.assert_array_equal(maps["bands_used"].values, good)
    assert np.all(np.isin(maps["status"].values, fitting.FIT_MADE))


def test_batch_args_take_a_masked_array_as_a_mask_per_fit(objective):
    """:meth:`fitting.Objective.batch_args` of a masked array: the masked points of one fit get
    weight 0 (data 0) and are not checked (NaN, -0.5); the other fits keep every weight."""
    data = np.stack([NOISY[0, 0], NOISY[0, 1], NOISY[0, 2]])
    data[1, 3], data[2, 7] = np.nan, -0.5
    masked = np.ma.MaskedArray(data, mask=~np.isfinite(data) | (data < -0.1))
    (ys, ws), n = objective.batch_args([masked])
    w, y = np.asarray(ws[0])[:, 0], np.asarray(ys[0])[:, 0]
    assert n == 3 and w.shape == y.shape == (3, WL.size)
    expected = np.full((3, WL.size), 1.0 / SIGMA)
    expected[1, 3] = expected[2, 7] = 0.0
    np.testing.assert_array_equal(w, expected)
    assert y[1, 3] == 0.0 and y[2, 7] == 0.0
    np.testing.assert_array_equal(y[0], data[0])
    with pytest.raises(ls.LayerstackError, match="NaN or infinite data"):
        objective.batch_args([data])  # the same data unmasked
