"""Each command reads its stack file once (issue 30): the stack, its free parameters and its
[instrument] come from one parse (``fitting.load_fit_file``; ``layerstack predict`` reads the
table once and builds both from it). Counted at the TOML parser, in-process runs of the CLI."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_cli import main
from layerstack_jax.io import save_spectra_csv

WL = np.arange(400.0, 701.0, 20.0)

STACK = """
[[layers]]
name = "slab"
n = 1.5
thickness_nm = { value = 8000, free = true, min = 0, max = 1e5 }
coherent = false
alpha_per_nm = 2e-5

[substrate]
n = 1.5
"""


@pytest.fixture
def reads(monkeypatch):
    """Paths parsed by the TOML reader while the test runs."""
    seen: list = []
    load = tomllib.load

    def counting(f, *args, **kwargs):
        seen.append(getattr(f, "name", None))
        return load(f, *args, **kwargs)

    monkeypatch.setattr(tomllib, "load", counting)
    return seen


def _files(tmp_path):
    stack = tmp_path / "s.toml"
    stack.write_text(STACK)
    truth = ls.Stack(1.0, [ls.Layer(1.5, 1e4, coherent=False, alpha=2e-5, name="slab")], ls.Substrate(1.5))
    data = tmp_path / "d.csv"
    save_spectra_csv(data, WL, {"a": np.asarray(ls.reflectance(truth, WL, ls.Specular(0.0, "T")))})
    return stack, data


def test_fit_reads_the_stack_file_once(tmp_path, reads, capsys):
    stack, data = _files(tmp_path)
    assert main(["fit", str(stack), str(data), "-g", "specular:0:T", "-o", str(tmp_path / "r.json")]) == 0, \
        capsys.readouterr()
    assert reads.count(str(stack)) == 1, reads


def test_predict_reads_the_stack_file_once(tmp_path, reads, capsys):
    stack, _ = _files(tmp_path)
    assert main(["predict", str(stack), "-g", "specular:0:T", "-w", "400:700:20", "-o", str(tmp_path / "p.csv")]) == 0, \
        capsys.readouterr()
    assert reads.count(str(stack)) == 1, reads


def test_load_fit_file_gives_stack_parameters_and_instrument_from_one_read(tmp_path, reads):
    import fitting

    stack, _ = _files(tmp_path)
    f = fitting.load_fit_file(stack)
    assert reads.count(str(stack)) == 1
    assert [p.name for p in f.parameters] == ["thickness_nm[slab]"] and f.stack.layers[0].name == "slab"
    assert f.instrument == ls.io.load_instrument(stack)  # the same settings as read on their own


def test_fit_cube_reads_the_stack_file_once(tmp_path, reads, capsys):
    pytest.importorskip("zarr")
    pytest.importorskip("dask")
    stack, _ = _files(tmp_path)
    h = np.array([[9e3, 1e4], [1.1e4, 1.2e4]])
    layer = ls.Layer(1.5, h[..., None], coherent=False, alpha=2e-5, name="slab")
    cube = np.asarray(ls.predict(ls.Stack(1.0, [layer], ls.Substrate(1.5)), WL, ls.Specular(0.0, "T")))
    np.save(tmp_path / "cube.npy", cube)
    argv = ["fit-cube", str(stack), str(tmp_path / "cube.npy"), "-g", "specular:0:T", "-o", str(tmp_path / "m.zarr"),
            "--sigma", "1e-3", "--quiet"]
    code = main(argv + ["-w", "400:700:20"])
    assert code == 0, capsys.readouterr()
    assert reads.count(str(stack)) == 1, reads
