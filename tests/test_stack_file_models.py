"""Dispersion models and their coefficients in stack files (issue 15): oscillator models by
name, any scalar coefficient declared free like a thickness, fitted through the same path as
every other parameter.

The references: the same materials built in Python (the file must give the same stack), and the
values that made the synthetic ψ/Δ data (the fit must return them). Errors name the file, the
layer and the coefficient.
"""

from __future__ import annotations

import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls
from layerstack_jax.io import load_fit_stack, load_stack

MODEL = """
[[layers]]
name = "film"
thickness_nm = { value = 50, free = true, min = 1, max = 200 }
coherent = true
n = { tauc_lorentz = { Eg = 3.2, A = { value = 150, free = true, min = 10, max = 500 }, E0 = 4.2, C = 1.5, eps_inf = 2.2 } }

[[layers]]
name = "cap"
thickness_nm = 20
coherent = true
n = { cauchy = [{ value = 1.40, free = true, min = 1.3, max = 1.7 }, 0.004] }

[substrate]
n = 3.9
k = 0.02
"""


def _truth(h=60.0, a=200.0, cauchy_a=1.46):
    return ls.Stack(1.0, [ls.Layer(ls.TaucLorentz(Eg=3.2, A=a, E0=4.2, C=1.5, eps_inf=2.2), h, name="film"),
                          ls.Layer(ls.Cauchy(cauchy_a, 0.004), 20.0, name="cap")], ls.Substrate(ls.Index(3.9, 0.02)))


def test_models_and_free_coefficients_read_as_built_in_python(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(MODEL)
    stack, declarations = load_fit_stack(path)
    wl = np.linspace(300.0, 900.0, 61)
    want = _truth(50.0, 150.0, 1.40)
    for got, ref in zip(stack.layers, want.layers):
        assert type(got.index) is type(ref.index)
        np.testing.assert_allclose(np.asarray(got.index(wl)), np.asarray(ref.index(wl)), rtol=0, atol=1e-14)
    assert [(d.path, d.name, d.lower, d.upper) for d in declarations] == [
        (("layers", "film", "thickness"), "thickness_nm[film]", 1.0, 200.0),
        (("layers", "film", "index", "A"), "tauc_lorentz.A[film]", 10.0, 500.0),
        (("layers", "cap", "index", "A"), "cauchy.A[cap]", 1.3, 1.7),
    ]


def test_oscillator_lists_and_every_model_name(tmp_path):
    text = """
[[layers]]
name = "a"
thickness_nm = 10
coherent = true
n = { lorentz = { A = [10.0, 5.0], E0 = [3.0, 5.0], gamma = [0.1, 0.2], eps_inf = 1.5 } }
[[layers]]
name = "b"
thickness_nm = 10
coherent = true
n = { drude = { Ep = 9.0, gamma = 0.07 } }
[[layers]]
name = "c"
thickness_nm = 10
coherent = true
n = { cody_lorentz = { Eg = 1.6, A = 50.0, E0 = 3.6, gamma = 2.0, Ep = 1.0, Et = 1.8, Eu = 0.05, eps_inf = 1.0 } }
[[layers]]
name = "d"
thickness_nm = 10
coherent = true
n = { cauchy_urbach = { A = 1.5, B = 0.005, k0 = 0.01, Eb = 3.5, Eu = 0.3 } }
[substrate]
n = 1.5
"""
    (tmp_path / "s.toml").write_text(text)
    stack = load_stack(tmp_path / "s.toml")
    wl = np.linspace(400.0, 800.0, 5)
    refs = [ls.Lorentz(A=np.array([10.0, 5.0]), E0=np.array([3.0, 5.0]), gamma=np.array([0.1, 0.2]), eps_inf=1.5),
            ls.Drude(Ep=9.0, gamma=0.07),
            ls.CodyLorentz(Eg=1.6, A=50.0, E0=3.6, gamma=2.0, Ep=1.0, Et=1.8, Eu=0.05, eps_inf=1.0),
            ls.CauchyUrbach(A=1.5, B=0.005, k0=0.01, Eb=3.5, Eu=0.3)]
    for layer, ref in zip(stack.layers, refs):
        np.testing.assert_allclose(np.asarray(layer.index(wl)), np.asarray(ref(wl)), rtol=0, atol=1e-14)


def test_free_model_coefficients_are_fitted(tmp_path):
    """ψ/Δ at 65° and 70° of the true stack (h = 60 nm, Tauc–Lorentz A = 200 eV, Cauchy A =
    1.46); the file's starts are 50 nm, 150 eV, 1.40: the fit returns the truth."""
    path = tmp_path / "m.toml"
    path.write_text(MODEL)
    stack, params = ft.load_fit_parameters(path)
    wl = np.linspace(300.0, 900.0, 61)
    e = ls.ellipsometry(_truth(), wl, np.array([65.0, 70.0]))
    datasets = [ft.Dataset(ls.Ellipsometric(a, q), np.asarray(v)[i], sigma=s)
                for i, a in enumerate((65.0, 70.0)) for q, v, s in (("psi", e.psi_deg, 0.01), ("delta", e.delta_deg, 0.02))]
    r = ft.fit(ft.Objective(stack, wl, datasets, params))
    assert r.converged, r.reason
    np.testing.assert_allclose([float(np.ravel(r.values[k])[0]) for k in
                                ("thickness_nm[film]", "tauc_lorentz.A[film]", "cauchy.A[cap]")],
                               [60.0, 200.0, 1.46], rtol=1e-6)


@pytest.mark.parametrize("n_spec, message", [
    ("{ tauc_lorentz = { Eg = 3.2, A = 150, E0 = 4.2, C = 1.5, epsinf = 2 } }", "epsinf"),
    ("{ tauc_lorentz = { Eg = 3.2, A = 150, C = 1.5 } }", "tauc_lorentz needs E0"),
    ("{ drude = 9.0 }", "drude must be an inline table of its coefficients"),
    ("{ lorentz = { A = 10, E0 = 3, gamma = -1 } }", "gamma"),
    ("{ cauchy = [{ value = 1.5, free = true }, 0.004, 0.0, 1.0] }", "cauchy takes 1 to 3 coefficients"),
])
def test_model_errors_name_the_coefficient(tmp_path, n_spec, message):
    (tmp_path / "e.toml").write_text(f"""
[[layers]]
name = "film"
thickness_nm = 10
coherent = true
n = {n_spec}
[substrate]
n = 1.5
""")
    with pytest.raises(ls.LayerstackError, match=message) as info:
        load_stack(tmp_path / "e.toml")
    assert "e.toml" in str(info.value) and "film" in str(info.value)


def test_free_coefficients_only_in_layers_and_no_k_beside_a_model(tmp_path):
    (tmp_path / "s.toml").write_text("""
[[layers]]
name = "film"
thickness_nm = 10
coherent = true
n = 1.5
[substrate]
n = { drude = { Ep = { value = 9.0, free = true }, gamma = 0.07 } }
""")
    with pytest.raises(ls.LayerstackError, match="free coefficients are declared in \\[\\[layers\\]\\] only"):
        load_fit_stack(tmp_path / "s.toml")
    (tmp_path / "k.toml").write_text("""
[[layers]]
name = "film"
thickness_nm = 10
coherent = true
n = { drude = { Ep = 9.0, gamma = 0.07 } }
k = 0.1
[substrate]
n = 1.5
""")
    with pytest.raises(ls.LayerstackError, match="the model gives k itself"):
        load_stack(tmp_path / "k.toml")
