"""`layerstack fit-cube` and `layerstack predict --vary / --vary-table` (issue 19).

The cube is made by the public forward model (:func:`layerstack_jax.predict`) from known maps of
a film's thickness and index; the command line must give those maps back, fit the pixel with a
NaN band from its other bands, mark the masked pixel, write the quick-look PNGs, say that it
resumes on a second run, mark the two local-minimum pixels of ``examples/cube`` (status, summary,
exit status 1), and refuse a cube
without a geometry or a mask of the wrong shape with exit status 2 and one line. The batched
prediction is compared with :func:`layerstack_jax.reflectance` on each single stack, built
directly in Python (not through the stack file or the batch code).
"""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest

pytest.importorskip("xarray")
pytest.importorskip("zarr")
pytest.importorskip("dask")
pytest.importorskip("matplotlib")

import layerstack_jax as ls  # noqa: E402
from layerstack_cli import main  # noqa: E402

WL = np.arange(400.0, 701.0, 10.0)  # 31 bands
GEOMETRY = ls.Specular(8.0, "R")
NY, NX = 6, 5
NAN_PIXEL, MASKED_PIXEL = (1, 2), (4, 4)

MODEL = """
[[layers]]
name = "film"
n = { value = 2.05, free = true, min = 1.6, max = 2.6 }
thickness_nm = { value = 150, free = true, min = 60, max = 260 }
coherent = true

[substrate]
n = 1.52
"""


def _truth():
    rng = np.random.default_rng(7)
    d = rng.uniform(110.0, 190.0, (NY, NX))
    n = rng.uniform(1.9, 2.2, (NY, NX))
    film = ls.Layer(ls.Index(n[..., None]), d[..., None], coherent=True, name="film")
    cube = np.array(ls.predict(ls.Stack(1.0, [film], ls.Substrate(1.52)), WL, GEOMETRY))
    cube[NAN_PIXEL + (4,)] = np.nan  # one NaN band: a bad band, left out of that pixel's fit
    return cube, d, n


CUBE, D_TRUE, N_TRUE = _truth()


@pytest.fixture(scope="module")
def cube_files(tmp_path_factory):
    import xarray as xr

    from layerstack_jax import write_zarr_cube

    d = tmp_path_factory.mktemp("cli_cube")
    (d / "model.toml").write_text(MODEL)
    cube = xr.DataArray(CUBE, dims=("y", "x", "wavelength"), coords={"wavelength": WL},
                        attrs={"geometry": "specular:8:R"})  # the cube says how it was measured
    write_zarr_cube(cube, d / "cube.zarr", chunks=(3, 3, -1))
    np.save(d / "cube.npy", CUBE)  # no metadata at all
    mask = np.ones((NY, NX), bool)
    mask[MASKED_PIXEL] = False
    np.save(d / "mask.npy", mask)
    np.save(d / "mask_wrong.npy", np.ones((NX, NY), bool))
    return d


@pytest.fixture(scope="module")
def fit_command(cube_files):
    d = cube_files
    argv = ["fit-cube", str(d / "model.toml"), str(d / "cube.zarr"), "-o", str(d / "maps.zarr"), "--mask",
            str(d / "mask.npy"), "--chunk", "3", "--batch", "8", "--sigma", "1e-3", "--quiet"]
    return d, argv


def test_fit_cube_recovers_the_maps_marks_pixels_and_writes_quicklooks(fit_command, capsys):
    import xarray as xr

    d, argv = fit_command
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "geometry: specular:8:R" in out and "from the cube's metadata" in out
    assert "resuming" not in out
    maps = xr.open_zarr(d / "maps.zarr", consolidated=False).load()
    status = maps["status"].values
    assert status[NAN_PIXEL] == 0 and status[MASKED_PIXEL] == 1
    assert maps["bands_used"].values[NAN_PIXEL] == WL.size - 1  # fitted from its 30 other bands
    ok = status == 0
    assert ok.sum() == NY * NX - 1
    for var in ("thickness_nm_film", "n_film", "thickness_nm_film_stderr", "reduced_chi2"):
        assert np.all(np.isnan(maps[var].values[~ok])), var
    # the truth the cube was made from (noise-free data: the fits reach it)
    assert np.all(maps["converged"].values[ok] == 1)
    np.testing.assert_allclose(maps["thickness_nm_film"].values[ok], D_TRUE[ok], atol=0.05)
    np.testing.assert_allclose(maps["n_film"].values[ok], N_TRUE[ok], atol=1e-4)
    # summary table
    assert re.search(r"outside the mask\s+1\n", out) and re.search(r"no data \(NaN/inf\)\s+0\n", out)
    assert re.search(r"fits with bad bands left out\s+1\n", out)
    assert "median reduced chi2" in out and "pixels/s" in out
    assert re.search(r"implausible chi2\s+0\n", out)
    # noise-free data with sigma 1e-3: chi2 ~ 0, below its distribution (said, not a status)
    assert re.search(rf"chi2 too small\s+{NY * NX - 1} \(below the central 99.9%", out)
    assert re.search(r"NOT converged\s+0\n", out) and re.search(rf"fitted\s+{NY * NX - 1}\n", out)
    # quick looks: every map, printed
    ql = d / "maps_quicklook"
    for name in ("thickness_nm_film", "thickness_nm_film_stderr", "n_film", "n_film_stderr", "reduced_chi2",
                 "status"):
        png = ql / f"{name}.png"
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
        assert f"wrote {png}" in out
    assert (d / "maps.zarr.log").read_text().count("px/s") >= 1  # progress logged


def test_second_run_resumes(fit_command, capsys):
    d, argv = fit_command
    if not (d / "maps.zarr").exists():
        assert main(argv) == 0
    capsys.readouterr()
    assert main(argv + ["--no-quicklook"]) == 0
    out = capsys.readouterr().out
    assert "resuming: 4 of 4 chunks already written" in out  # 6 x 5 pixels in 3 x 3 regions
    # a run killed before region (1, 1) (rows 3-5, columns 3-4: 6 pixels) was written: it is fitted again
    import xarray as xr

    before = xr.open_zarr(d / "maps.zarr", consolidated=False).load()
    (d / "maps.zarr.regions" / "1_1").unlink()  # the completion marker fit_cube documents
    assert main(argv + ["--no-quicklook"]) == 0
    assert "resuming: 3 of 4 chunks already written (24 of 30 pixels)" in capsys.readouterr().out
    after = xr.open_zarr(d / "maps.zarr", consolidated=False).load()
    for name in before.data_vars:
        np.testing.assert_array_equal(after[name].values, before[name].values, err_msg=name)
    # the same store with other settings is another job: refused (exit 2), the option to overwrite named
    assert main(argv[:-3] + ["--sigma", "2e-3", "--quiet", "--no-quicklook"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "another job" in err and "--restart" in err


def test_scheduler_address_runs_the_same_job_on_a_cluster(fit_command, capsys):
    """``--scheduler ADDRESS``: the same command on a running Dask cluster (here a scheduler with
    one in-process worker, reached over TCP like any remote one) writes the maps of the local run."""
    distributed = pytest.importorskip("distributed")
    import xarray as xr

    d, argv = fit_command
    if not (d / "maps.zarr").exists():
        assert main(argv) == 0
    local = xr.open_zarr(d / "maps.zarr", consolidated=False).load()
    out = d / "maps_cluster.zarr"
    remote_argv = [a if a != str(d / "maps.zarr") else str(out) for a in argv] + ["--no-quicklook"]
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                                  dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://")
        capsys.readouterr()
        assert cluster.scheduler.transition_counter == 0
        assert main(remote_argv + ["--scheduler", cluster.scheduler_address]) == 0
        assert cluster.scheduler.transition_counter > 0  # the regions ran as tasks of that cluster
    remote = xr.open_zarr(out, consolidated=False).load()
    assert set(remote.data_vars) == set(local.data_vars)
    for name in local.data_vars:
        np.testing.assert_array_equal(remote[name].values, local[name].values, err_msg=name)


def test_examples_cube_marks_the_two_local_minimum_pixels(tmp_path, capsys):
    """``examples/cube`` (its README's command): two pixels of the thin, low-index corner converge
    to a local minimum near 250 nm (truth ~110 nm). They get status 5 "implausible chi2", the
    summary counts them, and the command exits 1; every other pixel is fitted (the NaN-band
    pixel (2, 3) from its 30 other bands) and near the truth of ``make_film_cube.py``."""
    import os

    import xarray as xr

    ex = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples", "cube")
    out = tmp_path / "film_maps.zarr"
    argv = ["fit-cube", os.path.join(ex, "film_model.toml"), os.path.join(ex, "film_cube.npy"), "-w", "400:700:10",
            "-g", "specular:8:R", "--mask", os.path.join(ex, "film_mask.npy"), "--sigma", "1e-3", "--chunk", "8",
            "-o", str(out), "--quiet", "--no-quicklook"]
    assert main(argv) == 1
    text = capsys.readouterr().out
    assert re.search(r"implausible chi2\s+2 \(chi2 above the central 99.9%", text)
    assert re.search(r"fitted\s+181\n", text) and re.search(r"outside the mask\s+9\n", text)
    assert "2 pixel fit(s) not to be trusted" in text and "exit status 1" in text
    maps = xr.open_zarr(out, consolidated=False).load()
    status = maps["status"].values
    # the truth make_film_cube.py made the cube from: thickness 110 -> 190 nm across the 16 columns
    truth = np.broadcast_to(np.linspace(110.0, 190.0, 16), status.shape)
    far = np.abs(maps["thickness_nm_film"].values - truth) > 20.0  # NaN (not fitted): False
    assert far.sum() == 2 and np.all(status[far] == 5) and np.all(maps["converged"].values[far] == 1)
    near = np.isin(status, (0, 5, 6, 7)) & ~far
    assert np.all(status[near] == 0)
    assert np.max(np.abs(maps["thickness_nm_film"].values[near] - truth[near])) < 1.0
    assert status[2, 3] == 0 and maps["bands_used"].values[2, 3] == 30


def test_missing_geometry_and_bad_mask_are_user_errors(cube_files, capsys):
    d = cube_files
    base = ["fit-cube", str(d / "model.toml"), str(d / "cube.npy"), "-w", "400:700:10", "-o", str(d / "x.zarr")]
    assert main(base) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "cube.npy" in err and "give -g GEOM" in err and "Traceback" not in err
    assert main(base + ["-g", "specular:8:R", "--mask", str(d / "mask_wrong.npy")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "mask_wrong.npy" in err and f"({NY}, {NX})" in err
    assert main(base + ["-g", "specular:8:R", "--negative-sigmas", "6"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--negative-sigmas must be a number from 0 to 5" in err
    assert not (d / "x.zarr").exists()  # refused before anything was written


# ----------------------------------------------------------------------------- predict --vary

VARNISH = """
[[layers]]
name = "varnish"
n = 1.5
thickness_nm = 20000
coherent = false
alpha_per_nm = 1e-5

[substrate]
n = 1.52
"""


def _read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, values = rows[0], np.array(rows[1:], dtype=float)
    return header, values


def _single(h, alpha, q):
    """One stack built directly (not from the file), its specular spectrum at normal incidence."""
    st = ls.Stack(1.0, [ls.Layer(1.5, h, coherent=False, alpha=alpha, name="varnish")], ls.Substrate(1.52))
    return np.asarray(ls.reflectance(st, WL, ls.Specular(0.0, q)))


def test_predict_vary_outer_product_equals_single_stacks(tmp_path):
    (tmp_path / "s.toml").write_text(VARNISH)
    out = tmp_path / "v.csv"
    assert main(["predict", str(tmp_path / "s.toml"), "-g", "specular:0:R", "-g", "specular:0:T", "-w", "400:700:10",
                 "-o", str(out), "--vary", "varnish.thickness_nm=1e4:3e4:1e4", "--vary", "varnish.alpha_per_nm=1e-5,4e-5",
                 "--digits", "17"]) == 0
    header, values = _read_csv(out)
    np.testing.assert_array_equal(values[:, 0], WL)
    expected_names = []
    for q in ("R", "T"):  # one column per geometry and sample: geometries outer, the last --vary fastest
        for h in (10000, 20000, 30000):
            for a in ("1e-05", "4e-05"):
                expected_names.append(f"{q}_0 varnish.thickness_nm={h} varnish.alpha_per_nm={a}")
                col = values[:, len(expected_names)]
                np.testing.assert_allclose(col, _single(float(h), float(a), q), rtol=0, atol=1e-12)
    assert header[1:] == expected_names


def test_predict_vary_table_one_geometry(tmp_path):
    (tmp_path / "s.toml").write_text(VARNISH)
    table = tmp_path / "samples.csv"
    table.write_text("varnish.thickness_nm,varnish.alpha_per_nm\n15000,2e-5\n40000,1e-6\n")
    out = tmp_path / "t.csv"
    assert main(["predict", str(tmp_path / "s.toml"), "-g", "specular:0:T", "-w", "400:700:10", "-o", str(out),
                 "--vary-table", str(table), "--digits", "17"]) == 0
    header, values = _read_csv(out)
    assert header == ["wavelength_nm", "varnish.thickness_nm=15000 varnish.alpha_per_nm=2e-05",
                      "varnish.thickness_nm=40000 varnish.alpha_per_nm=1e-06"]
    np.testing.assert_allclose(values[:, 1], _single(15000.0, 2e-5, "T"), rtol=0, atol=1e-12)
    np.testing.assert_allclose(values[:, 2], _single(40000.0, 1e-6, "T"), rtol=0, atol=1e-12)


@pytest.mark.parametrize("vary, message", [
    ("varnish.thickness=1:2:1", "unknown field 'thickness' of layer 'varnish'"),
    ("paint.thickness_nm=1:2:1", "no layer named 'paint'"),
    ("background.rho_g=0:1:0.5", "has a [substrate], not a [background]"),
    ("varnish.thickness_nm=-5:5:5", "must be >= 0"),
    ("varnish.thickness_nm=5e4:1e4:1e3", "stop must be >= start"),
    ("varnish.thickness_nm=1e4:x:1e3", "use start:stop:step"),
])
def test_predict_vary_errors_name_the_field(tmp_path, capsys, vary, message):
    (tmp_path / "s.toml").write_text(VARNISH)
    assert main(["predict", str(tmp_path / "s.toml"), "-g", "specular:0", "-o", str(tmp_path / "e.csv"),
                 "--vary", vary]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and vary.split("=")[0] in err
    assert not (tmp_path / "e.csv").exists()


def test_mask_formats_and_envi_geometry_metadata(tmp_path):
    """The mask readers (npy, zarr, one-band ENVI) agree; a mask that is not 0/1 is refused;
    an ENVI header's ``geometry`` key is what the cube states."""
    import xarray as xr

    from layerstack_cli._cube import _read_mask, _stated_geometry
    from layerstack_jax import open_cube

    envi = pytest.importorskip("spectral.io.envi")
    mask = np.ones((NY, NX), bool)
    mask[MASKED_PIXEL] = False
    np.save(tmp_path / "m.npy", mask.astype(np.uint8))
    xr.Dataset({"keep": (("y", "x"), mask)}).to_zarr(tmp_path / "m.zarr", consolidated=False)
    envi.save_image(str(tmp_path / "m.hdr"), mask.astype(np.uint8)[..., None])
    for name in ("m.npy", "m.zarr", "m.hdr"):
        np.testing.assert_array_equal(_read_mask(str(tmp_path / name), (NY, NX)), mask, err_msg=name)
    np.save(tmp_path / "bad.npy", np.full((NY, NX), 2))
    with pytest.raises(ls.LayerstackError, match=r"bad.npy: mask values must be true/false or 1/0"):
        _read_mask(str(tmp_path / "bad.npy"), (NY, NX))
    envi.save_image(str(tmp_path / "c.hdr"), CUBE[..., :3].astype(np.float32),
                    metadata={"wavelength": [400, 410, 420], "wavelength units": "nm", "geometry": "45/0"})
    assert _stated_geometry(open_cube(tmp_path / "c.hdr"), str(tmp_path / "c.hdr")) == ["45/0"]


@pytest.mark.slow  # timing-dependent: a child process killed mid-run (as tests/test_cube.py's own kill test)
def test_killed_command_restarted_resumes(cube_files, tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    import xarray as xr

    d = cube_files
    out = tmp_path / "maps.zarr"
    argv = [sys.executable, "-m", "layerstack_cli", "fit-cube", str(d / "model.toml"), str(d / "cube.zarr"), "-o",
            str(out), "--chunk", "1", "--batch", "1", "--sigma", "1e-3", "--quiet", "--no-quicklook"]
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    child = subprocess.Popen(argv, cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    markers = tmp_path / "maps.zarr.regions"
    deadline = time.time() + 400
    while time.time() < deadline and child.poll() is None:
        if markers.exists() and len(list(markers.glob("*_*"))) >= 3:
            break
        time.sleep(0.02)
    assert child.poll() is None, child.communicate()[1][-2000:]
    child.send_signal(signal.SIGKILL)
    child.wait()
    done = len([p for p in markers.glob("*_*") if not p.name.endswith(".tmp")])
    assert 3 <= done < NY * NX  # 30 regions of one pixel: killed mid-way
    again = subprocess.run(argv, cwd=root, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-2000:]
    assert f"resuming: {done} of {NY * NX} chunks already written" in again.stdout
    maps = xr.open_zarr(out, consolidated=False).load()
    ok = maps["status"].values == 0
    assert ok.sum() == NY * NX  # every pixel (no mask here), the NaN-band one from its other bands
    np.testing.assert_allclose(maps["thickness_nm_film"].values[ok], D_TRUE[ok], atol=0.05)
