"""Instrument-file readers and the Measurement object (layerstack_jax._files.readers, _measurement).

References, independent of the code under test:
* numbers copied by hand from the files' text (first/last rows) and the sources' own tests
  (refellips test_dataSE.py, pyElli tests/test_wollam.py, test_accurion.py);
* the peer readers pyElli (``elli``) and refellips where installed (skipped otherwise);
* the same measurement in two formats (CompleteEASE .dat and NeXus .nxs);
* the thickness each source documents (refellips demo fit, sample descriptions), fitted here with
  the library's forward model on ψ and cos Δ (cos Δ does not depend on the sign convention of Δ).
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_jax._files.measurement import Measurement, component_names
from layerstack_jax._files.readers import (
    HC_EV_NM,
    read_accurion,
    read_jcamp,
    read_measurement,
    read_measurement_csv,
    read_nexus,
    read_sentech,
    read_woollam,
    sniff_format,
    wavelength_to_nm,
    write_measurement_csv,
)
from layerstack_jax._base.validate import LayerstackError

DATA = Path(__file__).resolve().parents[1] / "examples" / "data"
WVASE_GLASS = DATA / "woollam_wvase_glass.dat"
WVASE_PNIPAM = DATA / "woollam_wvase_11nm_PNIPAM_on_Si.dat"
CEASE = DATA / "woollam_completeease_2nm_SiO2_on_Si.dat"
M2000 = DATA / "woollam_completeease_m2000.dat"
SENTECH_PD = DATA / "sentech_SiO2_on_Si_psi_delta.txt"
SENTECH_MM = DATA / "sentech_SiO2_on_Si_mueller_70deg.txt"
NEXUS = DATA / "nexus_2nm_SiO2_on_Si.nxs"
NEXUS_OPT = DATA / "nexus_2nm_SiO2_on_Si_nx_opt.nxs"
EP4 = DATA / "accurion_ep4_15-1-1.dat"
ACCURION = DATA / "accurion_Si3N4_on_BF33.ds.dat"
JCAMP = DATA / "jcamp_ir_transmittance_dupdec2.jdx"
JCAMP_PCT = DATA / "jcamp_ir_percent_transmittance_fixinc1.jdx"

ALL_FILES = {
    WVASE_GLASS: "woollam",
    WVASE_PNIPAM: "woollam",
    CEASE: "woollam",
    M2000: "woollam",
    SENTECH_PD: "sentech",
    SENTECH_MM: "sentech",
    NEXUS: "nexus",
    NEXUS_OPT: "nexus",
    EP4: "accurion",
    ACCURION: "accurion",
    JCAMP: "jcamp",
    JCAMP_PCT: "jcamp",
}


def _options(path):
    return {JCAMP: dict(angle_deg=0.0), JCAMP_PCT: dict(angle_deg=0.0, percent=True)}.get(path, {})


# ------------------------------------------------------------------------------------------
# every reader on a real file: values from the file's text and the sources' own tests
# ------------------------------------------------------------------------------------------
def test_data_files_small_and_documented():
    readme = (DATA / "README.md").read_text(encoding="utf-8")
    for path in ALL_FILES:
        assert path.stat().st_size < 300_000, path.name
        assert path.name in readme, f"{path.name} has no provenance in examples/data/README.md"


@pytest.mark.filterwarnings("ignore:.*transmittance spans")  # fixinc1: %T up to 112.9
@pytest.mark.parametrize("path", list(ALL_FILES), ids=lambda p: p.name)
def test_sniffing_picks_the_format(path):
    assert sniff_format(path) == ALL_FILES[path]
    m = read_measurement(path, **_options(path))
    assert m.file_format == ALL_FILES[path]
    assert m.delta_convention == "instrument"
    assert m.source == str(path)
    assert m.valid().any()


def test_wvase_export():
    m = read_woollam(WVASE_GLASS)
    # pyElli tests/test_wollam.py: 543 (angle, wavelength) points from 300 to 1200 nm
    assert m.quantity == "psi_delta" and m.values.shape == (3, 2, 181)
    assert m.valid().sum() == 543
    np.testing.assert_array_equal(m.angles_deg, [65.0, 70.0, 75.0])
    assert (m.wavelength_nm[0], m.wavelength_nm[-1]) == (300.0, 1200.0)
    # first data row of the file: "300.000000 65.000000 12.140821 1.5609661 0.37071 3.46024"
    np.testing.assert_array_equal(m.values[0, :, 0], [12.140821, 1.5609661])
    np.testing.assert_array_equal(m.sigma[0, :, 0], [0.37071, 3.46024])
    # last E row: "1200.000000 75.000000 27.725864 0.55148453 0.052391 0.231062"
    np.testing.assert_array_equal(m.values[2, :, -1], [27.725864, 0.55148453])
    # dpolE rows kept as written (4 angles x 71 wavelengths), not on the psi/delta grid
    assert m.extras["dPolE"].shape == (284, 4)
    np.testing.assert_array_equal(m.extras["dPolE"][0], [300.0, 55.0, 1.30314, 0.978814])
    assert np.isnan(m.depolarization()).all()  # dpolE angles 55-58 deg, psi/delta 65-75 deg
    assert m.meta["title"].startswith("Glas substrate with tape")
    assert m.meta["wavelength_unit"] == "nm"


def test_completeease_export_in_angstroms():
    m = read_woollam(CEASE)
    assert m.meta["wavelength_unit"] == "angstrom" and m.meta["title"] == "2nm SiO2 on Si on RC2"
    # trimmed file: 272 of the 1088 wavelengths (pyElli: 3264 = 3 x 1088 points, 193-1700 nm)
    assert m.values.shape == (3, 2, 272)
    # first row "E 1930.000000 50.000000 40.014217 142.127655 0.008585 0.034774": 1930 A = 193 nm
    assert m.wavelength_nm[0] == pytest.approx(193.0, abs=1e-12)
    np.testing.assert_array_equal(m.values[0, :, 0], [40.014217, 142.127655])
    np.testing.assert_array_equal(m.sigma[0, :, 0], [0.008585, 0.034774])
    # dPolE "dPolE 1930.000000 50.000000 1.800296 0.165269" -> 1.800296 % on the grid
    assert m.depolarization()[0, 0] == pytest.approx(0.01800296, abs=1e-15)
    assert np.isfinite(m.depolarization()).all()
    np.testing.assert_array_equal(m.extras["uR"][0], [193.0, 50.0, np.inf, 1.0])


def test_completeease_m2000_matches_refellips_reference_values():
    # refellips tests/test_dataSE.py::test_M2000_loader (every 40th wavelength, 70 deg)
    bench = np.array(
        [
            [370.324, 70, 21.4553, 145.7525],
            [434.059, 70, 8.6922, 157.8022],
            [497.825, 70, 4.7986, 152.0333],
            [561.586, 70, 2.8442, 141.3818],
            [625.304, 70, 1.7848, 123.4001],
            [688.942, 70, 1.2906, 97.0818],
            [752.463, 70, 1.2037, 69.1318],
            [815.829, 70, 1.3271, 49.0608],
            [879.003, 70, 1.5043, 36.8692],
            [941.948, 70, 1.6879, 28.9926],
        ]
    )
    m = read_woollam(M2000)
    assert m.meta["title"] == "" and "CompleteEASE=3.65" in m.meta["method"]
    np.testing.assert_array_equal(m.angles_deg, [70.0])
    sel = np.searchsorted(m.wavelength_nm, bench[:, 0])
    np.testing.assert_allclose(m.wavelength_nm[sel], bench[:, 0], rtol=1e-12)
    np.testing.assert_allclose(m.psi_deg[0, sel], bench[:, 2], rtol=1e-12)
    np.testing.assert_allclose(m.delta_deg[0, sel], bench[:, 3], rtol=1e-12)
    assert set(m.extras) == {"dPolE", "uR"}


def test_sentech_psi_delta_export():
    m = read_sentech(SENTECH_PD)
    np.testing.assert_array_equal(m.angles_deg, [50.2, 60.2, 70.2])
    assert m.values.shape == (3, 2, 2209) and m.sigma is None
    # first row: "190.13558 45.74309 168.36886 55.11351 170.81765 56.03301 118.52958"
    assert m.wavelength_nm[0] == 190.13558
    np.testing.assert_array_equal(m.values[:, :, 0], [[45.74309, 168.36886], [55.11351, 170.81765], [56.03301, 118.52958]])
    # Delta kept as SpectraRay reports it (0..360 deg), not wrapped
    assert m.delta_deg.max() > 180.0
    assert m.delta_deg[0, 1] == 187.30627  # second row, 50.2 deg


def test_sentech_mueller_export():
    m = read_sentech(SENTECH_MM)
    assert m.quantity == "mueller" and m.mueller_normalized
    assert m.values.shape == (1, 4, 4, 1105)
    np.testing.assert_array_equal(m.angles_deg, [70.2])
    # first row of the file, M11 ... M44 row-major
    first = [1.0, 0.51251, 0.01932, -0.25386, 0.42243, 0.88447, -0.01350, 0.06720,
             -0.00949, 0.09000, -0.48318, 0.75947, 0.03951, 0.27812, -1.00000, 0.01332]
    np.testing.assert_array_equal(m.values[0, :, :, 0].ravel(), first)
    assert m.to_arrays()["M34"][0, 0] == 0.75947  # M34 as measured
    assert component_names("mueller")[11] == "M34"


@pytest.mark.parametrize("path", [NEXUS, NEXUS_OPT], ids=lambda p: p.name)
def test_nexus_is_the_completeease_measurement(path):
    """Two formats, one measurement: the NeXus files hold the CompleteEASE data."""
    m = read_nexus(path)
    c = read_woollam(CEASE)
    assert m.values.shape == (3, 2, 1088)
    assert m.meta["layer_structure"] == "2nm SiO2 on Si"
    np.testing.assert_array_equal(m.angles_deg, c.angles_deg)
    idx = np.searchsorted(m.wavelength_nm, c.wavelength_nm)
    np.testing.assert_allclose(m.wavelength_nm[idx], c.wavelength_nm, rtol=1e-14)
    np.testing.assert_array_equal(m.values[..., idx], c.values)
    if path == NEXUS_OPT:
        np.testing.assert_array_equal(m.sigma[..., idx], c.sigma)
    else:
        assert m.sigma is None


def test_accurion_ep4_zone_average_matches_refellips():
    m = read_accurion(EP4)
    np.testing.assert_array_equal(m.angles_deg, np.arange(50.0, 71.0, 2.0))
    np.testing.assert_array_equal(m.wavelength_nm, [658.0])
    # refellips test_dataSE.py::test_multiple_areas: last psi = 12.72666667 (zones 1-3; zone 4 NaN)
    assert m.psi_deg[-1, 0] == pytest.approx(12.72666667, abs=1e-8)
    # 50 deg: zones 4, 2, 1, 3 of the file
    assert m.delta_deg[0, 0] == pytest.approx(np.mean([169.624, 169.785, 169.598, 169.565]), abs=1e-12)
    assert m.meta["zones_averaged"] == "4"


def test_accurion_spectroscopic_latin1_export():
    m = read_accurion(ACCURION)
    assert m.valid().sum() == 114  # pyElli tests/test_accurion.py: 114 points
    np.testing.assert_array_equal(m.angles_deg, [40.0, 50.0])
    # first row: "0 40.000 365.0 ... 179.785156 32.535931" (Delta, Psi)
    np.testing.assert_array_equal(m.values[0, :, 0], [32.535931, 179.785156])


def test_jcamp_transmittance():
    m = read_jcamp(JCAMP, angle_deg=0.0)
    assert m.quantity == "transmittance"
    assert m.values.shape == (1, 3951)  # ##NPOINTS= 3951
    # x from 4400 to 450 cm-1 -> 2272.7 to 22222.2 nm, sorted increasing
    assert m.wavelength_nm[0] == pytest.approx(1e7 / 4400.0, rel=1e-15)
    assert m.wavelength_nm[-1] == pytest.approx(1e7 / 450.0, rel=1e-15)
    assert m.values[0, 0] == pytest.approx(0.5839, abs=1e-12)  # ##FIRSTY= 0.5839, at 4400 cm-1
    # ##MAXY= 79.17, ##MINY= 0.19 are in % (the file's header); the data (YFACTOR 1e-4) in fractions
    assert np.nanmax(m.values) == pytest.approx(0.7917, abs=1e-12)
    assert np.nanmin(m.values) == pytest.approx(0.0019, abs=1e-12)
    assert m.meta["owner"] == "Public Domain"


def test_jcamp_percent_transmittance():
    with pytest.warns(UserWarning, match=r"transmittance spans \[-0.001987, 1.129\] .*outside \[0, 1\]"):
        m = read_jcamp(JCAMP_PCT, angle_deg=0.0, percent=True)
    assert m.values.shape == (1, 3736)  # ##NPOINTS= 3736
    assert m.values[0, -1] == pytest.approx(1.128905654, rel=1e-6)  # ##FIRSTY= 112.89 %T at 399.26 cm-1


# ------------------------------------------------------------------------------------------
# peer readers (pyElli, refellips), where installed
# ------------------------------------------------------------------------------------------
def _elli():
    return pytest.importorskip("elli")


@pytest.mark.parametrize(
    "path,reader",
    [(WVASE_GLASS, "read_woollam_psi_delta"), (CEASE, "read_woollam_psi_delta"),
     (SENTECH_PD, "read_spectraray_psi_delta"), (NEXUS, "read_nexus_psi_delta"),
     (NEXUS_OPT, "read_nexus_psi_delta"), (ACCURION, "read_accurion_psi_delta")],
    ids=lambda x: getattr(x, "name", x),
)
def test_psi_delta_as_pyelli_reads_it(path, reader):
    elli = _elli()
    ref = getattr(elli, reader)(path)
    m = read_measurement(path)
    for ia, angle in enumerate(m.angles_deg):
        sub = ref.loc[angle]
        np.testing.assert_allclose(sub.index.values, m.wavelength_nm, rtol=1e-12)
        np.testing.assert_allclose(sub["Ψ"].values, m.psi_deg[ia], rtol=1e-12)
        # pyElli wraps SpectraRay's Delta into (-180, 180]; we keep the file's value
        d = (sub["Δ"].values - m.delta_deg[ia] + 180.0) % 360.0 - 180.0
        np.testing.assert_allclose(d, 0.0, atol=1e-9)


def test_mueller_as_pyelli_reads_it():
    elli = _elli()
    ref = elli.read_spectraray_mmatrix(SENTECH_MM)
    m = read_sentech(SENTECH_MM)
    np.testing.assert_allclose(ref.index.values, m.wavelength_nm, rtol=1e-12)
    for name in component_names("mueller"):
        np.testing.assert_array_equal(ref[name].values, m.to_arrays()[name][0])


def test_accurion_as_refellips_reads_it():
    dataSE = pytest.importorskip("refellips.dataSE")
    ref = dataSE.open_EP4file(EP4)
    m = read_accurion(EP4)
    np.testing.assert_array_equal(ref.aoi, m.angles_deg)
    np.testing.assert_allclose(ref.psi, m.psi_deg[:, 0], rtol=1e-12)
    np.testing.assert_allclose(ref.delta, m.delta_deg[:, 0], rtol=1e-12)


# ------------------------------------------------------------------------------------------
# the thickness each source documents, fitted with the library's forward model
# ------------------------------------------------------------------------------------------
def _fit_thickness(m: Measurement, build, lo: float, hi: float) -> float:
    """Least-squares thickness on ψ (rad) and cos Δ by a two-stage grid (convention-free in Δ's sign)."""
    psi = np.deg2rad(m.psi_deg)
    cos_delta = np.cos(np.deg2rad(m.delta_deg))

    @jax.jit
    @jax.vmap
    def cost(d):
        e = ls.ellipsometry(build(d), m.wavelength_nm, m.angles_deg)
        return jnp.sum((jnp.deg2rad(e.psi_deg) - psi) ** 2) + jnp.sum((jnp.cos(jnp.deg2rad(e.delta_deg)) - cos_delta) ** 2)

    grid = np.linspace(lo, hi, 201)
    best = grid[np.argmin(cost(jnp.asarray(grid)))]
    step = grid[1] - grid[0]
    fine = np.linspace(best - step, best + step, 201)
    return float(fine[np.argmin(cost(jnp.asarray(fine)))])


def test_pnipam_thickness_as_refellips_documents():
    # refellips demos/refellipsDemo.ipynb: PNIPAM Cauchy(A=1.47, B=0.00495) over 2 nm SiO2 on Si,
    # fitted thickness 113.501 +/- 0.544 A (its Si and SiO2 tables; ours: Aspnes, Malitson)
    m = read_measurement(WVASE_PNIPAM)
    si, sio2 = ls.material("Si", "Aspnes"), ls.material("SiO2", "Malitson")
    pnipam = ls.Cauchy(1.47, 0.00495)
    d = _fit_thickness(m, lambda d: ls.Stack(1.0, [ls.Layer(pnipam, d), ls.Layer(sio2, 2.0)], ls.Substrate(si)), 5.0, 25.0)
    assert d == pytest.approx(11.35, abs=0.3)


@pytest.mark.parametrize("path", [CEASE, NEXUS], ids=lambda p: p.name)
def test_native_oxide_thickness_as_the_sample_says(path):
    # "2nm SiO2 on Si" (sample description in both files)
    m = read_measurement(path).between(400.0, 820.0)
    si, sio2 = ls.material("Si", "Aspnes"), ls.material("SiO2", "Malitson")
    d = _fit_thickness(m, lambda d: ls.Stack(1.0, [ls.Layer(sio2, d)], ls.Substrate(si)), 0.0, 6.0)
    assert d == pytest.approx(2.0, abs=0.3)


# ------------------------------------------------------------------------------------------
# round trip through the measurement CSV
# ------------------------------------------------------------------------------------------
@pytest.mark.filterwarnings("ignore:.*transmittance spans")  # fixinc1: %T up to 112.9
@pytest.mark.parametrize("path", list(ALL_FILES), ids=lambda p: p.name)
def test_round_trip_is_identical(path, tmp_path):
    m = read_measurement(path, **_options(path))
    out = write_measurement_csv(tmp_path / "m.csv", m)
    assert sniff_format(out) == "csv"
    back = read_measurement(out)
    assert back.equals(m)
    assert back.metadata == m.metadata and back.file_format == m.file_format


def test_round_trip_of_selections_with_missing_points(tmp_path):
    m = read_woollam(CEASE).at_angle(60.0).between(300.0, 600.0)
    assert m.angles_deg.tolist() == [60.0]
    values = m.values.copy()
    values[0, :, 3] = np.nan  # a point the file does not have
    odd = (("note", "  leading spaces, a = sign, ψ/Δ and µm  "), ("note", "a repeated key"))
    m = Measurement(quantity=m.quantity, angles_deg=m.angles_deg, wavelength_nm=m.wavelength_nm,
                    values=values, sigma=m.sigma, extras=m.extras, file_format=m.file_format,
                    source=m.source, metadata=m.metadata + odd)
    back = read_measurement_csv(write_measurement_csv(tmp_path / "m.csv", m))
    assert back.equals(m)
    assert not back.valid()[0, 3] and back.valid().sum() == m.wavelength_nm.size - 1
    assert not back.equals(read_woollam(CEASE))
    assert back.metadata[-2:] == odd


def test_woollam_wavelengths_in_ev(tmp_path):
    p = _write(tmp_path, "ev.dat", "film\neV\n2.0\t70\t10\t120\t0.1\t0.2\n3.0\t70\t11\t130\t0.1\t0.3\n")
    assert sniff_format(p) == "woollam"
    m = read_measurement(p)
    np.testing.assert_allclose(m.wavelength_nm, [1239.841984 / 3.0, 1239.841984 / 2.0], rtol=1e-9)
    np.testing.assert_array_equal(m.values[0, :, 0], [11.0, 130.0])  # sorted by wavelength


# ------------------------------------------------------------------------------------------
# plain CSV: headers, units, percent
# ------------------------------------------------------------------------------------------
def _write(tmp_path, name, text, encoding="utf-8"):
    p = tmp_path / name
    p.write_text(text, encoding=encoding)
    return p


def test_csv_quoted_headers_as_r_writes_them(tmp_path):
    p = _write(tmp_path, "r.csv", '"","Wavelength (nm)","R (%)"\n"1",400,4.5\n"2",500,5.5\n')
    m = read_measurement(p, angle_deg=8.0)
    assert m.quantity == "reflectance"
    np.testing.assert_array_equal(m.wavelength_nm, [400.0, 500.0])
    np.testing.assert_allclose(m.values, [[0.045, 0.055]], rtol=1e-15)
    assert m.angles_deg.tolist() == [8.0] and m.meta["angle_source"] == "given by the caller"
    assert m.meta["ignored_columns"] == ""


def test_csv_excel_semicolon_decimal_comma_micrometres(tmp_path):
    p = _write(tmp_path, "t.csv", "Wavelength [µm];%T\n0,4;91,5\n0,55;92,25\n")
    m = read_measurement_csv(p, angle_deg=0.0)
    assert m.quantity == "transmittance"
    np.testing.assert_allclose(m.wavelength_nm, [400.0, 550.0], rtol=1e-15)
    np.testing.assert_allclose(m.values, [[0.915, 0.9225]], rtol=1e-15)


def test_csv_energy_in_ev_and_psi_delta_with_sigma(tmp_path):
    p = _write(
        tmp_path, "e.csv",
        "# measured on a bench ellipsometer\nenergy (eV)\tangle (deg)\tpsi\tdelta\tsigma_psi\tsigma_delta\n"
        "2.0\t70\t10\t120\t0.1\t0.2\n3.0\t70\t11\t130\t0.1\t0.3\n",
    )
    m = read_measurement(p)
    # lambda = hc/E, hc = 1239.841984 eV nm (CODATA)
    np.testing.assert_allclose(m.wavelength_nm, [1239.841984 / 3.0, 1239.841984 / 2.0], rtol=1e-9)
    np.testing.assert_array_equal(m.psi_deg, [[11.0, 10.0]])
    np.testing.assert_array_equal(m.sigma[0, 1], [0.3, 0.2])


def test_csv_angle_in_radians_converted(tmp_path):
    p = _write(tmp_path, "a.csv", "wavelength_nm,angle (rad),psi,delta\n500," + repr(np.pi / 3) + ",20,100\n")
    m = read_measurement_csv(p)
    assert m.angles_deg[0] == pytest.approx(60.0, abs=1e-12)


def test_wavelength_units():
    assert wavelength_to_nm(5000.0, "Angstroms") == 500.0
    assert wavelength_to_nm(0.5, "µm") == 500.0
    assert wavelength_to_nm(20000.0, "cm-1") == 500.0
    assert wavelength_to_nm(2.0, "eV") == pytest.approx(619.920992, abs=1e-6)
    assert HC_EV_NM == pytest.approx(1239.84198433, abs=1e-8)
    with pytest.raises(LayerstackError, match="unknown wavelength unit"):
        wavelength_to_nm(1.0, "furlong")


# ------------------------------------------------------------------------------------------
# clear errors: wrong unit, wrong format, truncated files (file, line and why)
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "text,match",
    [
        ("wavelength,R\n400,0.1\n", r"line 1: column 'wavelength': no wavelength unit"),
        ("wavelength_nm,R\n400,45.1\n500,47\n", r"line 3: column 'R' = 47: a fraction cannot exceed 1.*'R \(%\)'"),
        ("wavelength_nm,R,T\n400,0.1,0.8\n", r"line 1: the file holds reflectance, transmittance: pass quantity="),
        ("wavelength_nm,psi,delta\n400,10,100\n", r"line 1: no angle-of-incidence column: pass angle_deg="),
        ("wavelength_nm,angle,psi,delta\n400,70,10,100\n500,70,x,100\n", r"line 3: column 'psi': 'x' is not a number"),
        ("wavelength_nm,angle,psi,delta\n400,70,10,100\n500,70,11\n", r"line 3: 3 fields, the header has 4 \(truncated file\?\)"),
        ("wavelength_nm,angle,psi,delta\n400,70,100,100\n", r"line 2: psi = 100.0 is not in \[0, 90\] degrees"),
        ("wavelength_nm,angle,psi,delta\n400,95,10,100\n", r"line 2: angle of incidence = 95.0"),
        ("wavelength_nm,foo\n400,1\n", r"line 1: no measured columns"),
        ("lambda (nm),angle,psi,delta\n", r"a header but no data rows"),
    ],
)
def test_csv_errors_name_line_and_why(tmp_path, text, match):
    p = _write(tmp_path, "bad.csv", text)
    with pytest.raises(LayerstackError, match=match) as info:
        read_measurement_csv(p, **({"angle_deg": 0.0} if "R" in text.split("\n")[0] else {}))
    assert "bad.csv" in str(info.value)


def test_csv_quantity_choice(tmp_path):
    p = _write(tmp_path, "rt.csv", "wavelength_nm,R,T\n400,0.1,0.8\n")
    assert read_measurement_csv(p, angle_deg=0.0, quantity="transmittance").values[0, 0] == 0.8


def _truncate(src: Path, dst: Path, keep_bytes: int) -> Path:
    dst.write_bytes(src.read_bytes()[:keep_bytes])
    return dst


def test_truncated_woollam_names_the_last_line(tmp_path):
    text = WVASE_GLASS.read_bytes()
    cut = text.index(b"\n", 3000) + 25  # in the middle of a row
    p = _truncate(WVASE_GLASS, tmp_path / "cut.dat", cut)
    n_lines = p.read_text().count("\n") + 1
    with pytest.raises(LayerstackError, match=rf"cut.dat, line {n_lines}: expected 4 or 6 numbers.*got 3 \(truncated file\?\)"):
        read_woollam(p)


def test_truncated_sentech_names_the_last_line(tmp_path):
    text = SENTECH_PD.read_bytes()
    p = _truncate(SENTECH_PD, tmp_path / "cut.txt", text.index(b"\n", 5000) + 30)
    with pytest.raises(LayerstackError, match=r"cut.txt, line \d+: expected 7 numbers .* \(truncated file\?\)"):
        read_sentech(p)


def test_truncated_jcamp_and_nexus(tmp_path):
    p = _truncate(JCAMP, tmp_path / "cut.jdx", 3000)
    with pytest.raises(LayerstackError, match=r"cut.jdx, line \d+: the file ends without '##END=' \(truncated\?\)"):
        read_jcamp(p, angle_deg=0.0)
    p = _truncate(NEXUS, tmp_path / "cut.nxs", 20_000)
    with pytest.raises(LayerstackError, match=r"cut.nxs: not an HDF5/NeXus file"):
        read_nexus(p)


def test_wrong_format_for_the_reader(tmp_path):
    with pytest.raises(LayerstackError, match=r"line 1: not a SpectraRay export"):
        read_sentech(WVASE_GLASS)
    with pytest.raises(LayerstackError, match=r"no wavelength-unit line .*not a Woollam export"):
        read_woollam(SENTECH_PD)
    with pytest.raises(LayerstackError, match=r"line 1: not a JCAMP-DX file"):
        read_jcamp(CEASE, angle_deg=0.0)
    with pytest.raises(LayerstackError, match=r"not an HDF5/NeXus file"):
        read_nexus(CEASE)
    with pytest.raises(LayerstackError, match=r"line 1: not an Accurion export"):
        read_accurion(_write(tmp_path, "x.dat", "#only one header\n1\t2\n"))


def test_woollam_refusals(tmp_path):
    trig = _write(tmp_path, "trig.dat", "nm  TRIG\n300 70  .245    .123\n")
    with pytest.raises(LayerstackError, match=r"trig.dat, line 1: tan\(psi\)/cos\(delta\) \('TRIG'\)"):
        read_woollam(trig)
    dyn = _write(tmp_path, "dyn.dat", "VASEmethod[x]\nDynamic\nnm\n370.3\t70.0\t30.0\t121.6\t0.1\t0.2\t\t0.02\n")
    with pytest.raises(LayerstackError, match=r"dyn.dat, line 2: time-resolved \('Dynamic'\)"):
        read_woollam(dyn)
    bad = _write(tmp_path, "bad.dat", "title\nnm\n300\t65\t12.1\t1.5\t0.3\t3.4\n310\t65\t97.0\t1.5\t0.3\t3.4\n")
    with pytest.raises(LayerstackError, match=r"bad.dat, line 4: psi = 97.0 is not a number in \[0, 90\]"):
        read_woollam(bad)
    word = _write(tmp_path, "word.dat", "title\nnm\n300\t65\t12.1\t1.5\t0.3\t3.4\n310\t65\tabc\t1.5\t0.3\t3.4\n")
    with pytest.raises(LayerstackError, match=r"word.dat, line 4: 'abc' is not a number"):
        read_woollam(word)


def test_sentech_decimal_comma_and_refusals(tmp_path):
    p = _write(tmp_path, "de.txt", "; WAVELENGTH 70,0 70,0\n500,5 20,25 100,5\n600,0 21,0 101,0\n")
    m = read_sentech(p)
    np.testing.assert_array_equal(m.wavelength_nm, [500.5, 600.0])
    np.testing.assert_array_equal(m.values[0, :, 0], [20.25, 100.5])
    energy = _write(tmp_path, "ev.txt", "; ENERGY 70 70\n2.0 20 100\n")
    with pytest.raises(LayerstackError, match=r"ev.txt, line 1: first column is 'ENERGY'; only wavelength \(nm\)"):
        read_sentech(energy)
    odd = _write(tmp_path, "odd.txt", "; WAVELENGTH 50 60 70\n500 20 100 30\n")
    with pytest.raises(LayerstackError, match=r"odd.txt, line 1: psi/delta exports need the angles in pairs"):
        read_sentech(odd)


def test_woollam_mueller_rows(tmp_path):
    rows = []
    for wl in (400.0, 500.0):
        for i in range(1, 5):
            for j in range(1, 5):
                if (i, j) != (1, 1):
                    rows.append(f"mm{i}{j}\t{wl}\t70.0\t{(i * 4 + j) / 100}\t0.001")
    p = _write(tmp_path, "mm.dat", "Mueller export\nnm\n" + "\n".join(rows) + "\n")
    m = read_woollam(p)
    assert m.quantity == "mueller" and m.mueller_normalized
    assert m.values[0, 0, 0, 0] == 1.0 and m.values[0, 2, 3, 1] == (3 * 4 + 4) / 100  # M34
    np.testing.assert_array_equal(m.sigma[0, 1, 1], [0.001, 0.001])


def test_jcamp_refusals(tmp_path):
    pct = r"fixinc1.jdx, line 13: ##YUNITS= TRANSMITTANCE but the values reach 112.891.*percent=True"
    with pytest.raises(LayerstackError, match=pct):
        read_jcamp(JCAMP_PCT, angle_deg=0.0)
    with pytest.raises(LayerstackError, match=r"gives no angle of incidence: pass angle_deg="):
        read_jcamp(JCAMP)
    absorb = _write(
        tmp_path, "a.jdx",
        "##TITLE= test\n##JCAMP-DX= 4.24\n##DATA TYPE= UV-VISIBLE SPECTRUM\n##XUNITS= NANOMETERS\n"
        "##YUNITS= ABSORBANCE\n##XFACTOR= 1\n##YFACTOR= 1\n##FIRSTX= 400\n##LASTX= 402\n##NPOINTS= 3\n"
        "##XYDATA= (X++(Y..Y))\n400 0.1 0.2 0.3\n##END=\n",
    )
    with pytest.raises(LayerstackError, match=r"a.jdx, line 5: ##YUNITS= 'ABSORBANCE': only reflectance or transmittance"):
        read_jcamp(absorb, angle_deg=0.0)
    refl = _write(tmp_path, "r.jdx", absorb.read_text().replace("ABSORBANCE", "REFLECTANCE"))
    m = read_jcamp(refl, angle_deg=8.0)
    assert m.quantity == "reflectance"
    np.testing.assert_array_equal(m.wavelength_nm, [400.0, 401.0, 402.0])
    np.testing.assert_allclose(m.values, [[0.1, 0.2, 0.3]])


def test_read_measurement_rejects_unknown_options():
    with pytest.raises(LayerstackError, match=r"the woollam reader does not take option\(s\) \['angle_deg'\]"):
        read_measurement(WVASE_GLASS, angle_deg=3.0)
    with pytest.raises(LayerstackError, match="no such file"):
        read_measurement(DATA / "missing.dat")


# ------------------------------------------------------------------------------------------
# the Measurement object
# ------------------------------------------------------------------------------------------
def test_measurement_validation_names_the_field():
    wl, ang = np.array([400.0, 500.0]), np.array([70.0])
    with pytest.raises(LayerstackError, match=r"values .* must have shape \(ang, \*component, wl\) = \(1, 2, 2\)"):
        Measurement(quantity="psi_delta", angles_deg=ang, wavelength_nm=wl, values=np.zeros((1, 2)))
    with pytest.raises(LayerstackError, match="quantity must be one of"):
        Measurement(quantity="ellipsometry", angles_deg=ang, wavelength_nm=wl, values=np.zeros((1, 2)))
    with pytest.raises(LayerstackError, match="wavelength_nm must be finite, > 0 and strictly increasing"):
        Measurement(quantity="reflectance", angles_deg=ang, wavelength_nm=wl[::-1], values=np.zeros((1, 2)))
    with pytest.raises(LayerstackError, match=r"angles_deg must lie in \[0, 90\)"):
        Measurement(quantity="reflectance", angles_deg=np.array([90.0]), wavelength_nm=wl, values=np.zeros((1, 2)))
    m = Measurement(quantity="reflectance", angles_deg=ang, wavelength_nm=wl, values=np.zeros((1, 2)))
    with pytest.raises(LayerstackError, match="needs quantity 'psi_delta'"):
        _ = m.psi_deg
    with pytest.raises(LayerstackError, match=r"angle_deg 45: the measurement .* has angles 70 degrees"):
        m.at_angle(45)
    with pytest.raises(LayerstackError, match=r"no wavelength in \[600, 700\] nm"):
        m.between(600, 700)


def test_measurement_views():
    m = read_woollam(CEASE)
    rho = m.rho()
    psi, delta = np.deg2rad(m.psi_deg), np.deg2rad(m.delta_deg)
    np.testing.assert_allclose(np.abs(rho), np.tan(psi), rtol=1e-13)
    np.testing.assert_allclose(rho.real, np.tan(psi) * np.cos(delta), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(rho.imag, -np.tan(psi) * np.sin(delta), rtol=1e-12, atol=1e-15)
    arrays = m.to_arrays()
    assert set(arrays) == {"wavelength_nm", "angles_deg", "psi", "delta", "sigma_psi", "sigma_delta"}
    np.testing.assert_array_equal(arrays["delta"], m.values[:, 1])
    pts = m.to_points()
    assert pts["psi"].shape == (3 * 272,) and pts["angle_deg"][0] == 50.0
    one = m.at_angle(70.0)
    np.testing.assert_array_equal(one.values[0], m.values[2])
    assert one.extras is not m.extras and set(one.extras) == set(m.extras)


def test_measurement_rho_is_the_models_rho():
    """A ψ/Δ measurement made of the model's own ψ, Δ gives back the model's ρ = r_p/r_s (the two
    conventions agree: no conjugate between a measured and a modelled ρ)."""
    import layerstack_jax as ls

    wl = np.linspace(400.0, 800.0, 5)
    stack = ls.Stack(1.0, [ls.Layer(1.46, 120.0)], ls.Substrate(3.9 + 0.02j))
    e = ls.ellipsometry(stack, wl, np.array([55.0, 70.0]))
    m = Measurement(quantity="psi_delta", angles_deg=np.array([55.0, 70.0]), wavelength_nm=wl,
                    values=np.stack([np.asarray(e.psi_deg), np.asarray(e.delta_deg)], axis=1))
    np.testing.assert_allclose(m.rho(), np.asarray(e.rho), rtol=1e-12, atol=1e-15)


def test_measurement_is_a_pytree_for_jit():
    m = read_woollam(WVASE_PNIPAM)
    total = jax.jit(lambda meas: jnp.sum(meas.values))(m)
    assert float(total) == pytest.approx(np.sum(m.values))
