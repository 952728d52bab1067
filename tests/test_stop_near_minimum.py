"""The statistical stopping rule of the least-squares solvers (``sigma_tol``, issue 19).

A Gauss–Newton-family solve also stops as soon as the Gauss–Newton step still to go is shorter
than ``sigma_tol`` standard errors (MINUIT's estimated distance to the minimum). Checked here:
the distance itself against a least-squares step computed by numpy; noisy fits stop earlier and
land within that distance of the minimum found with the rule off and tight tolerances; noise-free
data never trigger the rule (their answers are bit-identical with and without it).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls
from fitting._least_squares import gauss_newton_distance

WL = np.linspace(400.0, 700.0, 61)
R0 = ls.Specular(0.0, "R")
LEAST_SQUARES = ["lm", "gauss-newton", "dogleg"]
TIGHT = dict(sigma_tol=0.0, rtol=1e-13, atol=1e-15)


def _film(h, n):
    return ls.Stack(1.0, [ls.Layer(n, h, name="film")], ls.Substrate(1.52))


def _objective(noise: float, sigma_given: bool):
    y = np.asarray(ls.reflectance(_film(180.0, 1.85), WL, R0))
    y = y + noise * np.random.default_rng(7).standard_normal(WL.size)
    ds = ft.Dataset(R0, y, sigma=0.001) if sigma_given else ft.Dataset(R0, y)
    return ft.Objective(_film(165.0, 1.75), WL, ds,
                        [ft.thickness("film", lower=100.0, upper=300.0), ft.index_n("film", lower=1.3, upper=2.5)])


def test_distance_is_the_gauss_newton_step_in_standard_errors():
    rng = np.random.default_rng(3)
    J = rng.standard_normal((40, 3)) * np.array([1.0, 30.0, 1e-2])
    r = rng.standard_normal(40)
    step = np.linalg.lstsq(J, -r, rcond=None)[0]  # numpy's Gauss–Newton step
    d2_numpy = step @ (J.T @ J) @ step  # its length² in the metric of the inverse covariance
    d2, s2 = gauss_newton_distance(jnp.asarray(r), jnp.asarray(J), 37)
    assert float(d2) == pytest.approx(d2_numpy, rel=1e-10)
    assert float(s2) == pytest.approx(r @ r / 37, rel=1e-14)
    # a component held on a bound (a zero column) is left out, as if it were not there
    d2_held, _ = gauss_newton_distance(jnp.asarray(r), jnp.asarray(np.column_stack([J[:, :2], 0 * J[:, 2]])), 37)
    step2 = np.linalg.lstsq(J[:, :2], -r, rcond=None)[0]
    assert float(d2_held) == pytest.approx(step2 @ (J[:, :2].T @ J[:, :2]) @ step2, rel=1e-10)


@pytest.mark.parametrize("method", LEAST_SQUARES)
@pytest.mark.parametrize("sigma_given", [True, False], ids=["sigma", "no-sigma"])
def test_noisy_fit_stops_within_sigma_tol_of_the_minimum(method, sigma_given):
    obj = _objective(0.001, sigma_given)
    ref = ft.fit(obj, method, **TIGHT)
    got = ft.fit(obj, method)
    assert ref.converged and got.converged, (ref.reason, got.reason)
    assert got.num_steps < ref.num_steps, (got.num_steps, ref.num_steps)
    x, x_ref = (np.array([float(np.ravel(r.values[k])[0]) for k in ref.values]) for r in (got, ref))
    err = np.array([float(np.ravel(ref.stderr[k])[0]) for k in ref.values])
    assert np.all(np.isfinite(err)) and np.all(err > 0)
    assert np.max(np.abs(x - x_ref) / err) <= 2e-3, (x - x_ref) / err
    # a looser rule stops earlier still, within its own distance
    loose = ft.fit(obj, method, sigma_tol=0.1)
    assert loose.num_steps <= got.num_steps
    xl = np.array([float(np.ravel(loose.values[k])[0]) for k in ref.values])
    assert np.max(np.abs(xl - x_ref) / err) <= 0.2


@pytest.mark.parametrize("method", LEAST_SQUARES)
def test_noise_free_data_never_trigger_the_rule(method):
    obj = _objective(0.0, True)
    on, off = ft.fit(obj, method), ft.fit(obj, method, sigma_tol=0.0)
    assert on.converged and on.num_steps == off.num_steps
    for k in on.values:
        assert np.array_equal(on.values[k], off.values[k])
    assert float(np.ravel(on.values["thickness[film]"])[0]) == pytest.approx(180.0, rel=1e-9)


def test_fit_batch_uses_the_same_rule():
    obj = _objective(0.001, True)
    rng = np.random.default_rng(11)
    y = np.asarray(ls.reflectance(_film(180.0, 1.85), WL, R0))
    data = y + 0.001 * rng.standard_normal((3, WL.size))
    b = ft.fit_batch(obj, data, progress=False)
    for i in range(3):
        r = ft.fit(obj, data=[data[i][None]])
        assert b.num_steps[i] == r.num_steps
        assert b.values["thickness[film]"][i] == pytest.approx(float(r.values["thickness[film]"]), rel=1e-12)


@pytest.mark.parametrize("bad", [-1e-3, 1.0, float("nan"), "1e-3"])
def test_sigma_tol_out_of_range_is_refused(bad):
    with pytest.raises(ls.LayerstackError, match="sigma_tol"):
        ft.fit(_objective(0.0, True), sigma_tol=bad)
