"""`layerstack predict --vary` writes large batches where users load them (.nc/.zarr through xarray,
.npz, .npy), refuses a CSV of more spectra than a CSV can usefully hold, and calls out angles that
read like radians. Expected spectra: `ls.predict` on the same stacks in Python."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_cli import main

ROOT = Path(__file__).resolve().parents[1]
PAINTING = ROOT / "examples" / "varnished_painting.toml"
FILM = ROOT / "examples" / "thin_film_on_metal.toml"
GRID = "400:700:25"
THICKNESSES = np.array([10_000.0, 20_000.0, 30_000.0])


def _expected(geometry: str) -> np.ndarray:
    """The same batch through the Python API."""
    stack = ls.load_stack(PAINTING)
    wl = ls.parse_wavelengths(GRID)
    varnish = stack.layers[0]
    batched = ls.Stack(stack.ambient, [ls.Layer(varnish.index, THICKNESSES[:, None], coherent=False,
                                                alpha=varnish.alpha, name=varnish.name)], stack.exit)
    return np.asarray(ls.predict(batched, wl, ls.parse_geometry(geometry), batch_shape=(3,)))


def _predict(out: Path, *extra) -> int:
    return main(["predict", str(PAINTING), "-w", GRID, "-g", "45/0", "-g", "sphere:8:sce",
                 "--vary", "varnish.thickness_nm=1e4:3e4:1e4", "-o", str(out), *extra])


@pytest.mark.parametrize("suffix", [".nc", ".zarr"])
def test_batch_as_an_xarray_dataset(tmp_path, suffix):
    xr = pytest.importorskip("xarray")
    out = tmp_path / f"batch{suffix}"
    assert _predict(out) == 0
    ds = xr.open_zarr(out, consolidated=False) if suffix == ".zarr" else xr.open_dataset(out, engine="h5netcdf")
    assert ds["45_0"].dims == ("sample", "wavelength_nm")
    np.testing.assert_array_equal(ds["varnish.thickness_nm"].values, THICKNESSES)
    np.testing.assert_allclose(ds["wavelength_nm"].values, np.arange(400.0, 701.0, 25.0))
    np.testing.assert_allclose(ds["45_0"].values, _expected("45/0"), rtol=1e-12)
    np.testing.assert_allclose(ds["sphere:8:sce"].values, _expected("sphere:8:sce"), rtol=1e-12)
    assert ds["45_0"].attrs["geometry"] == "45/0"


def test_batch_as_numpy_files(tmp_path):
    assert _predict(tmp_path / "b.npz") == 0
    z = np.load(tmp_path / "b.npz")
    assert list(z["fields"]) == ["varnish.thickness_nm"] and list(z["geometries"]) == ["45/0", "sphere:8:sce"]
    np.testing.assert_array_equal(z["values"][:, 0], THICKNESSES)
    np.testing.assert_allclose(z["reading_0"], _expected("45/0"), rtol=1e-12)
    assert _predict(tmp_path / "b.npy") == 0
    a = np.load(tmp_path / "b.npy")
    assert a.shape == (2, 3, 13)
    np.testing.assert_allclose(a[1], _expected("sphere:8:sce"), rtol=1e-12)


def test_csv_refuses_more_spectra_than_it_can_hold(tmp_path, capsys, monkeypatch):
    import layerstack_cli._predict as predict_cli

    monkeypatch.setattr(predict_cli, "CSV_MAX_COLUMNS", 5)
    assert _predict(tmp_path / "b.csv") == 2
    err = capsys.readouterr().err
    assert "6 spectra are too many for a CSV" in err and ".nc or .zarr" in err
    assert not (tmp_path / "b.csv").exists()


def test_output_suffix_is_checked_before_any_work(tmp_path, capsys):
    assert _predict(tmp_path / "b.xlsx") == 2
    assert "write one of .csv, .nc, .zarr, .npz, .npy" in capsys.readouterr().err
    rc = main(["predict", str(PAINTING), "-w", GRID, "-g", "45/0", "-o", str(tmp_path / "one.npy")])
    assert rc == 2 and "for --vary/--vary-table batches" in capsys.readouterr().err


def test_ellipsometry_angle_in_radians_is_called_out(tmp_path):
    with pytest.warns(ls.LayerstackWarning, match=r"ellipsometry:1\.2217:psi.*radians given"):
        assert main(["predict", str(FILM), "-w", "400:700:50", "-g", "specular:1.2217",
                     "--ellipsometry", "1.2217", "-o", str(tmp_path / "e.csv")]) == 0
    with pytest.warns(ls.LayerstackWarning, match=r"specular:1\.2217.*radians given"):
        assert main(["predict", str(FILM), "-w", "400:700:50", "-g", "specular:1.2217",
                     "-o", str(tmp_path / "s.csv")]) == 0


def test_incoherent_thickness_in_micrometres_is_called_out_on_the_command_line(tmp_path):
    with pytest.warns(ls.LayerstackWarning, match=r"varnish\): thickness \(nm\) 30\.0.*µm given"):
        assert main(["predict", str(PAINTING), "-w", GRID, "-g", "45/0", "--vary", "varnish.thickness_nm=30,30000",
                     "-o", str(tmp_path / "v.csv")]) == 0


def test_alpha_in_per_cm_is_called_out_on_the_command_line(tmp_path):
    (tmp_path / "v.toml").write_text('[[layers]]\nname = "varnish"\nn = 1.54\nthickness_nm = 30000\ncoherent = false\n'
                                     'alpha_per_nm = 20\n[background]\nn = 1.5\nrho_g = 0.6\n')
    with pytest.warns(ls.LayerstackWarning, match=r"varnish\): alpha \(1/nm\) 20\.0.*1/cm given"):
        assert main(["predict", str(tmp_path / "v.toml"), "-w", GRID, "-g", "45/0", "-o", str(tmp_path / "v.csv")]) == 0
