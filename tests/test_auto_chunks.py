"""``chunk="auto"``: sizes chosen from the memory available where the work runs.

:func:`layerstack_jax.predict` sizes its vmapped block and :func:`fitting.fit_cube` its regions
from a memory budget (:func:`layerstack_jax._base.memory.memory_budget`: a Dask worker's memory
limit, else this process's available memory) and the memory measured on the compiled program.
Checked here: "auto" resolves to concrete sizes that shrink with the budget and give the same
numbers as those sizes given explicitly; a budget too small for one block is a LayerstackError
naming ``chunk``; a resumed store keeps its own regions whatever the budget of the run resuming
it; the command line accepts ``auto`` and numbers; inside a LocalCluster worker the worker's
``memory_limit`` is the budget (slow: starts worker processes).
"""

from __future__ import annotations

import json
import logging
import re

import numpy as np
import pytest

import fitting
import layerstack_jax as ls
from layerstack_jax._instruments import batched as _batched
from layerstack_jax._base.memory import MemoryBudget, memory_budget
from layerstack_jax._instruments.batched import predict

WL = np.linspace(400.0, 700.0, 31)
GEOMETRY = ls.Specular(8.0, "R")


def _film(d, n=2.0):
    return ls.Stack(1.0, [ls.Layer(ls.Index(n), d, coherent=True, name="film")], ls.Substrate(1.52))


def _auto_line(caplog) -> dict:
    """The last ``predict: chunk auto -> ...`` record: chunk, step, measured bytes."""
    text = [r.getMessage() for r in caplog.records if "chunk auto ->" in r.getMessage()][-1]
    m = re.search(r"-> (\d+) spectra per block, step (\d+) \(measured ([\d.e+-]+) MB working memory per "
                  r"spectrum, ([\d.e+-]+) MB per call", text)
    return {"chunk": int(m[1]), "step": int(m[2]), "per_spectrum": float(m[3]) * 1e6, "io": float(m[4]) * 1e6,
            "text": text}


# ----------------------------------------------------------------------------- the budget
def test_memory_budget_is_half_of_this_process_available_memory():
    b = memory_budget()
    assert b.bytes > 0 and b.fraction == 0.5 and b.bytes == int(b.available * 0.5)
    assert "memory" in b.source and "MB" in b.describe()
    assert memory_budget(0.25).bytes <= b.bytes
    with pytest.raises(ls.LayerstackError, match="fraction"):
        memory_budget(0.0)


# ----------------------------------------------------------------------------- predict
H = np.linspace(100.0, 200.0, 13)[:, None]


def test_predict_auto_shrinks_with_the_budget_and_equals_explicit_chunks(caplog):
    caplog.set_level(logging.INFO, logger="layerstack_jax.batched")
    big = predict(_film(H), WL, GEOMETRY, memory=10**12)  # the default is "auto"
    first = _auto_line(caplog)
    assert first["chunk"] == _batched._auto_chunk_max() and "budget" in first["text"]
    np.testing.assert_array_equal(big, predict(_film(H), WL, GEOMETRY, chunk=first["chunk"]))
    # a budget for 3 spectra of working memory besides one call's input and output
    small_budget = int(first["io"] + 3.5 * first["per_spectrum"])
    small = predict(_film(H), WL, GEOMETRY, memory=small_budget)
    second = _auto_line(caplog)
    assert second["chunk"] == 3 < first["chunk"]
    np.testing.assert_array_equal(small, predict(_film(H), WL, GEOMETRY, chunk=3))
    np.testing.assert_allclose(small, big, rtol=1e-12, atol=0)
    # no budget at all for one spectrum: an error naming the field
    with pytest.raises(ls.LayerstackError, match=r"predict: chunk: the memory budget .* cannot hold one block of 1 "
                                                 r"spectrum: .* MB of working memory per spectrum"):
        predict(_film(H), WL, GEOMETRY, memory=int(first["io"] + 0.5 * first["per_spectrum"]))
    with pytest.raises(ls.LayerstackError, match="chunk must be an integer >= 1 or 'auto'"):
        predict(_film(H), WL, GEOMETRY, chunk="big")


def test_predict_auto_takes_the_default_budget_from_memory_budget(monkeypatch, caplog):
    caplog.set_level(logging.INFO, logger="layerstack_jax.batched")
    monkeypatch.setattr(_batched, "memory_budget", lambda *a, **k: MemoryBudget(10**3, 2 * 10**3, 0.5, "patched"))
    with pytest.raises(ls.LayerstackError, match=r"chunk: the memory budget 0\.001 MB \(0\.5 of 0\.002 MB, patched\)"):
        predict(_film(H), WL, GEOMETRY)


# ----------------------------------------------------------------------------- fit_cube
pytest.importorskip("xarray")
pytest.importorskip("zarr")
pytest.importorskip("dask")

from fitting._cube import fit_cube  # noqa: E402
from fitting._cube_regions import AUTO_REGION_MAX, _solver_memory, auto_region  # noqa: E402

NY, NX = 6, 5


def _cube():
    rng = np.random.default_rng(5)
    d = rng.uniform(110.0, 190.0, (NY, NX))
    return predict(_film(d[..., None]), WL, GEOMETRY, chunk=4) + rng.normal(0.0, 1e-3, (NY, NX, WL.size))


CUBE = _cube()
PARAMS = [fitting.thickness("film", value=150.0, lower=60.0, upper=260.0)]
OBJECTIVE = fitting.Objective(_film(150.0), WL, fitting.Dataset(GEOMETRY, CUBE[0, 0], sigma=1e-3), PARAMS)
CHUNK_SIZE = 4


@pytest.fixture(scope="module")
def sizes():
    """Measured bytes of the test objective's solver (one compile) and of a pixel."""
    _, s = auto_region(OBJECTIVE, (NY, NX), WL.size, 8, chunk_size=CHUNK_SIZE,
                       budget=MemoryBudget(10**12, 10**12, 1.0, "test"))
    return s


def _budget(sizes, pixels) -> int:
    """A budget for the solver and ``pixels`` pixels (and a little)."""
    return int(sizes["solver_bytes"] + (pixels + 0.5) * sizes["per_pixel_bytes"])


def test_auto_region_shrinks_with_the_budget(sizes):
    big, _ = auto_region(OBJECTIVE, (1000, 1000), WL.size, 8, chunk_size=CHUNK_SIZE,
                         budget=MemoryBudget(10**12, 10**12, 1.0, "test"))
    assert big == AUTO_REGION_MAX  # capped: cheap to resume
    mid, s = auto_region(OBJECTIVE, (1000, 1000), WL.size, 8, chunk_size=CHUNK_SIZE,
                         budget=MemoryBudget(_budget(sizes, 1000), 1, 1.0, "test"))
    assert s["memory_fit_pixels"] == 1000 and mid == (28, 35)  # 980 pixels: no padded solver call
    small, _ = auto_region(OBJECTIVE, (1000, 1000), WL.size, 8, chunk_size=CHUNK_SIZE,
                           budget=MemoryBudget(_budget(sizes, 40), 1, 1.0, "test"))
    assert small == (5, 8)
    # enough regions to feed every worker thread: 4 per thread
    fed, _ = auto_region(OBJECTIVE, (40, 40), WL.size, 8, chunk_size=CHUNK_SIZE,
                         budget=MemoryBudget(10**12, 10**12, 1.0, "test"), slots=4)
    assert fed == (10, 10)
    # the per-pixel formula: the block as read and its copies, the fits' host arrays, the maps
    temp, args, outs = _solver_memory(OBJECTIVE, "lm", CHUNK_SIZE, WL.size, ())
    assert sizes["solver_bytes"] == temp + args + outs > 0
    assert sizes["per_pixel_bytes"] > WL.size * (8 + 16)


def test_tiny_budget_names_the_chunk(sizes, tmp_path):
    with pytest.raises(ls.LayerstackError, match=r"fit_cube: chunk: the worker memory .* cannot hold one region of "
                                                 r"chunk_size=4 pixels, .* MB \(the compiled solver"):
        fit_cube(OBJECTIVE, CUBE, wavelength_nm=WL, out=tmp_path / "m.zarr", chunk_size=CHUNK_SIZE, progress=False,
                 memory=_budget(sizes, 2))
    assert not (tmp_path / "m.zarr").exists()


def test_auto_regions_of_a_host_method_are_refused_before_anything_is_written(tmp_path):
    with pytest.raises(ls.LayerstackError, match="fit_cube: method 'trf' runs on the host one fit at a time"):
        fit_cube(OBJECTIVE, CUBE, wavelength_nm=WL, out=tmp_path / "m.zarr", chunk_size=CHUNK_SIZE, progress=False,
                 method="trf")
    assert not (tmp_path / "m.zarr").exists()


def test_fit_cube_auto_equals_explicit_sizes_and_resumes_with_the_stored_ones(sizes, tmp_path, caplog):
    caplog.set_level(logging.INFO, logger="fitting.cube")
    auto = fit_cube(OBJECTIVE, CUBE, wavelength_nm=WL, out=tmp_path / "auto.zarr", chunk_size=CHUNK_SIZE,
                    progress=False, memory=_budget(sizes, 5)).load()
    chunk = tuple(json.loads(auto.attrs["chunk"]))
    assert chunk == (2, 2) and auto.attrs["chunk_size"] == CHUNK_SIZE  # 5 pixels fit: 2 x 2
    sizing = json.loads(auto.attrs["chunk_sizing"])
    assert sizing["memory_fit_pixels"] == 5 and sizing["budget_source"].endswith("(given (memory=))")
    assert any("chunk auto -> regions of 2 x 2 pixels" in r.getMessage() and "budget" in r.getMessage()
               for r in caplog.records)
    given = fit_cube(OBJECTIVE, CUBE, wavelength_nm=WL, out=tmp_path / "given.zarr", chunk_size=CHUNK_SIZE,
                     progress=False, chunk=chunk).load()
    assert json.loads(given.attrs["chunk_sizing"]) == "given"
    assert given.attrs["fit_cube_job"] == auto.attrs["fit_cube_job"]  # the job is the resolved sizes
    for name in auto.data_vars:
        np.testing.assert_array_equal(auto[name].values, given[name].values, err_msg=name)
    assert np.all(auto["converged"].values == 1)
    # an interrupted run: two regions not written; resumed with "auto" on a machine whose memory
    # would choose other regions (a large budget: 4 x 2), it keeps the store's 2 x 2 regions
    markers = tmp_path / "auto.zarr.regions"
    for name in ("0_1", "2_2"):
        (markers / name).unlink()
    caplog.clear()
    resumed = fit_cube(OBJECTIVE, CUBE, wavelength_nm=WL, out=tmp_path / "auto.zarr", chunk_size=CHUNK_SIZE,
                       progress=False, memory=10**12).load()
    messages = [r.getMessage() for r in caplog.records]
    assert any("the store's regions of 2 x 2 pixels" in m for m in messages)
    assert any("resuming" in m and "7 of 9 regions already written" in m for m in messages)
    assert sum("fit_cube: region" in m for m in messages) == 2
    for name in auto.data_vars:
        np.testing.assert_array_equal(resumed[name].values, auto[name].values, err_msg=name)
    # the same large budget on a new store does choose other regions
    fresh = fit_cube(OBJECTIVE, CUBE, wavelength_nm=WL, out=tmp_path / "fresh.zarr", chunk_size=CHUNK_SIZE,
                     progress=False, memory=10**12)
    assert tuple(json.loads(fresh.attrs["chunk"])) == (4, 2)  # 4 regions per thread, >= chunk_size pixels
    with pytest.raises(ls.LayerstackError, match="chunk must be"):
        fit_cube(OBJECTIVE, CUBE, wavelength_nm=WL, out=tmp_path / "x.zarr", chunk="large", progress=False)


# ----------------------------------------------------------------------------- command line
def test_cli_accepts_auto_and_numbers(tmp_path, capsys):
    from layerstack_cli import main

    (tmp_path / "s.toml").write_text('[[layers]]\nname = "film"\nn = 2.0\nthickness_nm = 150\ncoherent = true\n\n'
                                     '[substrate]\nn = 1.52\n')
    outs = {}
    for chunk in ("auto", "2"):
        out = tmp_path / f"p_{chunk}.csv"
        rc = main(["predict", str(tmp_path / "s.toml"), "-g", "specular:8:R", "-w", "400:700:10", "-o", str(out),
                   "--vary", "film.thickness_nm=100:200:10", "--chunk", chunk])
        assert rc == 0
        outs[chunk] = out.read_text()
    assert outs["auto"] == outs["2"]
    assert main(["predict", str(tmp_path / "s.toml"), "-g", "specular:8:R", "-o", str(tmp_path / "x.csv"),
                 "--chunk", "0"]) == 2
    assert "expected 'auto' or a positive integer" in capsys.readouterr().err


def test_cli_fit_cube_auto_regions_and_resume(tmp_path, capsys):
    from layerstack_cli import main

    (tmp_path / "m.toml").write_text('[[layers]]\nname = "film"\nn = 2.0\ncoherent = true\n'
                                     'thickness_nm = { value = 150, free = true, min = 60, max = 260 }\n\n'
                                     '[substrate]\nn = 1.52\n')
    np.save(tmp_path / "cube.npy", CUBE)
    argv = ["fit-cube", str(tmp_path / "m.toml"), str(tmp_path / "cube.npy"), "-w", "400:700:10", "-g", "specular:8:R",
            "-o", str(tmp_path / "maps.zarr"), "--batch", "4", "--sigma", "1e-3", "--quiet", "--no-quicklook"]
    assert main(argv) == 0  # --chunk auto is the default
    out = capsys.readouterr().out
    assert re.search(r"regions of 4 x 2 pixels, 4 pixels per solver call \(auto: budget [\d.e+]+ MB \(0\.5 of", out)
    assert main(argv + ["--chunk", "auto"]) == 0
    assert "resuming: 6 of 6 chunks already written (30 of 30 pixels)" in capsys.readouterr().out


# ----------------------------------------------------------------------------- a Dask worker
@pytest.mark.slow
def test_the_budget_inside_a_local_cluster_worker_is_its_memory_limit(tmp_path):
    distributed = pytest.importorskip("distributed")
    from fitting._cube_regions import _budget_and_slots

    limit = 1 << 30
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, memory_limit=limit,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        remote = client.submit(memory_budget, pure=False).result()
        assert remote.available == limit and remote.bytes == limit // 2
        assert "Dask worker" in remote.source and "memory_limit" in remote.source
        here, slots = _budget_and_slots(client, None)  # what fit_cube sees from the client
        assert here.available == limit and here.bytes == limit // 2 and slots == 1
        assert "Dask worker memory_limit" in here.source
        # fit_cube sizes its regions from it, and predict's blocks resolve "auto" on the worker
        maps = fit_cube(OBJECTIVE, CUBE, wavelength_nm=WL, out=tmp_path / "maps.zarr", chunk_size=CHUNK_SIZE,
                        progress=False, client=client)
        sizing = json.loads(maps.attrs["chunk_sizing"])
        assert sizing["budget_bytes"] == limit // 2 and "Dask worker memory_limit" in sizing["budget_source"]
        local = fit_cube(OBJECTIVE, CUBE, wavelength_nm=WL, out=tmp_path / "local.zarr", chunk_size=CHUNK_SIZE,
                         progress=False, chunk=tuple(json.loads(maps.attrs["chunk"])))
        for name in maps.data_vars:
            np.testing.assert_array_equal(maps[name].values, local[name].values, err_msg=name)
        import dask.array as da

        lazy = predict(_film(da.from_array(H, chunks=(5, 1))), WL, GEOMETRY)
        np.testing.assert_array_equal(lazy.compute(), predict(_film(H), WL, GEOMETRY))
