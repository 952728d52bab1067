"""Pigment-concentration maps from a cube of a varnished painting (issue 28): ``fit_cube`` with a
Kubelka–Munk body under the varnish gives concentration and varnish-thickness maps with standard
errors, equal to ``fit_batch`` on the same pixels and within their errors of the concentrations
the cube was made from; a run stopped mid-way resumes to maps identical to an uninterrupted run.

The cube is synthetic: three pigments (a white held at its concentration, a red and a blue
fitted: an opaque body fixes only the ratios of the concentrations) in an opaque body of binder
index 1.5 under an absorbing varnish of unknown thickness, 45°/0°, noise σ = 1e-3.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("xarray")
pytest.importorskip("zarr")

import fitting as ft  # noqa: E402
import layerstack_jax as ls  # noqa: E402

WL = np.linspace(400.0, 700.0, 21)
GEOMETRY = ls.Directional(45.0, 0.0)
SIGMA = 1e-3
NY, NX = 4, 5


def _bell(mu, width):
    return np.exp(-0.5 * ((WL - mu) / width) ** 2)


PIGMENTS = [ls.Paint(np.full(WL.size, 2e-7), np.full(WL.size, 6e-4), name="white"),
            ls.Paint(3e-4 * _bell(480.0, 50.0) + 1e-6, np.full(WL.size, 5e-5), name="red"),
            ls.Paint(2e-4 * _bell(620.0, 60.0) + 1e-6, np.full(WL.size, 3e-5), name="blue")]


def _stack(c, h):
    return ls.Stack(1.0, [ls.Layer(1.52, h, coherent=False, alpha=1e-5, name="varnish")],
                    ls.KubelkaMunk(1.5, ls.Mixture(c, PIGMENTS)))


def _painting():
    rng = np.random.default_rng(8)
    c = np.stack([np.full((NY, NX), 0.6), rng.uniform(0.1, 0.4, (NY, NX)), rng.uniform(0.1, 0.4, (NY, NX))], -1)
    h = rng.uniform(15_000.0, 35_000.0, (NY, NX))
    clean = np.asarray(ls.predict(_stack(c, h[..., None]), WL, GEOMETRY))
    return clean + rng.normal(0.0, SIGMA, clean.shape), c, h


CUBE, C_TRUE, H_TRUE = _painting()


def _objective():
    return ft.Objective(_stack(np.array([0.6, 0.25, 0.25]), 25_000.0), WL, ft.Dataset(GEOMETRY, CUBE[0, 0], sigma=SIGMA),
                        [ft.Parameter(("exit", "paint", "concentrations"), kind="thickness", name="c",
                                      fixed=np.array([True, False, False]), lower=0.0, upper=1.0),
                         ft.thickness("varnish", value=25_000.0, lower=1_000.0, upper=80_000.0)])


OPTIONS = dict(wavelength_nm=WL, chunk=(2, 3), chunk_size=6)


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    out = tmp_path_factory.mktemp("pigments") / "maps.zarr"
    return ft.fit_cube(_objective(), CUBE, out=out, progress=False, **OPTIONS).load()


def test_concentration_maps_equal_fit_batch_and_cover_the_truth(maps):
    assert np.all(maps["status"].values == 0)
    b = ft.fit_batch(_objective(), CUBE.reshape(-1, WL.size), chunk_size=6, progress=False)
    for k, name in ((1, "c_1"), (2, "c_2")):
        np.testing.assert_allclose(maps[name].values.ravel(), b.values["c"][:, k], rtol=1e-10)
        err = maps[f"{name}_stderr"].values
        assert np.all(np.isfinite(err) & (err > 0))
        assert np.all(np.abs(maps[name].values - C_TRUE[..., k]) <= 4.0 * err), name
    np.testing.assert_allclose(maps["thickness_varnish"].values.ravel(), b.values["thickness[varnish]"], rtol=1e-10)
    assert np.all(np.abs(maps["thickness_varnish"].values - H_TRUE) <= 4.0 * maps["thickness_varnish_stderr"].values)


class _Stop(Exception):
    """Stands for a run that ends mid-way (Ctrl-C, a lost worker)."""


def test_a_stopped_run_resumes_to_identical_maps(maps, tmp_path):
    out = tmp_path / "maps.zarr"

    def stop_after_two_regions(done, total):
        if done >= 2 * 6:
            raise _Stop

    with pytest.raises(_Stop):
        ft.fit_cube(_objective(), CUBE, out=out, progress=stop_after_two_regions, **OPTIONS)
    done_before = [p for p in (tmp_path / "maps.zarr.regions").glob("*_*") if not p.name.endswith(".tmp")]
    assert 1 <= len(done_before) < 4  # 4 regions of 2 × 3 pixels: stopped mid-way
    resumed = ft.fit_cube(_objective(), CUBE, out=out, progress=False, **OPTIONS).load()
    for name in maps.data_vars:
        np.testing.assert_array_equal(resumed[name].values, maps[name].values, err_msg=name)


# ----------------------------------------------------------------------------- virtual varnish removal

def _bare(c):
    return ls.Stack(1.0, [], ls.KubelkaMunk(1.5, ls.Mixture(c, PIGMENTS)))


def test_varnish_removal_of_the_cube_is_the_fitted_body_bare(maps):
    """Each pixel's fitted body without its varnish reads what that body reads bare (built here
    by hand from the maps' concentrations), close to the body the cube was made from; with the
    varnish, what the cube read (within its noise); and as sRGB colours of the image shape."""
    obj = _objective()
    x = ft.cube_parameters(obj, maps)
    assert x.shape == (NY, NX, 3)
    colours = ls.ColourSpace(WL, extrapolate="constant")
    r = ft.varnish_removal(obj, x, layer="varnish", colour_space=colours)
    assert r.varnished.shape == r.removed.shape == (NY, NX, WL.size)
    assert r.srgb_removed.shape == (NY, NX, 3) and np.all((r.srgb_removed >= 0) & (r.srgb_removed <= 1))
    c_fit = np.stack([np.full((NY, NX), 0.6), maps["c_1"].values, maps["c_2"].values], -1)
    for iy, ix in [(0, 0), (1, 3), (3, 4)]:
        bare = np.asarray(ls.reflectance(_bare(c_fit[iy, ix]), WL, GEOMETRY))
        np.testing.assert_allclose(r.removed[iy, ix], bare, rtol=1e-12, atol=1e-15)
        truth = np.asarray(ls.reflectance(_bare(C_TRUE[iy, ix]), WL, GEOMETRY))
        assert np.max(np.abs(r.removed[iy, ix] - truth)) < 0.015  # the fit's noise (c and h correlate)
    assert np.sqrt(np.mean((r.varnished - CUBE) ** 2)) < 1.5 * SIGMA
    assert np.all(r.removed > r.varnished)  # the absorbing varnish darkens every band
    np.testing.assert_allclose(r.srgb_removed, np.asarray(colours.sRGB(r.removed, clip=True)), rtol=0, atol=1e-12)


def test_varnish_replaced_by_a_fresh_one_and_refusals():
    obj = _objective()
    x = np.array([[0.2, 0.3, 20_000.0], [np.nan, np.nan, np.nan]])
    fresh = ls.Layer(1.52, 10_000.0, coherent=False, alpha=0.0, name="fresh varnish")
    r = ft.varnish_removal(obj, x, replacement=fresh)
    want = ls.reflectance(ls.Stack(1.0, [fresh], ls.KubelkaMunk(1.5, ls.Mixture(np.array([0.6, 0.2, 0.3]), PIGMENTS))),
                          WL, GEOMETRY)
    np.testing.assert_allclose(r.removed[0], np.asarray(want), rtol=1e-12)
    assert np.all(np.isnan(r.removed[1])) and np.all(np.isnan(r.varnished[1]))  # a fit not made
    assert r.srgb_removed is None
    # an instrument at several angles: (rows, angles, wl), the fit not made NaN at every angle
    at_angles = ls.Specular(np.array([8.0, 30.0, 60.0]), "R")
    r3 = ft.varnish_removal(obj, x, geometry=at_angles)
    assert r3.removed.shape == (2, 3, WL.size) and np.all(np.isnan(r3.removed[1]))
    bare = ls.Stack(1.0, [], ls.KubelkaMunk(1.5, ls.Mixture(np.array([0.6, 0.2, 0.3]), PIGMENTS)))
    np.testing.assert_allclose(r3.removed[0], np.asarray(ls.reflectance(bare, WL, at_angles)), rtol=1e-12)
    with pytest.raises(ls.LayerstackError, match=r"no layer named 'glaze'.*layers: 'varnish'"):
        ft.varnish_removal(obj, x, layer="glaze")
    with pytest.raises(ls.LayerstackError, match="must end in the objective's 3 free parameters"):
        ft.varnish_removal(obj, x[:, :2])


# ----------------------------------------------------------------------------- unmixing

def test_unmixing_under_a_varnish_has_calibrated_standard_errors():
    """100 noisy replicates of one varnished mixture (red and blue free, white held, varnish
    thickness free): the truth lies within ±2σ of the fit in 90–98 % of the components."""
    c, h = np.array([0.6, 0.22, 0.31]), 24_000.0
    clean = np.asarray(ls.reflectance(_stack(c, h), WL, GEOMETRY))
    rng = np.random.default_rng(40)
    b = ft.fit_batch(_objective(), clean + SIGMA * rng.standard_normal((100, WL.size)), chunk_size=50, progress=False)
    assert np.all(b.converged)
    x = np.column_stack([b.values["c"][:, 1:], b.values["thickness[varnish]"]])
    err = np.column_stack([b.errors["c"][:, 1:], b.errors["thickness[varnish]"]])
    inside = np.abs(x - np.array([c[1], c[2], h])) <= 2.0 * err
    assert 0.90 <= inside.mean() <= 0.98, inside.mean(axis=0)


def test_two_pigments_of_proportional_k_and_s_are_named_as_not_separated():
    """A second red whose K and S are the first's times 2: only c_red + 2 c_red2 enters K and S,
    so the fit names the pair instead of giving them separate values."""
    red2 = ls.Paint(2.0 * PIGMENTS[1].absorption, 2.0 * PIGMENTS[1].scattering, name="red2")
    pigments = [*PIGMENTS[:2], red2]
    stack = lambda c: ls.Stack(1.0, [], ls.KubelkaMunk(1.5, ls.Mixture(c, pigments)))  # noqa: E731
    data = np.asarray(ls.reflectance(stack(np.array([0.6, 0.1, 0.1])), WL, GEOMETRY))
    obj = ft.Objective(stack(np.array([0.6, 0.2, 0.05])), WL, ft.Dataset(GEOMETRY, data, sigma=SIGMA),
                       [ft.Parameter(("exit", "paint", "concentrations"), kind="thickness", name="c",
                                     fixed=np.array([True, False, False]), lower=0.0, upper=1.0)])
    r = ft.fit(obj)
    text = r.report()
    assert not r.identifiable and ("c[1]" in text and "c[2]" in text), text
    assert "NOT SEPARATED" in text or "NOT IDENTIFIABLE" in text
