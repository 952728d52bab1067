"""Every solver on the same problems (issue 17; optimistix tests its solvers the same way).

Data are made by the public forward model with known values; each method must find them: an
interior optimum (α of an absorbing slab), an optimum on a bound (data brighter than any α ≥ 0
allows: the least-squares α is exactly 0), and two coupled parameters (thickness and index of a
coherent film, from the fringes of its specular reflectance). The reference values are the ones
that made the data, not another fit.
"""

from __future__ import annotations

import numpy as np
import pytest

import fitting as ft
import layerstack_jax as ls

WL = np.linspace(400.0, 700.0, 41)
T0 = ls.Specular(0.0, "T")
R0 = ls.Specular(0.0, "R")
METHODS = ["lm", "gauss-newton", "dogleg", "bfgs", "lbfgsb", "trf"]


def _slab(a):
    return ls.Stack(1.0, [ls.Layer(1.5, 10_000.0, coherent=False, alpha=a, name="slab")], ls.Substrate(1.5))


def _film(h, n):
    return ls.Stack(1.0, [ls.Layer(n, h, name="film")], ls.Substrate(1.52))


def _interior():
    y = np.asarray(ls.reflectance(_slab(2e-5), WL, T0))
    return ft.Objective(_slab(5e-6), WL, ft.Dataset(T0, y, sigma=0.002), [ft.alpha("slab")]), {"alpha[slab]": 2e-5}


def _on_bound():
    y = 1.02 * np.asarray(ls.reflectance(_slab(0.0), WL, T0))
    return ft.Objective(_slab(5e-6), WL, ft.Dataset(T0, y, sigma=0.002), [ft.alpha("slab")]), {"alpha[slab]": 0.0}


def _coupled():
    y = np.asarray(ls.reflectance(_film(180.0, 1.85), WL, R0))
    obj = ft.Objective(_film(170.0, 1.8), WL, ft.Dataset(R0, y, sigma=0.001),
                       [ft.thickness("film", lower=100.0, upper=300.0), ft.index_n("film", lower=1.3, upper=2.5)])
    return obj, {"thickness[film]": 180.0, "n[film]": 1.85}


PROBLEMS = {"interior": _interior, "on_bound": _on_bound, "coupled": _coupled}


@pytest.fixture(scope="module", params=sorted(PROBLEMS))
def problem(request):
    return request.param, *PROBLEMS[request.param]()


@pytest.mark.parametrize("method", METHODS)
def test_every_method_finds_the_values_that_made_the_data(problem, method):
    name, obj, truth = problem
    r = ft.fit(obj, method)
    assert r.converged, (method, name, r.reason)
    assert set(truth) == set(r.values), r.values
    for k, v in truth.items():
        got = float(np.ravel(r.values[k])[0])
        if v == 0.0:
            assert got == 0.0, (method, k, got)  # exactly on the bound, named as such
            assert r.at_bound and r.at_bound[0]["parameter"] == k
        else:
            assert got == pytest.approx(v, rel=1e-6), (method, k, got)
    # exact data leave no residual; the bound case keeps the 2 % excess no α >= 0 can explain
    assert (r.reduced_chi2 < 1e-6) if name != "on_bound" else (r.reduced_chi2 > 1.0)
