"""Calibration series from the command line and for any exit (issue 31).

* Stack files give per-sample values and known samples:
  ``thickness_nm = { value = [115000, 480000], free = true, per_sample = true, known = [true, false] }``.
* ``fitting.calibration_series`` takes any exit (a free-standing sheet in air here) and several
  geometries at once (its reflectance and transmittance).
* ``layerstack fit -g specular:θ`` takes R or T from the data's column names, or refuses.
* Rounding negatives in α / k tables are clipped with a warning; larger ones refused.

The synthetic data come from the closed form of a thick slab in air at normal incidence
(incoherent multiple reflections between its two faces, Beer attenuation τ = exp(−α h)):
``R = ρ + (1 − ρ)² ρ τ² / (1 − ρ² τ²)``, ``T = (1 − ρ)² τ / (1 − ρ² τ²)``, ρ the Fresnel
reflectance ((n − 1)/(n + 1))² — not from the library.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls
from layerstack_cli._main import main
from layerstack_jax.io import load_stack

WL = np.linspace(400.0, 700.0, 31)
N_TRUE = 1.49
H_TRUE = np.array([115_000.0, 480_000.0])  # the first sheet's thickness is known
ALPHA_TRUE = 1.5e-6 + 4e-6 * np.exp(-(((WL - 520.0) / 50.0) ** 2))  # 1/nm
SIGMA = 2e-4


def slab(n, h, alpha):
    """``(R, T)`` of a thick, non-coherent slab of index ``n`` in air at normal incidence."""
    rho = ((n - 1.0) / (n + 1.0)) ** 2
    tau = np.exp(-alpha * h)
    den = 1.0 - rho ** 2 * tau ** 2
    return rho + (1.0 - rho) ** 2 * rho * tau ** 2 / den, (1.0 - rho) ** 2 * tau / den


def _noisy_T(seed=0):
    rng = np.random.default_rng(seed)
    return np.stack([slab(N_TRUE, h, ALPHA_TRUE)[1] for h in H_TRUE]) + SIGMA * rng.standard_normal((2, WL.size))


SHEET_TOML = """description = "two sheets of one film, free-standing in air"

[[layers]]
name = "sheet"
n = {{ value = 1.45, free = true, min = 1.2, max = 2.0 }}
thickness_nm = {{ value = [115000, {h2_start}], free = true, per_sample = true, known = [true, false], min = 1000, max = 2e6 }}
coherent = false
alpha_per_nm = {{ value = 3e-6, free = true, basis = "free" }}

[substrate]
n = 1.0
"""


def _write_csv(path, columns: dict):
    names = list(columns)
    rows = np.column_stack([WL] + [columns[n] for n in names])
    np.savetxt(path, rows, delimiter=",", header=",".join(["wavelength_nm"] + names), comments="", fmt="%.12g")


def test_the_library_reads_the_closed_form_slab():
    """The reference above is the library's model of the same slab (so the tests below check
    the fit, not a convention)."""
    stack = ls.Stack(1.0, [ls.Layer(N_TRUE, H_TRUE[1], coherent=False, alpha=ALPHA_TRUE)], ls.Substrate(1.0))
    R, T = slab(N_TRUE, H_TRUE[1], ALPHA_TRUE)
    np.testing.assert_allclose(np.asarray(ls.reflectance(stack, WL, ls.Specular(0.0, "T"))), T, rtol=1e-10)
    np.testing.assert_allclose(np.asarray(ls.reflectance(stack, WL, ls.Specular(0.0, "R"))), R, rtol=1e-10)


def test_two_sheet_transmittance_series_from_the_command_line(tmp_path, capsys):
    """One known thickness, α(λ) free at every wavelength, one n, fitted jointly from the
    command line; ``-g specular:0`` reads T from the column names."""
    (tmp_path / "sheets.toml").write_text(SHEET_TOML.format(h2_start=400000))
    T = _noisy_T()
    _write_csv(tmp_path / "sheets.csv", {"T_thin": T[0], "T_thick": T[1]})
    out = tmp_path / "fit.json"
    status = main(["fit", str(tmp_path / "sheets.toml"), str(tmp_path / "sheets.csv"), "-g", "specular:0", "--joint",
                   "--sigma", str(SIGMA), "-o", str(out)])
    printed = capsys.readouterr()
    assert status == 0, printed.out + printed.err
    payload = json.loads(out.read_text())
    assert payload["geometry"] == "specular:0:T"
    assert "transmittance from the data's column names" in payload["geometry_origin"]
    fit = payload["fits"][0]
    assert fit["converged"]
    p = fit["parameters"]
    h, h_err = np.asarray(p["thickness_nm[sheet]"]["value"]), np.asarray(p["thickness_nm[sheet]"]["stderr"], float)
    assert h[0] == H_TRUE[0]  # known: kept
    assert p["thickness_nm[sheet]"]["fixed"] in ([True, False], [[True], [False]])
    assert abs(h[1] - H_TRUE[1]) < 4 * h_err[1] and abs(h[1] / H_TRUE[1] - 1) < 2e-3
    n, n_err = float(np.ravel(p["n[sheet]"]["value"])[0]), float(np.ravel(p["n[sheet]"]["stderr"])[0])
    assert abs(n - N_TRUE) < 4 * n_err and abs(n - N_TRUE) < 2e-3
    a, a_err = np.asarray(p["alpha_per_nm[sheet]"]["value"]), np.asarray(p["alpha_per_nm[sheet]"]["stderr"])
    assert a.shape == WL.shape
    # within 4 standard errors at every wavelength (the α errors are correlated through n and the
    # free thickness: they move together) and within 1 % of the truth
    z = (a - ALPHA_TRUE) / a_err
    assert np.all(np.abs(z) < 4) and np.all(np.abs(a / ALPHA_TRUE - 1) < 1e-2)
    assert 0.5 < fit["reduced_chi2"] < 1.6


def test_calibration_series_of_free_standing_sheets_in_reflectance_and_transmittance():
    """``calibration_series`` over an exit that is the ambient again (a sheet in air), with R and
    T of the same two sheets in one fit and one n: recovers the truth of the closed form."""
    rng = np.random.default_rng(4)
    R, T = (np.stack(a) for a in zip(*(slab(N_TRUE, h, ALPHA_TRUE) for h in H_TRUE)))
    R, T = R + SIGMA * rng.standard_normal(R.shape), T + SIGMA * rng.standard_normal(T.shape)
    template = ls.Stack(1.0, [ls.Layer(1.45, 100_000.0, coherent=False, alpha=3e-6, name="sheet")], ls.Substrate(1.0))
    obj = ft.calibration_series(template, WL, [R, T], [ls.Specular(0.0, "R"), ls.Specular(0.0, "T")], layer="sheet",
                                thicknesses=[H_TRUE[0], 400_000.0], known=(0,), alpha_basis="free", sigma=SIGMA,
                                parameters=[ft.index_n("sheet", lower=1.2, upper=2.0)])
    assert [d.name for d in obj.datasets] == ["calibration series: specular:0:R", "calibration series: specular:0:T"]
    r = ft.fit(obj)
    assert r.converged
    h = np.ravel(r.values["thickness[sheet]"])
    assert h[0] == H_TRUE[0]
    assert abs(h[1] - H_TRUE[1]) < 4 * np.ravel(r.stderr["thickness[sheet]"])[1]
    n = float(np.ravel(r.values["n[sheet]"])[0])
    assert abs(n - N_TRUE) < 4 * float(np.ravel(r.stderr["n[sheet]"])[0])
    z = (np.ravel(r.spectra["alpha[sheet]"]) - ALPHA_TRUE) / np.ravel(r.stderr["alpha[sheet]"])
    assert np.all(np.abs(z) < 5)


def test_calibration_series_refuses_rho_g_without_a_lambertian_background():
    template = ls.Stack(1.0, [ls.Layer(1.45, 100_000.0, coherent=False, alpha=3e-6, name="sheet")], ls.Substrate(1.0))
    T = _noisy_T()
    with pytest.raises(ls.LayerstackError, match="rho_g and a bare-background measurement belong to a Lambertian"):
        ft.calibration_series(template, WL, T, ls.Specular(0.0, "T"), layer="sheet", rho_g_basis=8)
    obj = ft.calibration_series(template, WL, T, ls.Specular(0.0, "T"), layer="sheet", alpha_basis=5)
    assert [rp.parameter.kind for rp in obj.layout.params] == ["thickness", "alpha"]  # no rho_g by default


# --------------------------------------------------------------------------- stack-file syntax
def _params(tmp_path, thickness_line: str):
    lines = SHEET_TOML.format(h2_start=400000).splitlines()
    lines = [thickness_line if line.startswith("thickness_nm") else line for line in lines]
    (tmp_path / "s.toml").write_text("\n".join(lines) + "\n")
    return ft.load_fit_parameters(tmp_path / "s.toml")


def test_stack_file_per_sample_values_and_known_samples(tmp_path):
    stack, params = _params(tmp_path, "thickness_nm = { value = [115000, 400000, 9e5], free = true, per_sample = true, "
                                      "known = [true, false, false] }")
    p = next(p for p in params if p.kind == "thickness")
    np.testing.assert_array_equal(p.value, [115000.0, 400000.0, 9e5])
    np.testing.assert_array_equal(p.fixed, [True, False, False])
    assert float(stack.layers[0].thickness) == 115000.0  # the stack holds the first sample's value


@pytest.mark.parametrize("line, message", [
    ("thickness_nm = { value = [1e5, 2e5], free = true }", "add per_sample = true"),
    ("thickness_nm = { value = [1e5, 2e5], free = true, per_sample = true, known = [true] }", "known has 1 entries for 2"),
    ("thickness_nm = { value = [1e5, 2e5], free = true, per_sample = true, known = [true, true] }",
     "every sample's value is known"),
    ("thickness_nm = { value = 1e5, free = true, per_sample = true, known = [true, false] }",
     "write value = \\[one number per sample\\]"),
    ("thickness_nm = { value = [1e5, 2e5], per_sample = true, known = [true, false] }", "given but free is not true"),
    ("thickness_nm = { value = [1e5, \"a\"], free = true, per_sample = true }", "list of numbers"),
    ("thickness_nm = { value = [1e5, 2e5], free = true, per_sample = true, known = [1, 0] }", "list of true/false"),
])
def test_stack_file_per_sample_mistakes_are_named(tmp_path, line, message):
    with pytest.raises(ls.LayerstackError, match=message) as e:
        _params(tmp_path, line)
    assert "thickness_nm" in str(e.value)


def test_per_sample_values_must_number_the_spectra(tmp_path, capsys):
    (tmp_path / "sheets.toml").write_text(SHEET_TOML.format(h2_start=400000))
    T = _noisy_T()
    _write_csv(tmp_path / "three.csv", {"T_a": T[0], "T_b": T[1], "T_c": T[1]})
    status = main(["fit", str(tmp_path / "sheets.toml"), str(tmp_path / "three.csv"), "-g", "specular:0:T", "--joint",
                   "-o", str(tmp_path / "o.json")])
    assert status == 2
    assert "thickness_nm[sheet] has 2 per-sample values but the joint fit has 3 spectra (T_a, T_b, T_c)" in \
        capsys.readouterr().err


# --------------------------------------------------------------------------- -g specular:θ
@pytest.mark.parametrize("columns, message", [
    (("thin", "thick"), "the column names do not say"),
    (("R_thin", "T_thick"), "the column names name several of them"),
])
def test_specular_quantity_is_never_assumed(tmp_path, capsys, columns, message):
    (tmp_path / "sheets.toml").write_text(SHEET_TOML.format(h2_start=400000))
    T = _noisy_T()
    _write_csv(tmp_path / "d.csv", dict(zip(columns, T)))
    status = main(["fit", str(tmp_path / "sheets.toml"), str(tmp_path / "d.csv"), "-g", "specular:0", "--joint",
                   "-o", str(tmp_path / "o.json")])
    err = capsys.readouterr().err
    assert status == 2
    assert "-g specular:0 does not say which quantity the spectra are: R (reflectance), T (transmittance)" in err
    assert message in err and "-g specular:0:R" in err


@pytest.mark.parametrize("name", ["T_1", "T", "transmittance sheet 1", "t-thin"])
def test_specular_quantity_from_column_names(name):
    from layerstack_cli._fit import _quantity_from_columns

    g, origin = _quantity_from_columns("specular:8", [name], "d.csv")
    assert g.label == "specular:8:T" and "transmittance from the data's column names" in origin


# --------------------------------------------------------------------------- negative table values
def _alpha_table(tmp_path, values):
    (tmp_path / "alpha.csv").write_text("wavelength_nm,alpha_per_nm\n" + "\n".join(
        f"{w:g},{v:.6g}" for w, v in zip((400, 500, 600, 700), values)))
    (tmp_path / "s.toml").write_text('[[layers]]\nname = "sheet"\nn = 1.5\nthickness_nm = 1e5\ncoherent = false\n'
                                     'alpha_per_nm = { table = "alpha.csv" }\n[substrate]\nn = 1.0\n')
    return tmp_path / "s.toml"


def test_rounding_negatives_in_an_alpha_table_are_clipped_with_a_warning(tmp_path):
    path = _alpha_table(tmp_path, [1e-5, -2.5e-9, 3e-6, 0.0])
    with pytest.warns(ls.LayerstackWarning, match=r"alpha\.csv.*alpha_per_nm: 1 negative value\(s\) down to -2\.5e-09 "
                                                  r"\(within 0\.001 of the largest value"):
        stack = load_stack(path)
    alpha = stack.layers[0].alpha
    np.testing.assert_array_equal(np.asarray(alpha.values), [1e-5, 0.0, 3e-6, 0.0])


def test_larger_negatives_in_an_alpha_table_are_refused(tmp_path):
    path = _alpha_table(tmp_path, [1e-5, -2e-8, 3e-6, 0.0])  # 2e-3 of the largest value
    with warnings.catch_warnings():
        warnings.simplefilter("error", ls.LayerstackWarning)
        with pytest.raises(ls.LayerstackError, match="alpha_per_nm.*values must be >= 0"):
            load_stack(path)


def test_rounding_negatives_in_a_k_column_are_clipped_with_a_warning(tmp_path):
    (tmp_path / "nk.csv").write_text("wavelength_nm,n,k\n400,1.6,0.02\n500,1.55,-1e-8\n600,1.5,0.0\n")
    (tmp_path / "s.toml").write_text('[[layers]]\nname = "film"\nn = { table = "nk.csv" }\nthickness_nm = 100\n'
                                     'coherent = true\n[substrate]\nn = 1.5\n')
    with pytest.warns(ls.LayerstackWarning, match="column k: 1 negative value"):
        stack = load_stack(tmp_path / "s.toml")
    assert np.all(np.asarray(stack.layers[0].index.k) >= 0)
