"""Hyperspectral cubes: lazy readers (ENVI written by ``spectral``, zarr, NetCDF/HDF5, npy) and
:func:`fitting._cube.fit_cube` — equal to :func:`fitting.fit_batch` on the same pixels, a pixel's
bad bands (NaN, saturated, far below zero) left out of its fit only (equal to a fit whose
:class:`fitting.Dataset` masks that band), masked pixels never fitted, a fit in a local minimum
marked by its χ² (not "fitted"), a run killed mid-way (SIGKILL of the process) and resumed
giving identical maps, degenerate objectives refused before any compute, and the same job on a
``distributed.LocalCluster`` of 2 worker processes giving identical maps."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

pytest.importorskip("xarray")
pytest.importorskip("zarr")
pytest.importorskip("dask")

import fitting  # noqa: E402
import layerstack_jax as ls  # noqa: E402
from fitting._cube import CUBE_STATUS, fit_cube  # noqa: E402
from layerstack_jax._instruments.batched import predict  # noqa: E402
from layerstack_jax._files.cubes import as_cube, open_cube, read_envi, read_npy, read_zarr, write_zarr_cube  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# ----------------------------------------------------------------------------- readers


def _random_cube(ny=5, nx=7, nb=4, dtype=np.float32):
    return np.random.default_rng(0).random((ny, nx, nb)).astype(dtype)


@pytest.mark.parametrize("interleave", ["bsq", "bil", "bip"])
def test_envi_written_by_spectral_round_trips(tmp_path, interleave):
    envi = pytest.importorskip("spectral.io.envi")
    a = _random_cube()
    hdr = tmp_path / "cube.hdr"
    envi.save_image(str(hdr), a, interleave=interleave,
                    metadata={"wavelength": [0.4, 0.5, 0.6, 0.7], "wavelength units": "Micrometers"})
    cube = read_envi(hdr)
    assert cube.dims == ("y", "x", "wavelength")
    assert cube.chunks is not None  # dask-backed: lazy
    np.testing.assert_allclose(cube["wavelength"].values, [400.0, 500.0, 600.0, 700.0], rtol=1e-12)
    np.testing.assert_array_equal(cube.values, a)
    np.testing.assert_array_equal(open_cube(hdr).isel(y=slice(1, 3), x=slice(2, 5)).values, a[1:3, 2:5])


def test_zarr_npy_netcdf_round_trip(tmp_path):
    a = _random_cube(dtype=np.float64)
    wl = [400.0, 500.0, 600.0, 700.0]
    write_zarr_cube(a, tmp_path / "c.zarr", wl, chunks=(2, 3, -1))
    z = read_zarr(tmp_path / "c.zarr")
    assert z.chunks[0] == (2, 2, 1) and z.chunks[1] == (3, 3, 1)  # the store's chunks, read lazily
    np.testing.assert_array_equal(z.values, a)
    np.testing.assert_array_equal(z["wavelength"].values, wl)
    np.save(tmp_path / "c.npy", a)
    np.testing.assert_array_equal(read_npy(tmp_path / "c.npy", wl).values, a)
    pytest.importorskip("h5netcdf")
    z.to_dataset(name="r").to_netcdf(tmp_path / "c.h5", engine="h5netcdf")
    np.testing.assert_array_equal(open_cube(tmp_path / "c.h5").values, a)


def test_reader_errors_name_the_problem(tmp_path):
    with pytest.raises(ls.LayerstackError, match="3 wavelengths for 4 bands"):
        as_cube(_random_cube(), [400.0, 500.0, 600.0])
    with pytest.raises(ls.LayerstackError, match="strictly increasing"):
        as_cube(_random_cube(), [400.0, 500.0, 500.0, 600.0])
    with pytest.raises(ls.LayerstackError, match="unknown format"):
        open_cube(tmp_path / "c.txt")


# ----------------------------------------------------------------------------- fit_cube

WL = np.linspace(420.0, 700.0, 15)
GEOMETRY = ls.Specular(8.0, "R")
NY, NX = 6, 5


def _stack(d=150.0, n=2.0):
    return ls.Stack(1.0, [ls.Layer(ls.Index(n), d, coherent=True, name="film")], ls.Substrate(1.52))


#: pixel -> its one bad band: NaN, saturated (saturation=1 below), far below zero (-500 σ)
BAD_BANDS = {(1, 2): 5, (3, 0): 7, (5, 1): 2}


def _synthetic():
    """A cube made by the forward model (film thickness and index per pixel) with noise, one
    NaN band, one saturated reading and one far below zero (:data:`BAD_BANDS`); and a user mask."""
    rng = np.random.default_rng(3)
    d = rng.uniform(100.0, 200.0, (NY, NX))
    n = rng.uniform(1.9, 2.2, (NY, NX))
    cube = predict(_stack(d[..., None], n[..., None]), WL, GEOMETRY) + rng.normal(0.0, 1e-3, (NY, NX, WL.size))
    for (iy, ix), j, value in zip(BAD_BANDS, BAD_BANDS.values(), (np.nan, 5.0, -0.5)):
        cube[iy, ix, j] = value
    mask = np.ones((NY, NX), bool)
    mask[4, 4] = False
    return cube, mask, d, n


CUBE, MASK, D_TRUE, N_TRUE = _synthetic()


def _objective(degenerate=False):
    params = [fitting.thickness("film", value=150.0, lower=60.0, upper=260.0),
              fitting.index_n("film", value=2.05, lower=1.6, upper=2.6)]
    return fitting.Objective(_stack(), WL, fitting.Dataset(GEOMETRY, CUBE[0, 0], sigma=1e-3), params)


OPTIONS = dict(mask=MASK, saturation=1.0, chunk=(4, 3), chunk_size=8, progress=False)


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("cube")
    write_zarr_cube(CUBE, d / "cube.zarr", WL, chunks=(4, 3, -1))
    maps = fit_cube(_objective(), read_zarr(d / "cube.zarr"), out=d / "maps.zarr", **OPTIONS).load()
    return d, maps


def test_fit_cube_equals_fit_batch_and_drops_bad_bands_not_pixels(local_run):
    from scipy.stats import chi2 as chi2_distribution

    _, maps = local_run
    status = maps["status"].values
    assert set(np.unique(status)) <= set(CUBE_STATUS)
    assert status[4, 4] == 1 and np.isnan(maps["thickness_film"].values[4, 4]) and maps["num_steps"].values[4, 4] == -1
    made = np.isin(status, fitting.FIT_MADE)
    assert made.sum() == NY * NX - 1  # every pixel but the masked one: a bad band drops the band, not the pixel
    bands = np.full((NY, NX), WL.size)
    for pixel in BAD_BANDS:
        bands[pixel] -= 1
    bands[4, 4] = -1
    np.testing.assert_array_equal(maps["bands_used"].values, bands)
    clean = made & (bands == WL.size)
    b = fitting.fit_batch(_objective(), CUBE[clean], chunk_size=8)
    np.testing.assert_allclose(maps["thickness_film"].values[clean], b.x[:, 0], rtol=1e-10)
    np.testing.assert_allclose(maps["n_film"].values[clean], b.x[:, 1], rtol=1e-10)
    np.testing.assert_allclose(maps["thickness_film_stderr"].values[clean], b.stderr[:, 0], rtol=1e-6)
    np.testing.assert_allclose(maps["chi2"].values[clean], b.chi2, rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(maps["num_steps"].values[clean], b.num_steps)
    np.testing.assert_array_equal(maps["converged"].values[clean], b.converged.astype(np.int8))
    separable = np.array([not f for f in b.separability])  # no group of parameters with |ρ| > 0.99
    np.testing.assert_array_equal(maps["identifiable"].values[clean], ((b.rank == 2) & separable).astype(np.int8))
    # a pixel with a bad band: the fit of its spectrum by an objective whose Dataset masks that band
    params = _objective().layout.params
    for (iy, ix), j in BAD_BANDS.items():
        keep = np.arange(WL.size) != j
        own = fitting.Objective(_stack(), WL, fitting.Dataset(GEOMETRY, np.where(keep, CUBE[iy, ix], 0.0),
                                                              sigma=1e-3, mask=keep), [p.parameter for p in params])
        r = fitting.fit_batch(own, CUBE[iy, ix][None], chunk_size=1)  # the bad value is masked: unchecked
        np.testing.assert_allclose([maps["thickness_film"].values[iy, ix], maps["n_film"].values[iy, ix]], r.x[0],
                                   rtol=1e-8, err_msg=str((iy, ix)))
        np.testing.assert_allclose(maps["chi2"].values[iy, ix], r.chi2[0], rtol=1e-6, err_msg=str((iy, ix)))
        np.testing.assert_allclose(maps["reduced_chi2"].values[iy, ix], r.chi2[0] / (WL.size - 1 - 2), rtol=1e-6)
        np.testing.assert_allclose(maps["thickness_film_stderr"].values[iy, ix], r.stderr[0, 0], rtol=1e-6)
    # honest pixels (σ given): status 0 only where χ² lies inside the central 99.9 % of χ²(ν), ν = bands − 2
    tail = chi2_distribution.sf(maps["chi2"].values[made], bands[made] - 2)
    converged = maps["converged"].values[made] == 1
    np.testing.assert_array_equal(status[made] == 5, converged & (tail < 5e-4))
    assert np.all(converged)
    # every fit that found the truth the cube was made from (σ = 1e-3 noise) is "fitted"; a fit in
    # a local minimum (here pixel (3, 0), ~110 nm off, reduced χ² ~ 2600) is marked by its χ²
    off = np.abs(maps["thickness_film"].values - D_TRUE) > 3.0
    assert np.all(status[made & ~off] == 0) and np.all(status[made & off] == 5) and np.sum(made & off) <= 2


def test_resume_of_another_job_is_refused(local_run, tmp_path):
    d, _ = local_run
    with pytest.raises(ls.LayerstackError, match="another job"):
        fit_cube(_objective(), read_zarr(d / "cube.zarr"), out=d / "maps.zarr", **dict(OPTIONS, saturation=0.9))
    with pytest.raises(ls.LayerstackError, match="another job"):
        fit_cube(_objective(), read_zarr(d / "cube.zarr"), out=d / "maps.zarr", **OPTIONS, negative_sigmas=3.0)
    with pytest.raises(ls.LayerstackError, match=r"negative_sigmas must be a number from 0 to 5"):
        fit_cube(_objective(), read_zarr(d / "cube.zarr"), out=d / "maps.zarr", **OPTIONS, negative_sigmas=6.0)


def test_wavelength_mismatch_and_degenerate_objective_refused_before_compute(tmp_path):
    with pytest.raises(ls.LayerstackError, match="bands"):
        fit_cube(_objective(), CUBE[..., :-1], wavelength_nm=WL[:-1], out=tmp_path / "a.zarr")
    varnish = ls.Stack(1.0, [ls.Layer(1.5, 2e4, coherent=False, alpha=2e-5, name="varnish")],
                       ls.LambertianBackground(1.52, 0.5))
    wl = WL[:4]
    obj = fitting.Objective(varnish, wl, fitting.Dataset(ls.Directional(45.0, 0.0), np.full(4, 0.3)),
                            [fitting.thickness("varnish", value=2e4), fitting.alpha("varnish", value=2e-5)])
    with pytest.raises(ls.LayerstackError, match=r"varnish: thickness and alpha are both free.*alpha·h"):
        fit_cube(obj, np.full((2, 2, 4), 0.3), wavelength_nm=wl, out=tmp_path / "b.zarr")
    assert not (tmp_path / "b.zarr").exists()  # refused before anything was written or fitted
    # allowed: warned once, up front; here every pixel is no-data, so nothing is fitted at all
    with pytest.warns(UserWarning, match="degenerate by construction") as record:
        maps = fit_cube(obj, np.full((1, 2, 4), np.nan), wavelength_nm=wl, out=tmp_path / "c.zarr",
                        allow_degenerate=True, progress=False)
    assert sum("degenerate" in str(w.message) for w in record) == 1
    np.testing.assert_array_equal(maps["status"].values, [[2, 2]])
    assert np.all(np.isnan(maps["thickness_varnish"].values))


_CHILD = textwrap.dedent("""
    import sys, time
    import jax
    jax.config.update("jax_enable_x64", True)
    sys.path.insert(0, {tests!r})
    import test_cube as t
    from fitting._cube import fit_cube
    from layerstack_jax._files.cubes import read_zarr

    def slow(done, total):  # a slow worker, so that the parent kills it mid-way
        time.sleep(0.7)

    fit_cube(t._objective(), read_zarr({cube!r}), out={out!r}, **dict(t.OPTIONS, progress=slow))
""")


@pytest.mark.slow  # timing-dependent (a child process killed mid-run): once failed under a heavily loaded machine
def test_killed_run_resumes_to_identical_maps(local_run, tmp_path):
    d, maps = local_run
    out = tmp_path / "maps.zarr"
    code = _CHILD.format(tests=os.path.join(ROOT, "tests"), cube=str(d / "cube.zarr"), out=str(out))
    child = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    markers = tmp_path / "maps.zarr.regions"
    deadline = time.time() + 240
    while time.time() < deadline and child.poll() is None:
        if markers.exists() and len(list(markers.glob("*_*"))) >= 2:
            break
        time.sleep(0.05)
    assert child.poll() is None, child.communicate()[1][-2000:]
    child.send_signal(signal.SIGKILL)  # killed while it works on the next regions
    child.wait()
    done_before = {p.name for p in markers.glob("*_*") if not p.name.endswith(".tmp")}
    assert 2 <= len(done_before) < 6  # 6 regions of 4 × 3 pixels: killed mid-way
    resumed = fit_cube(_objective(), read_zarr(d / "cube.zarr"), out=out, **OPTIONS).load()
    for name in maps.data_vars:
        np.testing.assert_array_equal(resumed[name].values, maps[name].values, err_msg=name)


@pytest.mark.slow
def test_local_cluster_of_two_processes_gives_identical_maps(local_run, tmp_path):
    pytest.importorskip("distributed")
    d, maps = local_run
    remote = fit_cube(_objective(), read_zarr(d / "cube.zarr"), out=tmp_path / "maps.zarr", client="processes",
                      n_workers=2, **OPTIONS).load()
    for name in maps.data_vars:
        np.testing.assert_array_equal(remote[name].values, maps[name].values, err_msg=name)
