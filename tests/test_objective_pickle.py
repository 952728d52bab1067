"""An Objective travels to other processes (Dask workers of ``fit_cube``) also after it has been
used here: its compiled solvers stay behind (they cannot be pickled and belong to this process)."""

from __future__ import annotations

import pickle

import numpy as np

import fitting as ft
import layerstack_jax as ls


def test_objective_pickles_after_a_fit_and_fits_the_same_elsewhere():
    wl = np.linspace(400.0, 700.0, 31)
    geometry = ls.Specular(0.0, "T")
    slab = lambda a: ls.Stack(1.0, [ls.Layer(1.5, 1e4, coherent=False, alpha=a, name="slab")], ls.Substrate(1.5))
    data = np.stack([np.asarray(ls.reflectance(slab(a), wl, geometry)) for a in (1e-5, 3e-5)])
    obj = ft.Objective(slab(5e-6), wl, ft.Dataset(geometry, data[0], sigma=0.002), [ft.alpha("slab")])
    here = ft.fit_batch(obj, data, chunk_size=2, progress=False)  # compiles and caches a solver on obj
    assert obj.cache
    copy = pickle.loads(pickle.dumps(obj))  # was: "Can't pickle local object 'compiled_fit.<locals>.run_all'"
    assert copy.cache == {} and obj.cache  # the original keeps its cache
    there = ft.fit_batch(copy, data, chunk_size=2, progress=False)
    np.testing.assert_array_equal(there.x, here.x)
    np.testing.assert_allclose(np.ravel(here.x), [1e-5, 3e-5], rtol=1e-6)
