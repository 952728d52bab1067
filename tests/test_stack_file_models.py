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
from layerstack_jax.io import load_stack, save_stack

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
    stack, declarations = ft.load_fit_parameters(path)
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
    """ψ/Δ at 70° of the true stack (h = 60 nm, Tauc–Lorentz A = 200 eV, Cauchy A = 1.46); the
    file's starts are 50 nm, 150 eV, 1.40: the fit returns the truth."""
    path = tmp_path / "m.toml"
    path.write_text(MODEL)
    stack, params = ft.load_fit_parameters(path)
    wl = np.linspace(300.0, 900.0, 41)
    e = ls.ellipsometry(_truth(), wl, 70.0)
    datasets = [ft.Dataset(ls.Ellipsometric(70.0, q), np.asarray(v), sigma=s)
                for q, v, s in (("psi", e.psi_deg, 0.01), ("delta", e.delta_deg, 0.02))]
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
    _refused(tmp_path, n_spec, message, load_stack)


def _refused(tmp_path, n_spec, message, load):
    """A one-film stack file whose ``n = n_spec`` ``load`` refuses with ``message``, naming the
    file and the layer."""
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
        load(tmp_path / "e.toml")
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
        load_stack(tmp_path / "s.toml")
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


# ------------------------------------------------------- effective media, Sellmeier terms (issue 15)
MIXED = """
[[layers]]
name = "rough"
thickness_nm = 4
coherent = true
n = { bruggeman = { materials = [{ cauchy = [1.46, 0.004] }, 1.0], fractions = { value = 0.3, free = true } } }

[[layers]]
name = "glass"
thickness_nm = 150
coherent = true
n = { sellmeier = { B = [{ value = 0.6, free = true, min = 0.3, max = 0.9 }, 0.4079426, 0.8974794], C = [0.0046791, { value = 0.0135121, free = true, min = 0.01, max = 0.02 }, 97.934] } }

[[layers]]
name = "mix"
thickness_nm = 10
coherent = true
n = { looyenga = { materials = [{ tauc_lorentz = { Eg = 3.2, A = { value = 150, free = true, min = 10, max = 500 }, E0 = 4.2, C = 1.5, eps_inf = 2.2 } }, { n = 3.9, k = 0.5 }, 1.0], fractions = [0.3, { value = 0.2, free = true }] } }

[substrate]
n = 3.9
k = 0.02
"""

_B = np.array([0.6961663, 0.4079426, 0.8974794])
_C = np.array([0.0046791, 0.0135121, 97.934])


def _mixed_truth(fraction=0.5, b1=0.6961663):
    return ls.Stack(1.0, [ls.Layer(ls.Bruggeman([ls.Cauchy(1.46, 0.004), 1.0], fraction), 4.0, name="rough"),
                          ls.Layer(ls.Sellmeier(np.array([b1, *_B[1:]]), _C), 150.0, name="glass")],
                    ls.Substrate(ls.Index(3.9, 0.02)))


def test_effective_media_and_sellmeier_terms_read_as_built_in_python(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(MIXED)
    stack, declarations = ft.load_fit_parameters(path)
    wl = np.linspace(300.0, 900.0, 61)
    tl = ls.TaucLorentz(Eg=3.2, A=150.0, E0=4.2, C=1.5, eps_inf=2.2)
    want = [ls.Bruggeman([ls.Cauchy(1.46, 0.004), ls.Index(1.0)], 0.3),
            ls.Sellmeier(np.array([0.6, *_B[1:]]), _C),
            ls.Looyenga([tl, ls.Index(3.9, 0.5), ls.Index(1.0)], np.array([0.3, 0.2]))]
    for got, ref in zip(stack.layers, want):
        assert type(got.index) is type(ref)
        np.testing.assert_allclose(np.asarray(got.index(wl)), np.asarray(ref(wl)), rtol=0, atol=1e-14)
    assert [(d.path, d.name, d.lower, d.upper) for d in declarations] == [
        (("layers", "rough", "index", "fractions"), "bruggeman.fractions[rough]", 0.0, 1.0),  # default bounds [0, 1]
        (("layers", "glass", "index", "B", 0), "sellmeier.B1[glass]", 0.3, 0.9),
        (("layers", "glass", "index", "C", 1), "sellmeier.C2[glass]", 0.01, 0.02),
        (("layers", "mix", "index", "materials", 0, "A"), "looyenga.materials1.tauc_lorentz.A[mix]", 10.0, 500.0),
        (("layers", "mix", "index", "fractions", 1), "looyenga.fractions2[mix]", 0.0, 1.0),
    ]
    # the writer round-trips every one of them (free annotations aside: the values are written)
    save_stack(tmp_path / "out.toml", stack)
    again = load_stack(tmp_path / "out.toml")
    for got, ref in zip(again.layers, stack.layers):
        np.testing.assert_allclose(np.asarray(got.index(wl)), np.asarray(ref.index(wl)), rtol=0, atol=1e-14)


def test_roughness_is_one_line_and_bruggeman_solves_its_quadratic(tmp_path):
    """Surface roughness as a 50 % void layer over an absorbing medium; the value at 600 nm is
    checked against the two-phase Bruggeman condition f(εa − ε)/(εa + 2ε) + (1 − f)(εb − ε)/(εb
    + 2ε) = 0 multiplied out here with numpy polynomials (Aspnes et al., PRB 20, 3292 (1979)),
    its passive root (Im ε ≥ 0) taken."""
    (tmp_path / "r.toml").write_text("""
[[layers]]
name = "rough"
thickness_nm = 3
coherent = true
n = { bruggeman = { materials = [{ n = 3.9, k = 0.5 }, 1.0], fractions = 0.5 } }
[substrate]
n = 3.9
k = 0.5
""")
    got = complex(np.ravel(load_stack(tmp_path / "r.toml").layers[0].index(np.array([600.0])))[0]) ** 2
    ea, eb, f = (3.9 + 0.5j) ** 2, 1.0, 0.5
    P = np.polynomial.Polynomial
    condition = f * P([ea, -1]) * P([eb, 2]) + (1 - f) * P([eb, -1]) * P([ea, 2])
    roots = condition.roots()
    passive = roots[np.imag(roots) >= 0]
    assert passive.size == 1
    np.testing.assert_allclose(got, passive[0], rtol=1e-14, atol=0)
    # the documented line (README, io): roughness on silicon from the database; an absorbing
    # constituent where the medium must be transparent is refused, naming it
    (tmp_path / "si.toml").write_text("""
[[layers]]
name = "rough"
thickness_nm = 3
coherent = true
n = { bruggeman = { materials = [{ material = "Si", source = "Aspnes" }, 1.0], fractions = 0.5 } }
[substrate]
n = { material = "Si", source = "Aspnes" }
""")
    wl = np.linspace(300.0, 800.0, 11)
    np.testing.assert_array_equal(np.asarray(load_stack(tmp_path / "si.toml").layers[0].index(wl)),
                                  np.asarray(ls.Bruggeman([ls.material("Si", "Aspnes"), 1.0], 0.5)(wl)))
    (tmp_path / "a.toml").write_text("""
[ambient]
n = { looyenga = { materials = [{ n = 1.5, k = 0.1 }, 1.0], fractions = 0.5 } }
[substrate]
n = 1.5
""")
    with pytest.raises(ls.LayerstackError, match=r"a.toml: \[ambient\]: looyenga material 1: key 'k': not allowed here"):
        load_stack(tmp_path / "a.toml")


@pytest.mark.slow  # ~100 s idle, ~260 s on the shared 2-core machine (compiling the ψ/Δ Jacobian); make test-slow
def test_free_fraction_and_sellmeier_term_are_fitted(tmp_path):
    """ψ/Δ at 65° and 70° of the true stack (roughness fraction 0.5, Sellmeier B1 = 0.6961663 of
    fused silica, Malitson 1965); the file starts at 0.3 and 0.6: the fit returns the truth."""
    path = tmp_path / "m.toml"
    path.write_text(MIXED.split("[[layers]]\nname = \"mix\"")[0] + "[substrate]\nn = 3.9\nk = 0.02\n")
    stack, params = ft.load_fit_parameters(path)
    assert [p.name for p in params] == ["bruggeman.fractions[rough]", "sellmeier.B1[glass]", "sellmeier.C2[glass]"]
    params = params[:2]  # C2 stays at its (true) value
    wl = np.linspace(300.0, 900.0, 31)
    e = ls.ellipsometry(_mixed_truth(), wl, np.array([65.0, 70.0]))
    datasets = [ft.Dataset(ls.Ellipsometric(a, q), np.asarray(v)[i], sigma=s)
                for i, a in enumerate((65.0, 70.0)) for q, v, s in (("psi", e.psi_deg, 0.01), ("delta", e.delta_deg, 0.02))]
    r = ft.fit(ft.Objective(stack, wl, datasets, params))
    assert r.converged, r.reason
    np.testing.assert_allclose([float(r.values["bruggeman.fractions[rough]"]), float(r.values["sellmeier.B1[glass]"])],
                               [0.5, 0.6961663], rtol=1e-6)


def test_a_parameter_path_may_end_with_an_element_index():
    """``("layers", i, "index", "B", 0)``: one Sellmeier term freed, the others kept; the same
    array freed whole and by element, or an element twice, is refused; a bad index is named."""
    from fitting._layout import Layout, resolve_parameter

    stack = _mixed_truth()
    wl = np.linspace(400.0, 800.0, 5)
    b1 = ft.Parameter(("layers", "glass", "index", "B", 0), name="B1")
    c3 = ft.Parameter(("layers", 1, "index", "C", 2), name="C3")
    layout = Layout([resolve_parameter(p, stack, wl, 1) for p in (b1, c3)], 1)
    np.testing.assert_array_equal(layout.x0, [_B[0], _C[2]])
    out = layout.inject(stack, [np.array([0.7]), np.array([90.0])])
    np.testing.assert_array_equal(np.asarray(out.layers[1].index.B), [0.7, *_B[1:]])
    np.testing.assert_array_equal(np.asarray(out.layers[1].index.C), [*_C[:2], 90.0])
    np.testing.assert_array_equal(np.asarray(stack.layers[1].index.B), _B)  # the template is untouched
    whole = ft.Parameter(("layers", "glass", "index", "B"), name="B")
    for pair in ((b1, whole), (whole, b1), (b1, b1)):
        with pytest.raises(ls.LayerstackError, match="freed twice"):
            Layout([resolve_parameter(p, stack, wl, 1) for p in pair], 1)
    with pytest.raises(ls.LayerstackError, match="'B9'.*has 3 elements, no element 8"):
        resolve_parameter(ft.Parameter(("layers", "glass", "index", "B", 8), name="B9"), stack, wl, 1)
    with pytest.raises(ls.LayerstackError, match="free the number itself"):
        resolve_parameter(ft.Parameter(("layers", "rough", "index", "fractions", 0)), stack, wl, 1)
    with pytest.raises(ls.LayerstackError, match="has 2 entries, no entry 2"):
        resolve_parameter(ft.Parameter(("layers", "rough", "index", "materials", 2, "A")), stack, wl, 1)


@pytest.mark.parametrize("n_spec, message", [
    ("{ bruggeman = { materials = [3.9, 1.0], fractions = 1.5 } }", "bruggeman: Bruggeman.fractions must lie in \\[0, 1\\]"),
    ("{ bruggeman = { materials = [3.9, 1.0], fractions = { value = 0.5, free = true, min = -0.1, max = 1 } } }",
     "bruggeman.fractions: bounds \\[-0.1, 1\\] outside the range \\[0, 1\\]"),
    ("{ bruggeman = { materials = [3.9, 1.0], fraction = 0.5 } }", "fraction.*did you mean 'fractions'"),
    ("{ bruggeman = { materials = [3.9], fractions = 0.5 } }", "bruggeman needs materials = \\[<n>, <n>, ...\\]"),
    ("{ looyenga = { materials = [3.9, 1.0, 1.5], fractions = 0.5 } }", "Looyenga.fractions: give the volume fractions"),
    ("{ bruggeman = { materials = [{ n = 1.5, k = -1 }, 1.0], fractions = 0.5 } }", "bruggeman material 1: key .k.: must be >= 0"),
    ("{ sellmeier = { B = [{ value = 0.7, free = true }, 0.4], C = [0.005] } }",
     "sellmeier B and C must have the same length, got 2 and 1"),
    ("{ sellmeier = { B = [{ value = 0.7, free = true, mn = 0.5 }], C = [0.005] } }", "missing value|mn"),
    ("{ sellmeier = { B = { value = 0.7, free = true }, C = [0.005] } }", "sellmeier B must be a non-empty list"),
])
def test_mixture_and_sellmeier_errors_name_file_layer_and_coefficient(tmp_path, n_spec, message):
    _refused(tmp_path, n_spec, message, ft.load_fit_parameters)
