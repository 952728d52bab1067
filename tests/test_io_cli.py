"""Stack files (layerstack_jax.io) and the command line (layerstack_jax.cli)."""

from __future__ import annotations

import csv
import math
import tomllib
from pathlib import Path

import jax
import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_cli import main
from layerstack_jax.io import (
    load_stack,
    parse_wavelengths,
    read_csv_columns,
    save_spectra_csv,
    stack_from_dict,
    stack_to_dict,
)

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
PAINTING = EXAMPLES / "varnished_painting.toml"
FILM = EXAMPLES / "thin_film_on_metal.toml"
WL = np.arange(380.0, 781.0, 20.0)


def _read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    data = np.asarray(rows[1:], dtype=float)
    return header, data


# ------------------------------------------------------------------------ examples
def test_load_varnished_painting():
    stack = load_stack(PAINTING)
    assert isinstance(stack, ls.Stack)
    assert isinstance(stack.exit, ls.LambertianBackground)
    assert len(stack.layers) == 1
    varnish = stack.layers[0]
    assert varnish.name == "varnish" and not varnish.coherent
    assert float(varnish.thickness) == 30000.0
    assert isinstance(varnish.index, ls.Cauchy)
    n550 = complex(np.asarray(varnish.index(np.array([550.0])))[0])
    assert n550.real == pytest.approx(1.54, abs=0.005) and n550.imag == 0.0
    assert isinstance(varnish.alpha, ls.TabulatedSpectrum)
    alpha = np.asarray(varnish.alpha(WL))
    assert np.all(alpha >= 0) and alpha[0] > 10 * alpha[-1]  # absorbs in the blue
    rho = np.asarray(stack.exit.reflectance(WL))
    assert rho[WL == 500.0][0] == pytest.approx(0.05, abs=0.01)
    assert rho[WL == 700.0][0] == pytest.approx(0.6, abs=0.01)


def test_load_thin_film_on_metal():
    stack = load_stack(FILM)
    assert isinstance(stack.exit, ls.Substrate)
    (film,) = stack.layers
    assert film.coherent and float(film.thickness) == 120.0 and film.name == "SiO2"
    al = stack.exit.index
    assert isinstance(al, ls.Tabulated)
    n = np.asarray(al(np.array([400.0, 550.0, 700.0])))
    np.testing.assert_allclose(n.real, [0.49, 0.96, 1.83], atol=0.02)
    np.testing.assert_allclose(n.imag, [4.86, 6.69, 8.31], atol=0.05)


def _spectra(stack):
    return [np.asarray(ls.reflectance(stack, WL, g)) for g in (ls.Sphere(8.0), ls.Specular(30.0, "R"), ls.Specular(30.0, "T"))]


@pytest.mark.parametrize("path", [PAINTING, FILM], ids=["painting", "film"])
def test_stack_from_dict_round_trip(path):
    stack = load_stack(path)
    with open(path, "rb") as f:
        again = stack_from_dict(tomllib.load(f), path.parent)
    d = stack_to_dict(stack)
    inline = stack_from_dict(d)  # tables inline: no base_dir needed
    assert stack_to_dict(inline) == d
    for a, b, c in zip(_spectra(stack), _spectra(again), _spectra(inline)):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)


def test_stack_from_dict_matches_python_stack():
    d = {
        "ambient": {"n": 1.0},
        "layers": [
            {"name": "film", "n": 2.0, "k": 0.01, "thickness_nm": 80, "coherent": True},
            {"name": "glass", "n": {"sellmeier": {"B": [1.03961212, 0.231792344], "C": [0.00600069867, 0.0200179144]}},
             "thickness_nm": 1e6, "coherent": False, "alpha_per_nm": 1e-7},
        ],
        "background": {"n": 1.5, "rho_g": {"wavelength_nm": [300, 800], "values": [0.2, 0.7]}},
    }
    built = ls.Stack(
        ambient=1.0,
        layers=[
            ls.Layer(ls.Index(2.0, 0.01), 80.0, coherent=True, name="film"),
            ls.Layer(ls.Sellmeier(np.array([1.03961212, 0.231792344]), np.array([0.00600069867, 0.0200179144])),
                     1e6, coherent=False, alpha=1e-7, name="glass"),
        ],
        exit=ls.LambertianBackground(1.5, np.interp(WL, [300, 800], [0.2, 0.7])),
    )
    got = ls.reflectance(stack_from_dict(d), WL, ls.Directional(45.0, 0.0))
    want = ls.reflectance(built, WL, ls.Directional(45.0, 0.0))
    np.testing.assert_allclose(got, want, rtol=1e-5)


# ---------------------------------------------------------------- malformed files
GOOD_LAYER = 'name = "v"\nn = 1.5\nthickness_nm = 100\ncoherent = true\n'

MALFORMED = {
    "missing thickness": ('[[layers]]\nname = "v"\nn = 1.5\ncoherent = true\n[substrate]\nn = 1.5\n',
                          ["'thickness_nm'", "missing", "'v'"]),
    "unknown layer key": ('[[layers]]\n' + GOOD_LAYER + 'thicknes = 3\n[substrate]\nn = 1.5\n',
                          ["unknown key 'thicknes'", "did you mean 'thickness_nm'"]),
    "unknown top key": ('[substrat]\nn = 1.5\n', ["unknown key 'substrat'", "did you mean 'substrate'"]),
    "unknown substrate key": ('[substrate]\nn = 1.5\nrho_g = 0.5\n', ["[substrate]", "unknown key 'rho_g'"]),
    "both exits": ('[substrate]\nn = 1.5\n[background]\nn = 1.5\nrho_g = 0.5\n', ["not both", "[substrate]", "[background]"]),
    "no exit": ('[[layers]]\n' + GOOD_LAYER, ["missing the exit medium", "[substrate]", "[background]"]),
    "negative thickness": ('[[layers]]\nn = 1.5\nthickness_nm = -5\ncoherent = true\n[substrate]\nn = 1.5\n',
                           ["'thickness_nm'", ">= 0", "-5"]),
    "negative k": ('[substrate]\nn = 1.5\nk = -0.1\n', ["[substrate]", "'k'", ">= 0"]),
    "negative n": ('[substrate]\nn = -1.5\n', ["[substrate]", "'n'", "> 0"]),
    "n not a number": ('[substrate]\nn = "glass"\n', ["[substrate]", "'n'", "'glass'"]),
    "missing n": ('[[layers]]\nthickness_nm = 5\ncoherent = true\n[substrate]\nn = 1.5\n', ["'n'", "missing"]),
    "negative alpha": ('[[layers]]\nn = 1.5\nthickness_nm = 5\ncoherent = false\nalpha_per_nm = -1e-5\n[substrate]\nn = 1.5\n',
                       ["'alpha_per_nm'", ">= 0"]),
    "alpha on coherent": ('[[layers]]\n' + GOOD_LAYER + 'alpha_per_nm = 1e-5\n[substrate]\nn = 1.5\n',
                          ["'alpha_per_nm'", "incoherent"]),
    "coherent missing": ('[[layers]]\nn = 1.5\nthickness_nm = 5\n[substrate]\nn = 1.5\n', ["'coherent'", "missing"]),
    "coherent not bool": ('[[layers]]\nn = 1.5\nthickness_nm = 5\ncoherent = "yes"\n[substrate]\nn = 1.5\n',
                          ["'coherent'", "true or false"]),
    "rho_g above 1": ('[background]\nn = 1.5\nrho_g = 1.2\n', ["[background]", "'rho_g'", "<= 1"]),
    "rho_g missing": ('[background]\nn = 1.5\n', ["[background]", "'rho_g'", "missing"]),
    "rho_g inline lengths": ('[background]\nn = 1.5\nrho_g = { wavelength_nm = [400, 500], values = [0.1] }\n',
                             ["'rho_g'", "1 values for 2 wavelengths"]),
    "background k": ('[background]\nn = 1.5\nk = 0.1\nrho_g = 0.5\n', ["[background]", "'k'", "transparent"]),
    "ambient k": ('[ambient]\nn = 1.0\nk = 0.1\n[substrate]\nn = 1.5\n', ["[ambient]", "'k'", "transparent"]),
    "material": ('[substrate]\nn = { material = "Auu" }\n', ["[substrate]", "'n'", "unknown material 'Auu'", "Au"]),
    "material without source": ('[substrate]\nn = { material = "Au" }\n', ["[substrate]", "'n'", "source", "'Johnson'"]),
    "material with k": ('[substrate]\nn = { material = "Au", source = "Johnson" }\nk = 1.0\n', ["'k'", "database"]),
    "source without material": ('[substrate]\nn = { cauchy = [1.5], source = "x" }\n', ["unknown key 'source'"]),
    "absorbing ambient": ('[ambient]\nn = { material = "Au", source = "Johnson" }\n[substrate]\nn = 1.5\n',
                          ["[ambient]", "transparent"]),
    "two dispersions": ('[substrate]\nn = { cauchy = [1.5], table = "x.csv" }\n', ["'n'", "exactly one"]),
    "unknown dispersion": ('[substrate]\nn = { cauchi = [1.5] }\n', ["unknown key 'cauchi'", "did you mean 'cauchy'"]),
    "cauchy too long": ('[substrate]\nn = { cauchy = [1.5, 0.1, 0.1, 0.1] }\n', ["'n'", "1 to 3 coefficients"]),
    "sellmeier lengths": ('[substrate]\nn = { sellmeier = { B = [1.0, 0.2], C = [0.01] } }\n', ["'n'", "same length"]),
    "layers not array": ('[layers]\nn = 1.5\n[substrate]\nn = 1.5\n', ["'layers'", "[[layers]]"]),
    "description not str": ('description = 3\n[substrate]\nn = 1.5\n', ["'description'", "string"]),
    "invalid toml": ('[substrate\nn = 1.5\n', ["invalid TOML"]),
}


@pytest.mark.parametrize("name", list(MALFORMED))
def test_malformed_stack_files(tmp_path, name):
    text, needles = MALFORMED[name]
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ls.LayerstackError) as info:
        load_stack(path)
    msg = str(info.value)
    assert str(path) in msg
    for needle in needles:
        assert needle in msg, (needle, msg)


TABLE_STACK = '[[layers]]\nname = "v"\nn = 1.5\nthickness_nm = 1000\ncoherent = false\nalpha_per_nm = {{ table = "a.csv" }}\n' \
    '[background]\nn = {{ table = "n.csv" }}\nrho_g = {{ table = "rho.csv" }}\n'
GOOD_TABLES = {
    "a.csv": "wavelength_nm,alpha_per_nm\n380,1e-5\n780,1e-6\n",
    "n.csv": "# binder\nwavelength_nm,n\n380,1.52\n780,1.50\n",
    "rho.csv": "wavelength_nm,rho_g\n380,0.1\n780,0.6\n",
}
BAD_TABLES = {
    "no header": ("rho.csv", "380,0.1\n780,0.6\n", ["'rho_g'", "rho.csv", "header row required"]),
    "missing column": ("rho.csv", "wavelength_nm\n380\n780\n", ["'rho_g'", "missing column 'rho_g'"]),
    "unknown column": ("a.csv", "wavelength_nm,alpha\n380,1e-5\n780,1e-6\n", ["'alpha_per_nm'", "unknown column 'alpha'"]),
    "not a number": ("rho.csv", "wavelength_nm,rho_g\n380,0.1\n780,abc\n", ["'rho_g'", "line 3", "not a number"]),
    "short row": ("rho.csv", "wavelength_nm,rho_g\n380,0.1\n780\n", ["'rho_g'", "line 3", "1 fields for 2 columns"]),
    "decreasing": ("rho.csv", "wavelength_nm,rho_g\n780,0.1\n380,0.6\n", ["'rho_g'", "increase strictly"]),
    "one row": ("rho.csv", "wavelength_nm,rho_g\n380,0.1\n", ["'rho_g'", "at least 2"]),
    "empty": ("rho.csv", "", ["'rho_g'", "empty file"]),
    "rho above 1": ("rho.csv", "wavelength_nm,rho_g\n380,0.1\n780,1.6\n", ["'rho_g'", "<= 1"]),
    "negative alpha": ("a.csv", "wavelength_nm,alpha_per_nm\n380,-1e-5\n780,1e-6\n", ["'alpha_per_nm'", ">= 0"]),
    "nan": ("n.csv", "wavelength_nm,n\n380,nan\n780,1.5\n", ["'n'", "NaN"]),
    "background k column": ("n.csv", "wavelength_nm,n,k\n380,1.5,0.1\n780,1.5,0.1\n", ["'n'", "transparent"]),
    "missing file": ("n.csv", None, ["'n'", "'n.csv' not found"]),
}


def _write_tables(tmp_path, override=None):
    tables = dict(GOOD_TABLES)
    if override:
        tables[override[0]] = override[1]
    for name, text in tables.items():
        if text is not None:
            (tmp_path / name).write_text(text)
    path = tmp_path / "tables.toml"
    path.write_text(TABLE_STACK.format())
    return path


def test_tables_load(tmp_path):
    stack = load_stack(_write_tables(tmp_path))
    r = np.asarray(ls.reflectance(stack, WL, ls.Sphere(8.0)))
    assert np.all(np.isfinite(r)) and np.all((r > 0) & (r < 1))


@pytest.mark.parametrize("name", list(BAD_TABLES))
def test_malformed_tables(tmp_path, name):
    file, text, needles = BAD_TABLES[name]
    path = _write_tables(tmp_path, (file, text))
    with pytest.raises(ls.LayerstackError) as info:
        load_stack(path)
    msg = str(info.value)
    assert str(path) in msg
    for needle in needles:
        assert needle in msg, (needle, msg)


def test_k_both_in_key_and_table(tmp_path):
    (tmp_path / "m.csv").write_text("wavelength_nm,n,k\n380,1.0,5\n780,2.0,8\n")
    path = tmp_path / "s.toml"
    path.write_text('[substrate]\nn = { table = "m.csv" }\nk = 1.0\n')
    with pytest.raises(ls.LayerstackError, match="k is given both"):
        load_stack(path)
    path.write_text('[substrate]\nn = { table = "m.csv" }\n')
    n = np.asarray(load_stack(path).exit.index(np.array([580.0])))
    assert complex(n[0]) == pytest.approx(1.5 + 6.5j)


def test_missing_stack_file(tmp_path):
    with pytest.raises(ls.LayerstackError, match="stack file not found"):
        load_stack(tmp_path / "nope.toml")


# ---------------------------------------------------------------------- wavelengths
def test_parse_wavelengths():
    wl = parse_wavelengths("380:780:5")
    assert wl.size == 81 and wl[0] == 380.0 and wl[-1] == 780.0
    np.testing.assert_array_equal(parse_wavelengths("400:700:100"), [400, 500, 600, 700])
    np.testing.assert_array_equal(parse_wavelengths("400:750:100"), [400, 500, 600, 700])  # stop off the grid
    np.testing.assert_allclose(parse_wavelengths("400:401:0.1"), np.linspace(400, 401, 11))
    np.testing.assert_array_equal(parse_wavelengths("550"), [550.0])
    np.testing.assert_array_equal(parse_wavelengths(" 450, 550,650 "), [450.0, 550.0, 650.0])
    np.testing.assert_array_equal(parse_wavelengths("500:500:5"), [500.0])
    for bad in ["", "abc", "380:780", "380:780:0", "380:780:-5", "780:380:5", "0:10:5", "-5", "550,450", "nan"]:
        with pytest.raises(ls.LayerstackError, match="bad wavelengths"):
            parse_wavelengths(bad)


def test_save_spectra_csv(tmp_path):
    wl = np.array([400.0, 500.0, 600.0])
    path = save_spectra_csv(tmp_path / "sub" / "s.csv", wl, {"45/0": [0.1, 0.2, 0.3], "R_8": np.array([1e-3, 2e-3, 1 / 3])})
    header, data = _read_csv(path)
    assert header == ["wavelength_nm", "45/0", "R_8"]
    np.testing.assert_allclose(data[:, 2], [1e-3, 2e-3, 1 / 3], rtol=1e-9)
    cols = read_csv_columns(path, ["wavelength_nm", "45/0", "r_8"])
    np.testing.assert_array_equal(cols["wavelength_nm"], wl)
    with pytest.raises(ls.LayerstackError, match="shape"):
        save_spectra_csv(tmp_path / "x.csv", wl, {"a": [1.0, 2.0]})


# ------------------------------------------------------------------------------ CLI
def _check_output(path, columns, rows=81):
    header, data = _read_csv(path)
    assert header == ["wavelength_nm", *columns]
    assert data.shape == (rows, len(columns) + 1)
    values = data[:, 1:]
    assert np.all(np.isfinite(values))
    assert np.all(values >= -1e-9) and np.all(values <= 1 + 1e-9)
    return data


def test_cli_predict_varnished_painting(tmp_path, capsys):
    out, png = tmp_path / "p.csv", tmp_path / "plots" / "p.png"
    rc = main(["predict", str(PAINTING), "--wavelengths", "380:780:5", "--geometry", "45/0",
               "--geometry", "sphere:8:sce", "-g", "sphere:8:sci", "-g", "brdf:45:0", "-g", "specular:8",
               "-o", str(out), "--plot", str(png)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    data = _check_output(out, ["45/0", "sphere:8:sce", "sphere:8:sci", "brdf:45:0", "R_8", "T_8", "A_8"])
    np.testing.assert_array_equal(data[:, 0], parse_wavelengths("380:780:5"))
    # red paint under varnish: dark in the blue-green, bright in the red
    assert data[data[:, 0] == 500.0, 1][0] < 0.05 and data[data[:, 0] == 700.0, 1][0] > 0.3
    # BRDF is the reflectance factor / pi; SCI = SCE + specular R
    np.testing.assert_allclose(data[:, 4], data[:, 1] / math.pi, rtol=1e-9)  # CSV keeps 10 digits
    np.testing.assert_allclose(data[:, 3], data[:, 2] + data[:, 5], rtol=1e-9)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    lines = captured.out.strip().splitlines()
    assert len(lines) == 2 and str(out) in lines[0] and str(png) in lines[1]


def test_cli_predict_thin_film_on_metal(tmp_path, capsys):
    out, png = tmp_path / "f.csv", tmp_path / "f.png"
    rc = main(["predict", str(FILM), "--wavelengths", "380:780:5", "--geometry", "specular:30",
               "-o", str(out), "--plot", str(png)])
    assert rc == 0, capsys.readouterr().err
    data = _check_output(out, ["R_30", "T_30", "A_30"])
    np.testing.assert_allclose(data[:, 1] + data[:, 2] + data[:, 3], 1.0, atol=1e-12)
    assert np.all(data[:, 1] > 0.7)  # aluminium mirror
    assert png.stat().st_size > 10_000


def test_cli_float32_restores_precision(tmp_path, capsys):
    before = bool(jax.config.read("jax_enable_x64"))
    out = tmp_path / "f32.csv"
    rc = main(["predict", str(FILM), "-w", "400,550,700", "-g", "specular:0:R", "-o", str(out), "--float32"])
    assert rc == 0, capsys.readouterr().err
    assert bool(jax.config.read("jax_enable_x64")) == before
    _check_output(out, ["R_0"], rows=3)


@pytest.mark.parametrize(
    "args, needle",
    [
        (["-g", "sphere:8:xyz"], "unknown geometry 'sphere:8:xyz'"),
        (["-g", "45-0"], "unknown geometry '45-0'"),
        (["-g", "specular:95"], "[0, 90)"),
        (["-g", "45/0", "-g", "45/0"], "requested twice"),
        (["-g", "45/0", "-w", "380:780"], "bad wavelengths"),
        (["-g", "45/0", "-w", "300:780:10"], "outside the data range"),
    ],
)
def test_cli_bad_input_exit_2(tmp_path, capsys, args, needle):
    out = tmp_path / "x.csv"
    rc = main(["predict", str(PAINTING), *args, "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("layerstack: error: ") and needle in err, err
    assert "Traceback" not in err
    assert not out.exists()


def test_cli_directional_over_substrate(tmp_path, capsys):
    rc = main(["predict", str(FILM), "-g", "45/0", "-o", str(tmp_path / "x.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and "geometry '45/0'" in err and "substrate" in err


def test_cli_bad_stack_file(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[[layers]]\nn = 1.5\ncoherent = true\n[substrate]\nn = 1.5\n')
    rc = main(["predict", str(bad), "-g", "specular:0", "-o", str(tmp_path / "x.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and str(bad) in err and "'thickness_nm'" in err and "Traceback" not in err
    rc = main(["predict", str(tmp_path / "missing.toml"), "-g", "specular:0", "-o", str(tmp_path / "x.csv")])
    assert rc == 2 and "not found" in capsys.readouterr().err


def test_cli_usage_errors(capsys):
    assert main(["predict", str(PAINTING), "-o", "x.csv"]) == 2  # --geometry is required
    assert "--geometry" in capsys.readouterr().err
    assert main(["predict", str(PAINTING), "-g", "45/0", "-o", "x.csv", "--nodes", "0"]) == 2
    assert main([]) == 2
    assert main(["--version"]) == 0
