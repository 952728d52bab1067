"""Batched prediction (:func:`layerstack_jax._instruments.batched.predict`): equal to a Python loop of single
:func:`layerstack_jax.reflectance` calls for every geometry and every kind of batched leaf,
documented shapes, clear errors naming the field, jit/grad, one compilation per structure, and
peak memory that does not grow with the number of spectra (measured in subprocesses)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_jax._instruments.batched import _COMPILED, batch_layout, predict

WL = np.linspace(420.0, 700.0, 6)
N = 2
RNG = np.random.default_rng(7)
H = RNG.uniform(5e3, 3e4, N)  # thick-layer thicknesses, nm
D = RNG.uniform(60.0, 180.0, N)  # film thicknesses, nm
ALPHA = RNG.uniform(5e-6, 4e-5, (N, WL.size))  # 1/nm
RHO = RNG.uniform(0.2, 0.8, (N, WL.size))
N_FILM = RNG.uniform(1.9, 2.3, N)
K_FILM = RNG.uniform(0.0, 0.05, (N, WL.size))
A_CAUCHY = RNG.uniform(1.45, 1.6, N)


def _stack(h=1.2e4, d=100.0, alpha=2e-5, rho=0.6, n_film=2.1, k_film=0.01, a=1.5, background=True):
    """A coherent film on a thick absorbing dispersive layer, over a background or a substrate:
    every kind of leaf the batch can carry (thickness of both kinds, α(λ), ρg(λ), n, k, a
    dispersion coefficient)."""
    layers = [
        ls.Layer(ls.Index(n_film, k_film), d, coherent=True, name="film"),
        ls.Layer(ls.Cauchy(a, 0.004), h, coherent=False, alpha=alpha, name="varnish"),
    ]
    exit_ = ls.LambertianBackground(1.52, rho) if background else ls.Substrate(ls.Index(1.52, 0.0))
    return ls.Stack(1.0, layers, exit_)


def _all_batched(background=True):
    return _stack(h=H[:, None], d=D[:, None], alpha=ALPHA, rho=RHO if background else 0.5, n_film=N_FILM[:, None],
                  k_film=K_FILM, a=A_CAUCHY[:, None], background=background)


def _one(i, background=True):
    return _stack(h=H[i], d=D[i], alpha=ALPHA[i], rho=RHO[i] if background else 0.5, n_film=N_FILM[i],
                  k_film=K_FILM[i], a=A_CAUCHY[i], background=background)


GEOMETRIES = {
    "sphere SCE": ls.Sphere(8.0, "excluded"),
    "sphere SCI": ls.Sphere(20.0, "included"),
    "45/0": ls.Directional(45.0, 0.0),
    "brdf": ls.BRDF(30.0, 10.0),
    "specular R": ls.Specular(30.0, "R"),
    "specular T": ls.Specular(20.0, "T"),
}


@pytest.mark.parametrize("geometry", list(GEOMETRIES))
def test_every_leaf_batched_equals_a_loop(geometry):
    """Thicknesses (film and thick layer), α(λ), ρg(λ), n, k(λ) and a Cauchy coefficient, each
    with its own value per spectrum: row i equals reflectance() of stack i."""
    g = GEOMETRIES[geometry]
    got = predict(_all_batched(), WL, g, chunk=1)
    assert got.shape == (N, WL.size)
    ref = np.stack([np.asarray(ls.reflectance(_one(i), WL, g)) for i in range(N)])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-13)
    assert np.ptp(ref, axis=0).max() > 1e-3  # the samples really differ


@pytest.mark.parametrize("geometry", ["sphere SCE", "45/0"])
def test_thick_leaves_batched_fixed_optics_equals_a_loop(geometry):
    """Only h, α, ρg batched: the Fresnel algebra is computed once for the batch."""
    g = GEOMETRIES[geometry]
    got = predict(_stack(h=H[:, None], alpha=ALPHA, rho=RHO), WL, g, chunk=2)
    ref = np.stack([np.asarray(ls.reflectance(_stack(h=H[i], alpha=ALPHA[i], rho=RHO[i]), WL, g)) for i in range(N)])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-13)


def test_substrate_specular_absorptance():
    g = ls.Specular(40.0, "A")
    got = predict(_all_batched(False), WL, g)
    ref = np.stack([np.asarray(ls.reflectance(_one(i, False), WL, g)) for i in range(N)])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-13)


def test_shapes_two_batch_axes_and_angle_axes():
    hh = H[:, None, None] * np.array([1.0, 1.3, 0.7])[None, :, None]  # (2, 3, 1)
    angles = np.array([0.0, 30.0, 60.0, 75.0])
    got = predict(_stack(h=hh), WL, ls.Specular(angles, "R"), chunk=4)
    assert got.shape == (2, 3, angles.size, WL.size)
    ref = ls.reflectance(_stack(h=float(hh[1, 2, 0])), WL, ls.Specular(angles, "R"))
    np.testing.assert_allclose(got[1, 2], ref, rtol=0, atol=1e-13)
    # leaves with different batch parts broadcast together: (2, 1, 1) x (3, wl)
    rho3 = np.concatenate([RHO, RHO[:1] * 0.5])  # (3, wl)
    got = predict(_stack(h=H[:, None, None], rho=rho3), WL, ls.Sphere(8.0))
    assert got.shape == (2, 3, WL.size)
    ref = ls.reflectance(_stack(h=H[1], rho=rho3[2]), WL, ls.Sphere(8.0))
    np.testing.assert_allclose(got[1, 2], ref, rtol=0, atol=1e-13)


def test_explicit_batch_shape_accepts_one_scalar_per_spectrum():
    got = predict(_stack(h=H), WL, ls.Sphere(8.0), batch_shape=(N,))
    ref = predict(_stack(h=H[:, None]), WL, ls.Sphere(8.0))
    np.testing.assert_array_equal(got, ref)
    # nothing batched but a batch shape asked for: the one spectrum repeated
    one = predict(_stack(), WL, ls.Sphere(8.0), batch_shape=(2,))
    assert one.shape == (2, WL.size)
    np.testing.assert_array_equal(one[0], np.asarray(ls.reflectance(_stack(), WL, ls.Sphere(8.0))))


def test_wrong_length_batch_axis_names_the_field():
    with pytest.raises(ls.LayerstackError, match=r"layers\[1\] \('varnish'\)\.thickness"):
        predict(_stack(h=np.full(N + 1, 1e4)), WL, ls.Sphere(8.0))  # (3,) is neither (1,) nor (wl,)
    with pytest.raises(ls.LayerstackError, match=r"exit\.reflectance.*batch_shape"):
        predict(_stack(rho=RHO), WL, ls.Sphere(8.0), batch_shape=(N + 1,))
    with pytest.raises(ls.LayerstackError, match="do not broadcast together"):
        predict(_stack(h=np.ones((N + 1, 1)) * 1e4, rho=RHO), WL, ls.Sphere(8.0))
    with pytest.raises(ls.LayerstackError, match=r"layers\[1\] \('varnish'\)\.alpha.*ambiguous"):
        predict(_stack(alpha=ALPHA[0]), WL, ls.Sphere(8.0), batch_shape=(WL.size,))
    with pytest.raises(ls.LayerstackError, match="chunk"):
        predict(_stack(h=H[:, None]), WL, ls.Sphere(8.0), chunk=0)


def test_layout_reports_the_batched_fields():
    lay = batch_layout(_stack(h=H[:, None], alpha=ALPHA), WL.size)
    assert lay.batch_shape == (N,)
    batched = {n for n, b in zip(lay.names, lay.batched) if b}
    assert batched == {"layers[1] ('varnish').thickness", "layers[1] ('varnish').alpha"}


def test_one_compilation_per_structure_and_progress():
    calls = []
    st = _stack(h=np.linspace(1e4, 2e4, 10)[:, None])
    predict(st, WL, ls.Sphere(8.0), chunk=2, step=4, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(4, 10), (8, 10), (10, 10)]
    fn = next(reversed(_COMPILED.values()))
    keys, traces = list(_COMPILED), fn._cache_size()
    # other thicknesses, another N: same compiled function, no new trace
    out = predict(_stack(h=np.linspace(2e4, 3e4, 7)[:, None]), WL, ls.Sphere(8.0), chunk=2, step=4)
    assert list(_COMPILED) == keys and next(reversed(_COMPILED.values())) is fn
    assert fn._cache_size() == traces
    assert out.shape == (7, WL.size)


def test_inside_jit_and_grad():
    g45 = ls.Specular(30.0, "R")

    def loss(h):
        return jnp.sum(predict(_stack(h=h[:, None], background=False), WL, g45, chunk=1) ** 2)

    h = jnp.asarray(H) * 0.01  # thin enough that R depends on h
    g = jax.jit(jax.grad(loss))(h)

    def single(hi):
        return jnp.sum(ls.reflectance(_stack(h=hi, background=False), WL, g45) ** 2)

    ref = np.array([jax.grad(single)(hi) for hi in h])
    np.testing.assert_allclose(np.asarray(g), ref, rtol=1e-10, atol=0)
    fd = (loss(h.at[0].add(0.5)) - loss(h.at[0].add(-0.5)))  # central difference, 1 nm step
    np.testing.assert_allclose(float(g[0]), float(fd), rtol=1e-5)
    assert abs(float(g[0])) > 0


def test_out_array_is_filled(tmp_path):
    out = np.lib.format.open_memmap(tmp_path / "r.npy", mode="w+", dtype=float, shape=(N, WL.size))
    got = predict(_stack(h=H[:, None]), WL, ls.Sphere(8.0), out=out)
    assert got is out
    np.testing.assert_array_equal(np.load(tmp_path / "r.npy"), predict(_stack(h=H[:, None]), WL, ls.Sphere(8.0)))


_MEMORY_CHILD = textwrap.dedent("""
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import layerstack_jax as ls
    from layerstack_jax._instruments.batched import predict

    n = int(sys.argv[1])
    wl = np.linspace(400.0, 700.0, 31)
    h = np.random.default_rng(0).uniform(2e3, 3e4, (n, 1))
    st = ls.Stack(1.0, [ls.Layer(1.5, h, coherent=False, alpha=2e-5)], ls.LambertianBackground(1.52, 0.5))
    out = predict(st, wl, ls.Sphere(8.0), chunk=4, step=256)
    with open("/proc/self/status") as f:
        peak = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))
    print(json.dumps({"peak": peak, "out": out.nbytes, "finite": bool(np.isfinite(out).all())}))
""")


def _peak(n: int) -> dict:
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=1", JAX_PLATFORMS="cpu")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    r = subprocess.run([sys.executable, "-c", _MEMORY_CHILD, str(n)], capture_output=True, text=True, env=env,
                       cwd=root, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_peak_memory_does_not_grow_with_n():
    small, large = _peak(512), _peak(16_384)
    assert small["finite"] and large["finite"]
    # all 16k spectra vmapped at once would hold ~0.1 MB per spectrum of intermediates (> 1.6 GB);
    # in chunks the peak grows by the output array only (+ allocator noise)
    growth = large["peak"] - small["peak"] - (large["out"] - small["out"])
    assert growth < 40 * 2**20, (small, large)


def test_dask_leaves_give_a_lazy_dask_array_equal_to_the_numpy_path():
    da = pytest.importorskip("dask.array")
    import dask

    hh = np.linspace(1e4, 3e4, 10)[:, None]
    lazy = predict(_stack(h=da.from_array(hh, chunks=(4, 1)), alpha=ALPHA[:1]), WL, ls.Sphere(8.0), chunk=2)
    assert isinstance(lazy, da.Array) and lazy.shape == (10, WL.size) and lazy.chunks[0] == (4, 4, 2)
    with dask.config.set(scheduler="threads"):
        got = lazy.compute()
    # each Dask block runs the program for its own number of rows (4, 4, 2), which XLA may fuse
    # otherwise than the one for all 10: equal to the last bit or two
    np.testing.assert_allclose(got, predict(_stack(h=hh, alpha=ALPHA[:1]), WL, ls.Sphere(8.0), chunk=2),
                               rtol=1e-15, atol=0)


@pytest.mark.slow
def test_dask_prediction_on_a_local_cluster_of_two_processes():
    da = pytest.importorskip("dask.array")
    distributed = pytest.importorskip("distributed")
    hh = np.linspace(1e4, 3e4, 10)[:, None]
    lazy = predict(_stack(h=da.from_array(hh, chunks=(5, 1))), WL, ls.Sphere(8.0), chunk=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        got = client.compute(lazy).result()
    np.testing.assert_allclose(got, predict(_stack(h=hh), WL, ls.Sphere(8.0), chunk=2), rtol=1e-15, atol=0)
