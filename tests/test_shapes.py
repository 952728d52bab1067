"""Every public function returns its documented shape, checked at run time (issue 17, "shapes").

The documented shape of a result is the library's own annotation — the return annotation of the
function, or the field annotations of the named tuple it returns (``Float[Array, "*angle wl"]``
…) — read with :func:`typing.get_type_hints`, never restated here. Each result is checked by
jaxtyping + beartype inside one ``jaxtyped`` call that also receives the wavelength grid as
``" wl"`` and the angles as ``"*angle"``: the axis names of the annotation are bound to the
actual inputs, so ``wl`` must be the grid's length and ``*angle`` the angles' shape (``()`` for a
scalar angle), and the dtype kind (Float/Complex) must hold. Only ``predict`` has no annotation
(its ``(*batch, *angle, wl)`` is in the docstring); it is checked against the shape
:func:`reflectance` documents, with the batch axes in front.

Run on a dispersionless stack (where ``(1,)`` instead of ``(wl,)`` used to come out) and on
dispersive ones (Cauchy, Sellmeier, tabulated n,k, a tabulated ρg), each with a scalar and an
array angle. :data:`COVERED` and :data:`NOT_SPECTRA` classify every public function of
``layerstack_jax.__all__``: a new public function must be added to one of them.
"""

import inspect
import typing

import jax.numpy as jnp
import numpy as np
import pytest
from beartype import beartype
from jaxtyping import Array, Shaped, jaxtyped

import layerstack_jax as ls

WL = jnp.linspace(400.0, 800.0, 7)
ANGLES = {"scalar": 30.0, "array": jnp.array([0.0, 30.0, 60.0])}


def _substrate_stacks():
    rho = ls.TabulatedSpectrum([350.0, 850.0], [0.3, 0.7])
    return {
        "dispersionless": ls.Stack(1.0, [ls.Layer(2.0, 100.0), ls.Layer(1.46, 80.0)], ls.Substrate(1.52)),
        "dispersive": ls.Stack(
            1.0,
            [ls.Layer(ls.Cauchy(1.5, 0.004), 100.0),
             ls.Layer(ls.Tabulated([350.0, 850.0], [1.9, 2.1], [0.0, 0.02]), 40.0)],
            ls.Substrate(ls.Sellmeier([1.03, 0.23], [0.006, 0.02]))),
    }, {
        "dispersionless": ls.Stack(1.0, [ls.Layer(1.5, 2e4, coherent=False, alpha=1e-5), ls.Layer(1.6, 80.0)],
                                   ls.LambertianBackground(1.52, 0.6)),
        "dispersive": ls.Stack(
            1.0,
            [ls.Layer(ls.Cauchy(1.5, 0.004), 2e4, coherent=False, alpha=ls.TabulatedSpectrum([350.0, 850.0], [1e-5, 3e-5])),
             ls.Layer(ls.Tabulated([350.0, 850.0], [1.9, 2.1], [0.0, 0.02]), 40.0)],
            ls.LambertianBackground(ls.Sellmeier([1.03], [0.006]), rho)),
    }


SUBSTRATE, BACKGROUND = _substrate_stacks()


def assert_documented(value, annotation, angle=()):
    """``value`` satisfies ``annotation`` with ``wl`` = len(WL) and ``*angle`` = shape of ``angle``."""

    @jaxtyped(typechecker=beartype)
    def check(wavelength: Shaped[Array, " wl"], angles: Shaped[Array, "*angle"], result: annotation) -> None:
        pass

    check(WL, jnp.asarray(angle), value)


def assert_fields_documented(result, angle=()):
    """Every field of a named-tuple result satisfies its field annotation."""
    hints = typing.get_type_hints(type(result))
    assert set(hints) == set(result._fields), f"{type(result).__name__}: unannotated fields"
    for field in result._fields:
        try:
            assert_documented(getattr(result, field), hints[field], angle)
        except Exception as error:
            raise AssertionError(f"{type(result).__name__}.{field}: shape {jnp.shape(getattr(result, field))} "
                                 f"is not {hints[field]} ({error})") from error


def returns(fn):
    return typing.get_type_hints(fn)["return"]


# -- the cases: name -> (stacks, call(stack, angle)) ---------------------------------------------

def _geometry_case(make):
    return lambda stack, angle: ls.reflectance(stack, WL, make(angle))


ARRAY_RETURNING = {
    "reflectance/Specular": (SUBSTRATE, _geometry_case(ls.Specular)),
    "reflectance/Sphere": (BACKGROUND, _geometry_case(lambda a: ls.Sphere(a))),
    "reflectance/Directional": (BACKGROUND, _geometry_case(lambda a: ls.Directional(a, 0.0))),
    "reflectance/BRDF": (BACKGROUND, _geometry_case(lambda a: ls.BRDF(a, 10.0))),
    "specular_mueller": (SUBSTRATE, lambda s, a: ls.specular_mueller(s, WL, a)),
    "polarized_brdf": (BACKGROUND, lambda s, a: ls.polarized_brdf(s, WL, a, 10.0)),
    "diffuse_mueller": (BACKGROUND, lambda s, a: ls.diffuse_mueller(s, WL, a, 10.0)),
}
TUPLE_RETURNING = {
    "specular": (SUBSTRATE, lambda s, a: ls.specular(s, WL, a)),
    "specular/background": (BACKGROUND, lambda s, a: ls.specular(s, WL, a)),
    "ellipsometry": (SUBSTRATE, lambda s, a: ls.ellipsometry(s, WL, a)),
    "coated_rough": (SUBSTRATE, lambda s, a: ls.coated_rough(s, WL, a, 20.0, sigma_nm=0.2, tau_nm=300.0)),
    "rough_brdf": (SUBSTRATE, lambda s, a: ls.rough_brdf(s, WL, a, 20.0, roughness=0.2)),
}
FUNCTION = {"reflectance/Specular": ls.reflectance, "reflectance/Sphere": ls.reflectance,
            "reflectance/Directional": ls.reflectance, "reflectance/BRDF": ls.reflectance,
            "specular_mueller": ls.specular_mueller, "polarized_brdf": ls.polarized_brdf,
            "diffuse_mueller": ls.diffuse_mueller}

#: public functions whose spectra are checked here (by the tests named in the comment)
COVERED = {"reflectance", "specular_mueller", "polarized_brdf", "diffuse_mueller", "specular", "ellipsometry",
           "coated_rough", "rough_brdf", "predict", "diffuse", "he_torrance_brdf", "reflection_amplitudes"}
#: public functions that return no spectrum of a stack (files, tables, colour, Mueller algebra,
#: per-interface kernels with their own tests), each with its reason
NOT_SPECTRA = {
    "apply_mueller": "Mueller algebra (test_polarimetry)", "cloude_eigenvalues": "Mueller algebra",
    "coherency_matrix": "Mueller algebra", "degree_of_polarization": "Mueller algebra",
    "is_physical": "Mueller algebra", "mueller_from_jones": "Mueller algebra", "stokes": "Mueller algebra",
    "psi_delta": "of given amplitudes", "fresnel_amplitudes": "one interface (annotated '2 *B')",
    "normal_wavevector": "one medium (annotated '...')", "snell_invariant": "angle algebra",
    "photon_energy": "unit conversion", "hemispherical_rule": "quadrature nodes",
    "microfacet_distribution": "facet statistics", "smith_lambda": "facet statistics",
    "delta_e_2000": "colour (annotated)", "delta_e_ab": "colour (annotated)", "srgb_encode": "colour",
    "xyz_to_lab": "colour (annotated)", "xyz_to_xyy": "colour (annotated)",
    "fixed_optics": "returns an Optics cache", "invert_background": "shaped like the measurement given",
    "check_stack": "returns None", "coating_tables": "rendering tables (test_render_lookup)",
    "interpolate_k_d": "rendering tables", "interpolate_k_r": "rendering tables", "interpolate_k_t": "rendering tables",
    "geometry_kinds": "names", "parse_geometry": "parser", "shared_readings": "a grouping of geometries (SharedReadings)", "database_version": "string",
    "material": "returns a Material", "material_sources": "names", "as_cube": "cubes", "open_cube": "cubes",
    "read_envi": "cubes", "read_netcdf": "cubes", "read_npy": "cubes", "read_zarr": "cubes",
    "write_zarr_cube": "cubes", "load_stack": "files", "parse_wavelengths": "files",
    "read_csv_columns": "files", "read_measurement": "files", "read_spectra_csv": "files",
    "save_spectra_csv": "files", "save_stack": "files", "stack_from_dict": "files", "stack_to_dict": "files",
    "write_measurement_csv": "files", "memory_budget": "memory for chunk='auto' (test_auto_chunks)",
    "use_compilation_cache": "configuration (test_programs)", "compilation_cache_dir": "a path (test_programs)",
    "file_fields": "leaf roles (test_exit_seam)", "leaf": "field declaration", "leaf_role_at": "leaf roles",
    "optics_fixed_at": "leaf roles", "replace_at": "returns a Stack", "stack_leaves": "leaf roles",
    "km_reflectance": "Kubelka-Munk closed forms of given K, S, X (test_kubelka_munk)",
    "km_transmittance": "Kubelka-Munk closed forms", "km_r_infinity": "Kubelka-Munk closed forms",
    "k_over_s": "Kubelka-Munk closed forms", "layered": "Kubelka-Munk closed forms",
    "as_spectrum": "a spectrum given by value or function, as given", "progress_reporter": "progress (test_progress)",
    "traced_checks_off": "a context manager (test_validation)",
}

CASES = [(name, kind, angle) for name in (*ARRAY_RETURNING, *TUPLE_RETURNING)
         for kind in ("dispersionless", "dispersive") for angle in ANGLES]


def test_every_public_function_classified():
    functions = {n for n in ls.__all__ if inspect.isfunction(getattr(ls, n))}
    assert not COVERED & set(NOT_SPECTRA)
    assert functions == COVERED | set(NOT_SPECTRA), (
        f"unclassified: {sorted(functions - COVERED - set(NOT_SPECTRA))}, "
        f"gone: {sorted((COVERED | set(NOT_SPECTRA)) - functions)}")


@pytest.mark.filterwarnings("ignore::layerstack_jax.LayerstackWarning")  # absorbing film on the rough object
@pytest.mark.parametrize("name, kind, angle", CASES)
def test_documented_shape(name, kind, angle):
    angle = ANGLES[angle]
    if name in ARRAY_RETURNING:
        stacks, call = ARRAY_RETURNING[name]
        value = call(stacks[kind], angle)
        annotation = returns(FUNCTION[name])
        try:
            assert_documented(value, annotation, angle)
        except Exception as error:
            raise AssertionError(f"{name}: shape {jnp.shape(value)} is not {annotation} ({error})") from error
    else:
        stacks, call = TUPLE_RETURNING[name]
        assert_fields_documented(call(stacks[kind], angle), angle)


def test_documented_shape_catches_a_wrong_one():
    """The check is not vacuous: a spectrum of ``(1,)`` (the old dispersionless result), a
    missing angle axis and a complex array all fail the annotation of :func:`reflectance`."""
    annotation = returns(ls.reflectance)
    assert_documented(jnp.zeros((3, WL.size)), annotation, ANGLES["array"])
    for wrong, angle in ((jnp.zeros(1), ()), (jnp.zeros(WL.size), ANGLES["array"]),
                         (jnp.zeros(WL.size, complex), ())):
        with pytest.raises(Exception):
            assert_documented(wrong, annotation, angle)


@pytest.mark.parametrize("kind", ["dispersionless", "dispersive"])
@pytest.mark.parametrize("angle", list(ANGLES))
def test_predict_shape(kind, angle):
    """``predict``: ``(*batch, *angle, wl)`` — reflectance's annotation with the batch in front."""
    angle = ANGLES[angle]
    stack = BACKGROUND[kind]
    geometry = ls.Directional(angle, 0.0)
    annotation = returns(ls.reflectance)
    assert_documented(jnp.asarray(ls.predict(stack, WL, geometry)), annotation, angle)
    batched = ls.Stack(stack.ambient, [ls.Layer(stack.layers[0].index, jnp.array([[1e4], [2e4]]), False,
                                                stack.layers[0].alpha), *stack.layers[1:]], stack.exit)
    out = np.asarray(ls.predict(batched, WL, geometry))
    assert out.shape[0] == 2
    assert_documented(jnp.asarray(out[0]), annotation, angle)


@pytest.mark.parametrize("kind", ["dispersionless", "dispersive"])
def test_diffuse_shape(kind):
    for stacks in (SUBSTRATE, BACKGROUND):
        assert_fields_documented(ls.diffuse(stacks[kind], WL))


@pytest.mark.parametrize("angle", list(ANGLES))
def test_he_torrance_shape(angle):
    angle = ANGLES[angle]
    for n in (1.52, ls.Sellmeier([1.03], [0.006])(WL)):
        assert_fields_documented(ls.he_torrance_brdf(WL, angle, 20.0, n_substrate=n, sigma_nm=0.2, tau_nm=300.0), angle)


@pytest.mark.parametrize("kind", ["dispersionless", "dispersive"])
@pytest.mark.parametrize("angle", list(ANGLES))
def test_reflection_amplitudes_shape(kind, angle):
    """``(r_s, r_p)``, complex ``(*angle, wl)`` (docstring; the function has no annotation)."""
    angle = ANGLES[angle]
    for r in ls.reflection_amplitudes(SUBSTRATE[kind], WL, angle):
        assert_documented(r, typing.get_type_hints(ls.Ellipsometry)["rho"], angle)

