"""The ``[instrument]`` table of stack files (issue 15: "stack files declare any model coefficient
free with bounds — … non-ideality parameters — in the same inline-table syntax as thickness").

The fitted angle offset of the command-line test is checked against the offset that made the
data (the forward model at 70.3° read as 70°), not against the code's own output.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_jax import LayerstackError
import fitting as ft
from layerstack_jax.io import instrument_geometry, load_instrument, load_stack

ROOT = Path(__file__).resolve().parents[1]

FILM_ON_SI = """
[[layers]]
name = "film"
n = {{ cauchy = [1.46, 0.0035] }}
thickness_nm = {{ value = {start}, free = true, min = 10, max = 300 }}
coherent = true

[substrate]
n = 3.87
k = 0.02

[instrument]
{instrument}
"""


def _write(tmp_path, instrument: str, start: float = 100.0) -> Path:
    path = tmp_path / "model.toml"
    path.write_text(FILM_ON_SI.format(start=start, instrument=instrument))
    return path


def test_instrument_table_is_read_declared_and_applied(tmp_path):
    path = _write(tmp_path, 'angle_offset_deg = { value = 0.1, free = true, min = -1, max = 1 }\n'
                            'bandwidth_nm = 2.5\nthickness_spread = 0.02\nnonuniform_layer = "film"')
    stack, free = ft.load_fit_parameters(path)
    assert [p.path for p in free] == [("layers", "film", "thickness"), ("datasets", "all", "angle_offset_deg")]
    offset = free[1]
    assert (offset.name, offset.kind, offset.lower, offset.upper) == ("angle_offset_deg", "other", -1.0, 1.0)
    settings = load_instrument(path)
    assert settings.values == {"angle_offset_deg": 0.1, "bandwidth_nm": 2.5, "thickness_spread": 0.02}
    assert settings.static == {"nonuniform_layer": "film"}
    g = instrument_geometry(ls.Ellipsometric(70.0, "psi"), settings)
    assert (float(g.angle_offset_deg), float(g.bandwidth_nm), float(g.thickness_spread), g.nonuniform_layer) == (
        0.1, 2.5, 0.02, "film")
    assert float(g.angle_deg) == 70.0 and g.quantity == "psi"
    # the stack itself is the same with or without the table (load_stack accepts and checks it)
    assert load_stack(path).layers[0].name == "film"
    # no table: geometries unchanged (the same object)
    plain = tmp_path / "plain.toml"
    plain.write_text(FILM_ON_SI.format(start=100.0, instrument="").replace("[instrument]\n", ""))
    e = ls.Ellipsometric(70.0, "psi")
    assert instrument_geometry(e, load_instrument(plain)) is e


@pytest.mark.parametrize("line, words, fit_only", [
    ('bandwidth_nm = "wide"', ["[instrument]", "bandwidth_nm", "must be a number"], False),
    ('angle_offset_deg = { free = true }', ["[instrument]", "angle_offset_deg", "value"], False),
    ('angle_offset_deg = { value = 0.0, min = -1 }', ["[instrument]", "angle_offset_deg", "free is not true"], True),
    ('angle_offset_deg = { value = 0.0, free = true, min = 1, max = -1 }',
     ["[instrument]", "angle_offset_deg", "inverted"], True),
    ('nonuniform_layer = "varnish"', ["nonuniform_layer", "no layer named 'varnish'"], False),
    ('nonuniform_layer = 3', ["nonuniform_layer", "no layer 3"], False),
    ('nonuniform_layer = true', ["nonuniform_layer", "name or 0-based position"], False),
    ('angle_offset_deg = { offset = 1 }', ["angle_offset_deg", "a number or"], False),
])
def test_bad_instrument_tables_name_the_file_table_and_key(tmp_path, line, words, fit_only):
    """Every loader refuses what the file's grammar forbids; the fitting words (``min``, ``free``
    …) are checked where they are read, by the fit's loader (a prediction skips them)."""
    path = _write(tmp_path, line)
    if fit_only:
        assert load_instrument(path).values == {"angle_offset_deg": 0.0}
    for load in (ft.load_fit_parameters,) if fit_only else (load_stack, ft.load_fit_parameters, load_instrument):
        with pytest.raises(LayerstackError) as e:
            load(path)
        assert str(path) in str(e.value)
        for w in words:
            assert w in str(e.value), (w, str(e.value))


def test_a_key_the_geometry_lacks_is_refused_naming_it_and_the_geometry(tmp_path):
    settings = load_instrument(_write(tmp_path, "bandwidth_nm = 2.0"))
    with pytest.raises(LayerstackError, match=r"\[instrument\]: bandwidth_nm: not a field of the geometry 'sphere:8:sce'"):
        instrument_geometry(ls.Sphere(8.0), settings)


def test_cli_fit_recovers_a_declared_angle_offset(tmp_path):
    """``layerstack fit MODEL.toml FILE`` with ``angle_offset_deg`` free in ``[instrument]``: ψ/Δ
    at 65/70/75° made at the true angles + 0.3° (and 123.4 nm) fit back to both values."""
    from layerstack_jax._files.measurement import measurement_from_points
    from layerstack_jax._files.readers import write_measurement_csv

    wl = np.linspace(400.0, 800.0, 41)
    stack = ls.Stack(1.0, [ls.Layer(ls.Cauchy(1.46, 0.0035), 123.4, name="film")], ls.Substrate(ls.Index(3.87, 0.02)))
    angles = np.array([65.0, 70.0, 75.0])
    e = ls.ellipsometry(stack, wl, angles[:, None] + 0.3)  # (3, 41): the instrument's true angles
    A, W = np.meshgrid(angles, wl, indexing="ij")
    m = measurement_from_points("psi_delta", A.ravel(), W.ravel(),
                                {"psi": np.asarray(e.psi_deg).ravel(), "delta": np.asarray(e.delta_deg).ravel()},
                                sigma={"psi": np.full(A.size, 0.01), "delta": np.full(A.size, 0.02)})
    data = write_measurement_csv(tmp_path / "film.csv", m)
    model = _write(tmp_path, 'angle_offset_deg = { value = 0.0, free = true, min = -2, max = 2 }', start=110.0)
    out = tmp_path / "fit.json"
    run = subprocess.run([sys.executable, "-m", "layerstack_cli", "fit", str(model), str(data), "-o", str(out)],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    fit = json.loads(out.read_text())["fits"][0]
    values = {name: np.ravel(p["value"])[0] for name, p in fit["parameters"].items()}
    # one offset shared by the 9 datasets (3 angles x N, C, S: the default residuals of a psi/Delta file)
    assert fit["parameters"]["angle_offset_deg"]["path"] == ["datasets", str(tuple(range(9))), "angle_offset_deg"]
    assert values["angle_offset_deg"] == pytest.approx(0.3, abs=1e-6)
    assert values["thickness_nm[film]"] == pytest.approx(123.4, rel=1e-7)
    assert "angle_offset_deg" in run.stdout


SLIDE = """
[[layers]]
name = "glass"
n = 1.5
thickness_nm = 1e6
coherent = false

[substrate]
n = 1.0

[instrument]
{instrument}
"""


def _predict(tmp_path, instrument: str, *extra):
    from layerstack_cli import main

    model = tmp_path / "slide.toml"
    model.write_text(SLIDE.format(instrument=instrument))
    out = tmp_path / "slide.csv"
    code = main(["predict", str(model), "-w", "400:700:100", "-g", "specular:60", "--ellipsometry", "60", "-o", str(out),
                 *extra])
    return code, out


def test_cli_predict_reads_a_glass_slide_as_the_ellipsometer_does(tmp_path, capsys):
    """``predict --ellipsometry`` of a thick slide (a thick incoherent layer: the backside's beams
    add incoherently) writes ψ, Δ and the depolarization, equal to the Ellipsometric reading with
    the table's bandwidth; a key no geometry has is refused naming it."""
    from layerstack_jax.io import read_spectra_csv

    code, out = _predict(tmp_path, "bandwidth_nm = 3.0")
    assert code == 0
    wl, cols = read_spectra_csv(out)
    stack = ls.Stack(1.0, [ls.Layer(1.5, 1e6, coherent=False, name="glass")], ls.Substrate(1.0))
    e = ls.Ellipsometric(60.0, "psi", bandwidth_nm=3.0).reading(stack, wl)
    np.testing.assert_allclose(cols["psi_60"], e.psi_deg, rtol=1e-9)
    np.testing.assert_allclose(cols["delta_60"], e.delta_deg, atol=1e-9)
    np.testing.assert_allclose(cols["depolarization_60"], e.depolarization, atol=1e-12)
    assert np.all((cols["depolarization_60"] > 1e-4) & (cols["depolarization_60"] < 1.0))  # the backside depolarizes (5e-4)
    code, _ = _predict(tmp_path, "port_half_angle_deg = 5.0")
    assert code == 2
    assert "port_half_angle_deg: not a field of any geometry asked for" in capsys.readouterr().err
