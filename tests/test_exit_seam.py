"""The exit-medium seam (issue 28): an exit defined outside the library, in this file only, is
predicted, batched, fitted and set from ``--vary`` like the library's own — no edit elsewhere.

``GreyBody`` is a toy diffusing exit (its internal reflectance is one number ``albedo`` or a
spectrum): physically a :class:`~layerstack_jax.LambertianBackground` under another name, so every
expected value comes from that independent, long-tested class.
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls
from layerstack_cli._predict import _set_field

WL = np.linspace(420.0, 680.0, 14)
SPHERE = ls.Sphere(8.0, "excluded")


class GreyBody(ls.ExitMedium):
    """A toy diffusing exit: ρg = ``albedo`` (dimensionless, a number or a spectrum on the grid)."""

    index: ls.Material = ls.leaf()
    albedo: object = ls.leaf(spectral=True, fixed_optics=True, per_wavelength=True, file_key="albedo")
    diffuse: ClassVar[bool] = True
    table: ClassVar[str] = "greybody"
    label: ClassVar[str] = "grey body"

    def lower(self, wavelength_nm):
        return jnp.asarray(self.albedo)


def _stack(exit_, h=20_000.0):
    return ls.Stack(1.0, [ls.Layer(1.5, h, coherent=False, alpha=2e-5, name="varnish")], exit_)


def test_a_new_exit_is_predicted_like_the_background_it_equals():
    for g in (SPHERE, ls.Directional(45.0, 0.0), ls.Sphere(8.0, "included")):
        got = ls.reflectance(_stack(GreyBody(ls.Index(1.5), 0.35)), WL, g)
        want = ls.reflectance(_stack(ls.LambertianBackground(1.5, 0.35)), WL, g)
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=0, atol=1e-15)


def test_roles_of_a_new_exit_come_from_its_field_declarations():
    stack = _stack(GreyBody(ls.Index(1.5), 0.35))
    leaves = {leaf.path: leaf for leaf in ls.stack_leaves(stack)}
    albedo = leaves[("exit", "albedo")]
    assert albedo.role.axes == "spectral" and albedo.fixed_optics and albedo.role.file_key == "albedo"
    assert not leaves[("exit", "index", "n")].fixed_optics
    assert leaves[("layers", 0, "thickness")].fixed_optics  # incoherent layer: its callable declaration
    coherent = ls.Stack(1.0, [ls.Layer(1.5, 100.0)], GreyBody(ls.Index(1.5), 0.35))
    assert not ls.optics_fixed_at(coherent, ("layers", 0, "thickness"))
    assert ls.optics_fixed_at(stack, ("exit", "albedo"))
    assert ls.file_fields(stack.exit) == {"albedo": "albedo"}


def test_a_new_exit_is_batchable_with_the_optics_computed_once():
    from layerstack_jax._instruments.batched import _optics_fixed_by, batch_layout

    albedo = np.array([[0.1], [0.5], [0.9]])
    stack = _stack(GreyBody(ls.Index(1.5), albedo))
    lay = batch_layout(stack, WL.size)
    assert lay.batch_shape == (3,) and _optics_fixed_by(stack, lay.names, lay.batched)
    got = np.asarray(ls.predict(stack, WL, SPHERE))
    for i, a in enumerate(albedo[:, 0]):
        want = ls.reflectance(_stack(ls.LambertianBackground(1.5, float(a))), WL, SPHERE)
        np.testing.assert_allclose(got[i], np.asarray(want), rtol=0, atol=1e-14)


def test_a_new_exit_is_fitted_with_fixed_optics():
    truth = np.asarray(ls.reflectance(_stack(ls.LambertianBackground(1.5, 0.62)), WL, SPHERE))
    obj = ft.Objective(_stack(GreyBody(ls.Index(1.5), 0.3)), WL, ft.Dataset(SPHERE, truth),
                       [ft.Parameter(("exit", "albedo"), kind="rho_g", name="albedo")])
    assert obj._fixed_optics() is not None  # a free albedo leaves the Fresnel algebra fixed
    r = ft.fit(obj)
    assert r.converged, r.reason
    assert r.values["albedo"] == pytest.approx(0.62, rel=1e-8)


def test_a_new_exit_is_set_from_vary():
    stack = _stack(GreyBody(ls.Index(1.5), 0.3))
    batched = _set_field(stack, "greybody.albedo", np.array([0.2, 0.4]), "s.toml")
    np.testing.assert_array_equal(np.asarray(batched.exit.albedo), [[0.2], [0.4]])
    batched = _set_field(stack, "greybody.n", np.array([1.4, 1.6]), "s.toml")
    np.testing.assert_array_equal(np.asarray(batched.exit.index.n), [[1.4], [1.6]])
    with pytest.raises(ls.LayerstackError, match=r"has a \[greybody\], not a \[background\]"):
        _set_field(stack, "background.rho_g", np.array([0.2]), "s.toml")
    with pytest.raises(ls.LayerstackError, match="unknown field 'rho_g' of \\[greybody\\]; fields: albedo, n, k"):
        _set_field(stack, "greybody.rho_g", np.array([0.2]), "s.toml")
