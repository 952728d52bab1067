"""`layerstack fit` and free parameters in stack files (the reader returns the fitting words
unread, ``layerstack_jax.io.Annotation``; ``fitting.load_fit_parameters`` makes parameters of them).

The data are made by the public forward model with known values; the command line must give
them back. A cheap model (an absorbing slab on glass, specular transmittance) keeps compilation
short.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_cli import main
import fitting as ft
from layerstack_jax.io import load_stack, read_toml, save_spectra_csv, stack_from_dict

WL = np.arange(400.0, 701.0, 10.0)

STACK = """
[[layers]]
name = "slab"
n = 1.5
thickness_nm = {{ value = 8000, free = true, min = 0, max = 1e5 }}
coherent = false
alpha_per_nm = {alpha}

[substrate]
n = 1.5
"""


def _truth(h, alpha):
    st = ls.Stack(1.0, [ls.Layer(1.5, h, coherent=False, alpha=alpha, name="slab")], ls.Substrate(1.5))
    return np.asarray(ls.reflectance(st, WL, ls.Specular(0.0, "T")))


def test_the_reader_returns_fitting_words_unread_and_fitting_makes_parameters_of_them(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text(STACK.format(alpha="{ value = 2e-5, free = true, basis = 4 }"))
    found: list = []
    stack = stack_from_dict(read_toml(f), f.parent, source=str(f), annotations=found)
    assert float(stack.layers[0].thickness) == 8000.0
    assert [(a.path, a.kind, a.name, a.key, a.words, a.spectral) for a in found] == [
        (("layers", "slab", "thickness"), "thickness", "thickness_nm[slab]", "thickness_nm",
         {"free": True, "min": 0, "max": 1e5}, False),
        (("layers", "slab", "alpha"), "alpha", "alpha_per_nm[slab]", "alpha_per_nm", {"free": True, "basis": 4}, True),
    ]
    # fitting reads the words: the file's bounds and basis, in the file's units
    _, params = ft.load_fit_parameters(f)
    assert [(p.path, p.kind, p.name, p.lower, p.upper, p.basis) for p in params] == [
        (("layers", "slab", "thickness"), "thickness", "thickness_nm[slab]", 0.0, 1e5, None),
        (("layers", "slab", "alpha"), "alpha", "alpha_per_nm[slab]", None, None, 4),
    ]
    # load_stack reads the same file, values only
    assert float(load_stack(f).layers[0].alpha) == 2e-5


@pytest.mark.parametrize(
    "alpha, message",
    [
        ("{ value = 2e-5, free = true, min = 1, max = 0 }", "bounds inverted"),
        ("{ value = 2e-5, min = 0 }", "given but free is not true"),
        ("{ free = true }", "missing value"),
        ("{ value = 2e-5, free = true, basis = 0 }", "basis must be"),
    ],
)
def test_bad_free_declarations(tmp_path, alpha, message):
    f = tmp_path / "s.toml"
    f.write_text(STACK.format(alpha=alpha))
    with pytest.raises(ls.LayerstackError, match=message):
        ft.load_fit_parameters(f)
    if message != "missing value":  # the words are fitting's: a prediction reads the value and skips them
        assert float(load_stack(f).layers[0].alpha) == 2e-5


def test_cli_fit_recovers_thickness(tmp_path, capsys):
    stack = tmp_path / "s.toml"
    stack.write_text(STACK.format(alpha="2e-5"))
    data = tmp_path / "d.csv"
    save_spectra_csv(data, WL, {"a": _truth(10_000.0, 2e-5), "b": _truth(12_500.0, 2e-5)})
    out = tmp_path / "r.json"
    png = tmp_path / "fit.png"
    code = main(["fit", str(stack), str(data), "-g", "specular:0:T", "-o", str(out), "--plot", str(png)])
    text = capsys.readouterr().out
    assert code == 0, text
    # several spectra: one summary line each (no report per column unless --report all),
    # headed by the geometry and the origin of sigma
    assert "geometry: specular:0:T (transmittance; given (-g))" in text and "sigma: estimated from the residuals" in text
    assert "layerstack fit report" not in text and sum(line.strip().startswith(("a ", "b ")) for line in text.splitlines()) == 2
    d = json.loads(out.read_text())
    assert d["geometry"] == "specular:0:T" and d["sigma_origin"].startswith("estimated")
    h = [f["parameters"]["thickness_nm[slab]"]["value"] for f in d["fits"]]
    np.testing.assert_allclose(h, [10_000.0, 12_500.0], rtol=1e-8)
    assert png.stat().st_size > 10_000


def test_cli_fit_errors(tmp_path, capsys):
    stack = tmp_path / "s.toml"
    stack.write_text(STACK.format(alpha="2e-5"))
    data = tmp_path / "d.csv"
    save_spectra_csv(data, WL, {"a": _truth(10_000.0, 2e-5)})
    out = str(tmp_path / "r.json")
    # model grid beyond the data: never extrapolated
    assert main(["fit", str(stack), str(data), "-g", "specular:0:T", "-o", out, "-w", "380:700:10"]) == 2
    assert "never extrapolated" in capsys.readouterr().err
    # negative data
    save_spectra_csv(data, WL, {"a": _truth(10_000.0, 2e-5) - 0.95})
    assert main(["fit", str(stack), str(data), "-g", "specular:0:T", "-o", out]) == 2
    assert "below -0.01 without sigma" in capsys.readouterr().err
    # no free parameter
    plain = tmp_path / "p.toml"
    plain.write_text(STACK.format(alpha="2e-5").replace("{ value = 8000, free = true, min = 0, max = 1e5 }", "8000"))
    assert main(["fit", str(plain), str(data), "-g", "specular:0:T", "-o", out]) == 2
    assert "no free parameter" in capsys.readouterr().err


BG_STACK = """
[[layers]]
name = "varnish"
n = 1.5
thickness_nm = { value = 15000, free = true, per_sample = true, min = 0, max = 1e5 }
coherent = false
alpha_per_nm = 2e-5

[background]
n = 1.5
rho_g = { value = 0.5, free = true, basis = 4 }
"""


def test_cli_joint_fit_with_bare_background(tmp_path, capsys):
    """`--joint --background COLUMN`: per-sample thicknesses and a shared ρg(λ) (4 B-splines),
    the bare-background column fitted as the stack without layers; noise-free data come back."""
    import fitting

    geometry = ls.Directional(45.0, 0.0)
    rho = fitting.bspline_basis(WL, 4) @ np.array([0.2, 0.6, 0.3, 0.7])

    def measured(layers):
        return np.asarray(ls.reflectance(ls.Stack(1.0, layers, ls.LambertianBackground(1.5, rho)), WL, geometry))

    hs = [8_000.0, 20_000.0]
    cols = {f"h{i}": measured([ls.Layer(1.5, h, coherent=False, alpha=2e-5, name="varnish")]) for i, h in enumerate(hs)}
    cols["bare"] = measured([])
    stack = tmp_path / "s.toml"
    stack.write_text(BG_STACK)
    data = tmp_path / "d.csv"
    save_spectra_csv(data, WL, cols)
    out = tmp_path / "r.json"
    code = main(["fit", str(stack), str(data), "-g", "45/0", "--joint", "--background", "bare", "--method", "trf",
                 "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "bare background" in text
    fit = json.loads(out.read_text())["fits"][0]
    assert fit["spectrum"] == "h0+h1"
    h = fit["parameters"]["thickness_nm[varnish]"]["value"]
    np.testing.assert_allclose(h, hs, rtol=1e-6)
    np.testing.assert_allclose(fit["parameters"]["rho_g"]["value"], [0.2, 0.6, 0.3, 0.7], rtol=1e-6)
    # --background without --joint, or naming a missing column: exit 2 with the reason
    assert main(["fit", str(stack), str(data), "-g", "45/0", "--background", "bare", "-o", str(out)]) == 2
    assert "--background needs --joint" in capsys.readouterr().err
    assert main(["fit", str(stack), str(data), "-g", "45/0", "--joint", "--background", "nope", "-o", str(out)]) == 2
    assert "no column 'nope'" in capsys.readouterr().err


def test_cli_keeps_compiled_programs_on_disk(tmp_path):
    """`layerstack fit` in a fresh process writes its compiled programs to the persistent cache
    ($LAYERSTACK_CACHE_DIR); a second run of the same model structure loads them (no new entry)
    and gives the same result; LAYERSTACK_CACHE_DIR= (empty) writes nothing."""
    import os
    import subprocess
    import sys

    stack = tmp_path / "s.toml"
    stack.write_text(STACK.format(alpha="2e-5"))
    data = tmp_path / "d.csv"
    save_spectra_csv(data, WL, {"a": _truth(10_000.0, 2e-5)})
    cache = tmp_path / "cache"

    def run(out, cache_dir):
        env = dict(os.environ, LAYERSTACK_CACHE_DIR=cache_dir, JAX_PLATFORMS="cpu",
                   JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0")  # this small model compiles fast
        proc = subprocess.run([sys.executable, "-m", "layerstack_cli", "fit", str(stack), str(data), "-g",
                               "specular:0:T", "-o", str(out)], env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
        return json.loads(out.read_text())["fits"][0]["parameters"]

    first = run(tmp_path / "1.json", str(cache))
    entries = {p.name for p in cache.iterdir() if p.name.startswith("jit_")} if cache.exists() else {"no cache dir"}
    assert any(e.startswith("jit_run") for e in entries), entries  # the compiled fit itself
    second = run(tmp_path / "2.json", str(cache))
    assert {p.name for p in cache.iterdir() if p.name.startswith("jit_")} == entries
    assert second == first
    off = tmp_path / "off"
    run(tmp_path / "3.json", "")
    assert not off.exists()


def test_a_list_value_without_per_sample_is_refused_by_every_loader(tmp_path):
    """``value = [a, b]`` is one value per sample; without ``per_sample = true`` a prediction would
    otherwise read the first number and say nothing."""
    f = tmp_path / "s.toml"
    f.write_text(STACK.format(alpha="2e-5").replace("{ value = 8000, free = true, min = 0, max = 1e5 }",
                                                    "{ value = [8000, 9000], free = true }"))
    for load in (load_stack, ft.load_fit_parameters):
        with pytest.raises(ls.LayerstackError, match=r"one value per sample: add per_sample = true"):
            load(f)
