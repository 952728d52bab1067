"""`layerstack fit` on files as they come (issue 27): missing points masked, descending
wavelengths, semicolons with decimal commas, malformed files refused with the reader's own
reason (file, line, column), Mueller-matrix files, and ``--range``.

References: spectra made by the public forward model with known thicknesses (the command line
must give them back); for the measured Sentech Mueller matrix, a numpy closed form (Airy
summation of one film on a substrate, Fresnel coefficients written out here) fitted with scipy.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_cli import main

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "examples" / "data"
WL = np.arange(400.0, 701.0, 10.0)

STACK = """
[[layers]]
name = "slab"
n = 1.5
thickness_nm = { value = 8000, free = true, min = 0, max = 1e5 }
coherent = false
alpha_per_nm = 2e-5

[substrate]
n = 1.5
"""


def _truth(h):
    st = ls.Stack(1.0, [ls.Layer(1.5, h, coherent=False, alpha=2e-5, name="slab")], ls.Substrate(1.5))
    return np.asarray(ls.reflectance(st, WL, ls.Specular(0.0, "T")))


def _stack(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(STACK)
    return p


def test_fit_masks_missing_points_reads_descending_semicolon_decimal_comma(tmp_path, capsys):
    """An Excel export in a decimal-comma locale, red to blue, with an empty cell, a NaN and an
    NA in different places of the two spectra: each spectrum fitted on its own points."""
    a, b = _truth(10_000.0), _truth(12_500.0)
    cells = {"a": [f"{v:.15g}".replace(".", ",") for v in a], "b": [f"{v:.15g}".replace(".", ",") for v in b]}
    cells["a"][3], cells["a"][17] = "", "NaN"
    cells["b"][20] = "NA"
    rows = [f"{w:g};{cells['a'][k]};{cells['b'][k]}" for k, w in enumerate(WL)][::-1]
    data = tmp_path / "excel.csv"
    data.write_text("wavelength_nm;a;b\n" + "\n".join(rows) + "\n")
    out = tmp_path / "r.json"
    code = main(["fit", str(_stack(tmp_path)), str(data), "-g", "specular:0:T", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    fits = {f["spectrum"]: f for f in json.loads(out.read_text())["fits"]}
    assert fits["a"]["parameters"]["thickness_nm[slab]"]["value"] == pytest.approx(10_000.0, rel=1e-6)
    assert fits["b"]["parameters"]["thickness_nm[slab]"]["value"] == pytest.approx(12_500.0, rel=1e-6)
    assert fits["a"]["n_points"] == WL.size - 2 and fits["b"]["n_points"] == WL.size - 1


def test_fit_joint_masks_missing_points(tmp_path, capsys):
    a, b = _truth(10_000.0), _truth(12_500.0)
    rows = [f"{w:g},{'' if k == 5 else repr(float(a[k]))},{repr(float(b[k]))}" for k, w in enumerate(WL)]
    data = tmp_path / "d.csv"
    data.write_text("wavelength_nm,a,b\n" + "\n".join(rows) + "\n")
    stack = tmp_path / "j.toml"
    stack.write_text(STACK.replace("max = 1e5 }", "max = 1e5, per_sample = true }"))
    out = tmp_path / "r.json"
    assert main(["fit", str(stack), str(data), "-g", "specular:0:T", "--joint", "-o", str(out)]) == 0, capsys.readouterr()
    fit = json.loads(out.read_text())["fits"][0]
    np.testing.assert_allclose(fit["parameters"]["thickness_nm[slab]"]["value"], [10_000.0, 12_500.0], rtol=1e-6)
    assert fit["n_points"] == 2 * WL.size - 1


def _cut_woollam(tmp_path):
    raw = (DATA / "woollam_wvase_glass.dat").read_bytes()
    start = raw.index(b"\n", len(raw) // 2) + 1
    end = raw.index(b"\n", start)
    p = tmp_path / "cut.dat"
    p.write_bytes(raw[: end - 3])
    return p, raw[:start].count(b"\n") + 1


@pytest.mark.parametrize("case", ["cut spectra", "decimal commas between commas", "unsorted", "no wavelength",
                                  "cut instrument file", "not a number in a measurement csv"])
def test_fit_refuses_malformed_files_with_the_readers_reason(tmp_path, capsys, case):
    text, line, column = {
        "cut spectra": ("wavelength_nm,a\n400,0.1000\n410,0.1100\n420,0.1", 4, "column 2 ('a'): the file ends inside a number"),
        "decimal commas between commas": ("wavelength_nm,a\n400,0,10\n410,0,11\n", 2, "(decimal commas? they need ';'"),
        "unsorted": ("wavelength_nm,a\n400,0.1\n420,0.11\n410,0.1\n", 4, "column 'wavelength_nm': 410 comes after 420"),
        "no wavelength": ("wavelength_nm,a\n400,0.1\n,0.11\n", 3, "column 'wavelength_nm' (column 1): no value"),
        "cut instrument file": (None, None, "column 6: the file ends inside a number"),
        "not a number in a measurement csv": ("wavelength (nm),angle,psi,delta\n400,70,10,100\n410,70,1l,101\n", 3,
                                              "column 'psi': '1l' is not a number (column 3)"),
    }[case]
    if text is None:
        data, line = _cut_woollam(tmp_path)
        model = ROOT / "examples" / "glass_plate_backside.toml"
    else:
        data = tmp_path / "bad.csv"
        data.write_text(text)
        model = _stack(tmp_path)
    args = ["fit", str(model), str(data), "-o", str(tmp_path / "r.json")]
    if case.endswith("spectra") or case in ("decimal commas between commas", "unsorted", "no wavelength"):
        args += ["-g", "specular:0:T"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"{data}" in err and f"line {line}" in err and column in err, err
    assert "no measured columns" not in err


def _airy_ncs(d_nm, wl_nm, n_film, n_sub, angle_deg):
    """N, C, S of one film on a substrate in air: Fresnel coefficients (tmm's sign convention,
    r_p = -r_s at normal incidence), Airy summation, exp(-i omega t) with n + ik; rho = r_p/r_s =
    tan psi e^{-i Delta}, so 2 r_p conj(r_s)/(|r_s|^2 + |r_p|^2) = sin 2psi e^{-i Delta}."""
    th = np.deg2rad(angle_deg)
    s0 = np.sin(th)
    c0, c1, c2 = np.cos(th), np.sqrt(1 - (s0 / n_film) ** 2 + 0j), np.sqrt(1 - (s0 / n_sub) ** 2 + 0j)

    def rs(na, ca, nb, cb):
        return (na * ca - nb * cb) / (na * ca + nb * cb)

    def rp(na, ca, nb, cb):
        return (nb * ca - na * cb) / (nb * ca + na * cb)

    phase = np.exp(2j * (2 * np.pi * d_nm * n_film * c1 / wl_nm))
    r = {}
    for name, f in (("s", rs), ("p", rp)):
        r01, r12 = f(1.0, c0, n_film, c1), f(n_film, c1, n_sub, c2)
        r[name] = (r01 + r12 * phase) / (1 + r01 * r12 * phase)
    total = abs(r["s"]) ** 2 + abs(r["p"]) ** 2
    x = 2 * r["p"] * np.conj(r["s"]) / total
    return (abs(r["s"]) ** 2 - abs(r["p"]) ** 2) / total, x.real, -x.imag


def test_fit_mueller_file_matches_a_numpy_airy_fit(tmp_path, capsys):
    """The measured Sentech Mueller matrix of SiO2 on Si at 70.2° (examples/data), 400–800 nm by
    --range: the command line fits the six elements an isotropic sample sets (−M12, −M21 = N;
    M33, M44 = C; M34, −M43 = S) on the file's own wavelengths; scipy, minimising the same sum of
    squares of the closed form above, finds the same thickness."""
    from scipy.optimize import minimize_scalar

    path = DATA / "sentech_SiO2_on_Si_mueller_70deg.txt"
    raw = np.loadtxt(path, comments=";")
    raw = raw[(raw[:, 0] >= 400.0) & (raw[:, 0] <= 800.0)]
    wl, M = raw[:, 0], raw[:, 1:17].reshape(-1, 4, 4)
    measured = np.stack([-M[:, 0, 1], -M[:, 1, 0], M[:, 2, 2], M[:, 3, 3], M[:, 2, 3], -M[:, 3, 2]])
    n_film = 1.452 + 0.0036 / (wl / 1000) ** 2
    n_si = np.asarray(ls.material("Si", "Aspnes")(wl))  # tabulated data, the same for both fits

    def sse(d):
        N, C, S = _airy_ncs(d, wl, n_film, n_si, 70.2)
        return float(np.sum((np.stack([N, N, C, C, S, S]) - measured) ** 2))

    ref = minimize_scalar(sse, bounds=(90.0, 120.0), method="bounded", options={"xatol": 1e-6})
    assert np.sqrt(ref.fun / measured.size) < 0.02  # the closed form describes the data (right signs)

    model = tmp_path / "sio2.toml"
    model.write_text('[[layers]]\nname = "SiO2"\nn = { cauchy = [1.452, 0.0036] }\n'
                     'thickness_nm = { value = 110, free = true, min = 50, max = 200 }\ncoherent = true\n\n'
                     '[substrate]\nn = { material = "Si", source = "Aspnes" }\n')
    out = tmp_path / "r.json"
    code = main(["fit", str(model), str(path), "--range", "400:800", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "geometry: ellipsometry:70.2:N,C,S (from the file's Mueller matrix" in text
    fit = json.loads(out.read_text())["fits"][0]
    assert fit["parameters"]["thickness_nm[SiO2]"]["value"] == pytest.approx(ref.x, abs=1e-4)
    np.testing.assert_array_equal(fit["wavelength_nm"], wl)  # the file's own points, not resampled
    assert fit["n_points"] == measured.size


def test_range_restricts_the_files_wavelengths_without_resampling(tmp_path, capsys):
    """Spectra spoiled above 650 nm (a detector change, say): --range 400:650 fits the rest."""
    y = _truth(10_000.0).copy()
    y[WL > 650] *= 1.2
    data = tmp_path / "d.csv"
    data.write_text("wavelength_nm,a\n" + "\n".join(f"{w:g},{float(v)!r}" for w, v in zip(WL, y)) + "\n")
    out = tmp_path / "r.json"
    stack = _stack(tmp_path)
    assert main(["fit", str(stack), str(data), "-g", "specular:0:T", "--range", "400:650", "-o", str(out)]) == 0
    fit = json.loads(out.read_text())["fits"][0]
    assert fit["parameters"]["thickness_nm[slab]"]["value"] == pytest.approx(10_000.0, rel=1e-8)
    np.testing.assert_array_equal(fit["wavelength_nm"], WL[WL <= 650])
    capsys.readouterr()
    assert main(["fit", str(stack), str(data), "-g", "specular:0:T", "--range", "800:900", "-o", str(out)]) == 2
    assert "--range 800:900: no wavelength of the file in [800, 900] nm (it spans 400-700 nm)" in capsys.readouterr().err
    assert main(["fit", str(stack), str(data), "-g", "specular:0:T", "--range", "650:400", "-o", str(out)]) == 2
    assert "--range '650:400': give START:STOP in nm" in capsys.readouterr().err


def test_fit_mueller_csv_not_normalised_is_divided_by_m11(tmp_path, capsys):
    """The same Sentech matrix written as a measurement CSV scaled by an M11 of 0.3 (as a
    non-normalising instrument reports it): the same thickness as the normalised file."""
    from layerstack_jax import Measurement
    from layerstack_jax.io import read_measurement, write_measurement_csv

    m = read_measurement(DATA / "sentech_SiO2_on_Si_mueller_70deg.txt").between(400.0, 800.0)
    scaled = Measurement(quantity="mueller", angles_deg=m.angles_deg, wavelength_nm=m.wavelength_nm,
                         values=0.3 * np.asarray(m.values), mueller_normalized=False, file_format="csv")
    data = write_measurement_csv(tmp_path / "mm.csv", scaled)
    model = tmp_path / "sio2.toml"
    model.write_text('[[layers]]\nname = "SiO2"\nn = { cauchy = [1.452, 0.0036] }\n'
                     'thickness_nm = { value = 110, free = true, min = 50, max = 200 }\ncoherent = true\n\n'
                     '[substrate]\nn = { material = "Si", source = "Aspnes" }\n')
    d = {}
    for name, path in (("normalised", DATA / "sentech_SiO2_on_Si_mueller_70deg.txt"), ("scaled", data)):
        out = tmp_path / f"{name}.json"
        assert main(["fit", str(model), str(path), "--range", "400:800", "-o", str(out)]) == 0, capsys.readouterr()
        d[name] = json.loads(out.read_text())["fits"][0]["parameters"]["thickness_nm[SiO2]"]["value"]
    assert d["scaled"] == pytest.approx(d["normalised"], abs=1e-6)


def test_fit_psi_delta_csv_with_an_angle_column_and_missing_points(tmp_path, capsys):
    """A CSV 'wavelength_nm, angle, psi, delta' is a measurement (points at an angle), not three
    spectra, even though it starts with wavelength_nm; its missing points are masked. Data: the
    public forward model at 2.5 nm of SiO2 on Si, red to blue, a NaN ψ and an empty Δ."""
    from layerstack_jax.io import load_stack

    model = ROOT / "examples" / "sio2_on_si_fit.toml"
    stack = load_stack(model)
    stack = ls.Stack(stack.ambient, [ls.Layer(stack.layers[0].index, 2.5, name="SiO2")], stack.exit)
    wl = np.arange(400.0, 801.0, 20.0)
    e = ls.ellipsometry(stack, wl, 70.0)
    psi, delta = np.asarray(e.psi_deg).ravel(), np.asarray(e.delta_deg).ravel()
    cells = [[f"{w:g}", "70", repr(float(p)), repr(float(d))] for w, p, d in zip(wl, psi, delta)]
    cells[4][2], cells[9][3] = "nan", ""
    data = tmp_path / "pd.csv"
    data.write_text("wavelength_nm,angle,psi,delta\n" + "\n".join(",".join(c) for c in cells[::-1]) + "\n")
    out = tmp_path / "r.json"
    code = main(["fit", str(model), str(data), "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "geometry: ellipsometry:70:N,C,S" in text
    fit = json.loads(out.read_text())["fits"][0]
    assert fit["parameters"]["thickness_nm[SiO2]"]["value"] == pytest.approx(2.5, rel=1e-6)
    assert fit["n_points"] == 3 * (wl.size - 2)
