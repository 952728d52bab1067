"""Files as they come (issue 27): missing points, descending wavelengths, semicolons with decimal
commas, and files cut while they were written — read right, or refused with the file, line,
column and reason.

Expected values are read off the test's own text (the numbers written in it) or parsed here from
the real files with plain string operations, never from the readers under test.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from layerstack_jax import LayerstackError
from layerstack_jax.io import read_measurement, read_measurement_csv, read_spectra_csv, sniff_format

DATA = Path(__file__).resolve().parents[1] / "examples" / "data"
WVASE_GLASS = DATA / "woollam_wvase_glass.dat"
CEASE = DATA / "woollam_completeease_2nm_SiO2_on_Si.dat"
SENTECH_PD = DATA / "sentech_SiO2_on_Si_psi_delta.txt"
ACCURION = DATA / "accurion_Si3N4_on_BF33.ds.dat"


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_bytes(text.encode("utf-8"))
    return p


# ------------------------------------------------------------------------------------------
# measurement CSV (read_measurement_csv / read_measurement)
# ------------------------------------------------------------------------------------------
def test_measurement_csv_nan_and_empty_cells_are_masked_points(tmp_path):
    p = _write(tmp_path, "nan.csv", "wavelength (nm),angle,psi,delta,sigma_psi,sigma_delta\n"
                                    "400,70,10,100,0.1,0.2\n410,70,nan,101,0.1,0.2\n420,70,,102,0.1,\n"
                                    "430,70,11,NA,0.1,0.2\n440,70,12,104,0.1,0.2\n")
    m = read_measurement(p)
    np.testing.assert_array_equal(m.wavelength_nm, [400, 410, 420, 430, 440])
    np.testing.assert_array_equal(m.valid(), [[True, False, False, False, True]])
    np.testing.assert_array_equal(m.psi_deg[0, [0, 3, 4]], [10, 11, 12])
    np.testing.assert_array_equal(m.delta_deg[0, [0, 1, 2, 4]], [100, 101, 102, 104])
    assert np.isnan(m.psi_deg[0, 1]) and np.isnan(m.psi_deg[0, 2]) and np.isnan(m.delta_deg[0, 3])
    assert np.isnan(m.sigma[0, 1, 2]) and m.sigma[0, 1, 1] == 0.2


def test_measurement_csv_descending_semicolon_decimal_comma(tmp_path):
    """An Excel export in a decimal-comma locale, red to blue, one empty cell."""
    p = _write(tmp_path, "de.csv", "Wellenlänge;x\nwavelength (nm);angle;R (%)\n")  # not a header we know
    with pytest.raises(LayerstackError, match=r"de.csv, line 1: no wavelength column"):
        read_measurement_csv(p)
    p = _write(tmp_path, "de.csv", "wavelength (nm);angle;R (%)\n700,5;8;4,25\n600;8;\n500;8;5,5\n")
    m = read_measurement(p)
    np.testing.assert_array_equal(m.wavelength_nm, [500.0, 600.0, 700.5])
    np.testing.assert_allclose(m.values[0, [0, 2]], [0.055, 0.0425], rtol=1e-15)
    assert np.isnan(m.values[0, 1])


def test_measurement_csv_decimal_commas_between_commas_refused_by_name(tmp_path):
    p = _write(tmp_path, "dc.csv", "wavelength (nm),angle,psi,delta\n400,70,10,100\n410,70,10,5,101\n")
    with pytest.raises(LayerstackError, match=r"dc.csv, line 3: 5 fields, the header has 4 \(decimal commas\? they "
                                              r"need ';' or tabs between the columns\)"):
        read_measurement(p)


@pytest.mark.parametrize("text, match", [
    ("wavelength (nm),angle,psi,delta\n400,70,10,100\n,70,11,101\n",
     r"line 3: column 'wavelength \(nm\)' \(column 1\): no value \(''\); every row needs its wavelength"),
    ("wavelength (nm),angle,psi,delta\n400,70,10,100\n410,NaN,11,101\n",
     r"line 3: column 'angle' \(column 2\): no value \('NaN'\); every row needs its angle"),
    ("wavelength (nm),angle,psi,delta\n400,70,10,100\n410,70,1l,101\n",
     r"line 3: column 'psi': '1l' is not a number \(column 3\)"),
    ("wavelength (nm),angle,psi,delta\n400,70,10.25,100.25\n410,70,10.50,101.25\n420,70,10.75,1",
     r"line 4: column 4 \('delta'\): the file ends inside a number: '1' has 0 decimals where every earlier row "
     r"has 2 \(truncated file\?"),
])
def test_measurement_csv_errors_name_line_and_column(tmp_path, text, match):
    p = _write(tmp_path, "bad.csv", text)
    with pytest.raises(LayerstackError, match=match) as info:
        read_measurement(p)
    assert str(info.value).startswith(str(p))


# ------------------------------------------------------------------------------------------
# spectra CSV (read_spectra_csv: wavelength_nm, then one column per spectrum)
# ------------------------------------------------------------------------------------------
def test_spectra_csv_nan_empty_and_na_are_nan_points(tmp_path):
    p = _write(tmp_path, "s.csv", "wavelength_nm,a,b\n400,0.1,0.2\n410,nan,0.21\n420,,0.22\n430,0.13,NA\n")
    wl, cols = read_spectra_csv(p)
    np.testing.assert_array_equal(wl, [400, 410, 420, 430])
    np.testing.assert_array_equal(np.isnan(cols["a"]), [False, True, True, False])
    np.testing.assert_array_equal(np.isnan(cols["b"]), [False, False, False, True])
    np.testing.assert_array_equal(cols["a"][[0, 3]], [0.1, 0.13])


def test_spectra_csv_descending_semicolon_decimal_comma(tmp_path):
    p = _write(tmp_path, "s.csv", "wavelength_nm;a;b\n430;0,13;0,23\n420;0,12;\n410,5;0,11;0,21\n")
    wl, cols = read_spectra_csv(p)
    np.testing.assert_array_equal(wl, [410.5, 420.0, 430.0])
    np.testing.assert_array_equal(cols["a"], [0.11, 0.12, 0.13])
    np.testing.assert_array_equal(np.isnan(cols["b"]), [False, True, False])


@pytest.mark.parametrize("text, match", [
    ("wavelength_nm,a\n400,0.1\n420,0.11\n410,0.1\n",
     r"line 4: column 'wavelength_nm': 410 comes after 420: wavelengths must increase \(or decrease\) strictly"),
    ("wavelength_nm,a\n400,0.1\n400,0.11\n", r"line 3: column 'wavelength_nm': 400 repeats the wavelength before it"),
    ("wavelength_nm,a\n400,0.1\n,0.11\n", r"line 3: column 'wavelength_nm' \(column 1\): no value \(''\)"),
    ("wavelength_nm,a\n400,0.1\n410,inf\n", r"line 3: column 'a' \(column 2\): NaN or infinite value 'inf'"),
    ("wavelength_nm,a\n400,0.1\n410,0.1x\n", r"line 3: column 'a' \(column 2\): '0.1x' is not a number"),
    ("wavelength_nm,a\n400,0,10\n410,0,11\n", r"line 2: 3 fields for 2 columns \(wavelength_nm, a\) \(decimal commas\?"),
    ("wavelength_nm,a\n400,0.1000\n410,0.1100\n420,0.1",
     r"line 4: column 2 \('a'\): the file ends inside a number: '0.1' has 1 decimals where every earlier row has "
     r"4 \(truncated file\?"),
    ("wavelength_nm,a,b\n400,0.1,0.2\n410,0.1", r"line 3: 2 fields for 3 columns \(wavelength_nm, a, b\) \(truncated file\?\)"),
])
def test_spectra_csv_errors_name_line_and_column(tmp_path, text, match):
    p = _write(tmp_path, "bad.csv", text)
    with pytest.raises(LayerstackError, match=match) as info:
        read_spectra_csv(p)
    assert str(info.value).startswith(str(p))


def test_spectra_csv_complete_last_row_without_line_end_is_read(tmp_path):
    """A last row written as precisely as the others is whole, line end or not; so is one of a
    file typed by hand (the earlier rows written with varying precision)."""
    wl, cols = read_spectra_csv(_write(tmp_path, "s.csv", "wavelength_nm,a\n400,0.1000\n410,0.1100\n420,0.1200"))
    np.testing.assert_array_equal(cols["a"], [0.1, 0.11, 0.12])
    wl, cols = read_spectra_csv(_write(tmp_path, "t.csv", "wavelength_nm,a\n400,0.12\n410,0.125\n420,0.5"))
    np.testing.assert_array_equal(cols["a"], [0.12, 0.125, 0.5])


# ------------------------------------------------------------------------------------------
# instrument files cut while they were written
# ------------------------------------------------------------------------------------------
def _cut(src: Path, dst: Path, keep: int) -> Path:
    dst.write_bytes(src.read_bytes()[:keep])
    return dst


def test_woollam_cut_inside_the_last_number_is_refused(tmp_path):
    """WVASE glass export cut inside σΔ of a row in the middle: the row keeps its 6 fields,
    its last number loses digits."""
    raw = WVASE_GLASS.read_bytes()
    start = raw.index(b"\n", len(raw) // 2) + 1           # a whole row starts here
    row = raw[start:raw.index(b"\n", start)].decode()
    fields = row.split("\t")
    assert len(fields) == 6 and len(fields[-1].split(".")[1]) >= 4
    keep = start + len(row) - 3                          # three digits of the last number cut off
    p = _cut(WVASE_GLASS, tmp_path / "cut.dat", keep)
    line = raw[:start].count(b"\n") + 1
    shown = fields[-1][:-3]
    with pytest.raises(LayerstackError, match=rf"cut.dat, line {line}: column 6: the file ends inside a number: "
                                              rf"'{re.escape(shown)}' has \d+ decimals"):
        read_measurement(p)


def test_completeease_cut_inside_the_last_angle_is_refused(tmp_path):
    """The CompleteEASE file cut after its 70° row at 386 nm: 70° would cover 193–386 nm only."""
    lines = CEASE.read_text().splitlines(keepends=True)
    e_rows = [(k, ln.split("\t")) for k, ln in enumerate(lines) if ln.startswith("E\t")]
    at70 = [(k, f) for k, f in e_rows if float(f[2]) == 70.0]
    at50 = [float(f[1]) / 10 for k, f in e_rows if float(f[2]) == 50.0]  # Å -> nm
    last = next(i for i, (k, f) in enumerate(at70) if float(f[1]) >= 3860.0)
    k_cut = at70[last][0]
    p = tmp_path / "cut.dat"
    p.write_text("".join(lines[: k_cut + 1]))
    n, wl_last = last + 1, float(at70[last][1][1]) / 10
    with pytest.raises(LayerstackError, match=(
            rf"cut.dat, line {k_cut + 1}: the file ends inside the block of angle 70 deg: {n} rows \(wavelength "
            rf"{at50[0]:g}–{wl_last:g} nm\) where every other angle has {len(at50)} \(wavelength {at50[0]:g}–"
            rf"{max(at50):g} nm\): truncated file\?")):
        read_measurement(p)
    assert wl_last < 390.0


def test_accurion_cut_at_a_row_end_inside_an_angle_is_refused(tmp_path):
    raw = ACCURION.read_bytes()
    text = raw.decode("latin-1").splitlines()
    column = [h.strip().lower() for h in text[0].lstrip("#").split("\t")].index("aoi")
    rows = [ln for ln in text if ln and not ln.startswith("#")]
    aoi = [float(r.split("\t")[column]) for r in rows]
    assert sorted(set(aoi)) == [40.0, 50.0]
    first50 = aoi.index(50.0)
    ends = [m.end() for m in re.finditer(rb"\n", raw)]
    data_ends = ends[-len(rows):]
    keep = data_ends[first50 + 5]                          # six rows of the 50° block
    p = _cut(ACCURION, tmp_path / "cut.ds.dat", keep)
    with pytest.raises(LayerstackError, match=r"cut.ds.dat, line \d+: the file ends inside the block of angle 50 deg: "
                                              r"6 rows .* where every other angle has \d+ .*truncated file\?"):
        read_measurement(p)


def test_sentech_cut_inside_the_last_number_is_refused(tmp_path):
    raw = SENTECH_PD.read_bytes()
    start = raw.index(b"\n", len(raw) // 2) + 1
    row = raw[start:raw.index(b"\n", start)].decode().rstrip()
    keep = start + len(row) - 2
    p = _cut(SENTECH_PD, tmp_path / "cut.txt", keep)
    assert sniff_format(p) == "sentech"
    line = raw[:start].count(b"\n") + 1
    with pytest.raises(LayerstackError, match=rf"cut.txt, line {line}: column 7: the file ends inside a number"):
        read_measurement(p)


def test_every_real_file_still_reads():
    """The real files end complete: none is refused by the truncation checks."""
    for path in sorted(DATA.iterdir()):
        if path.suffix in (".dat", ".txt"):
            assert read_measurement(path).valid().any(), path.name
