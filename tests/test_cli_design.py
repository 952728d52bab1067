"""`layerstack design DESIGN.toml -o design.toml [--plot design.png]` (fitting/_design_file.py).

References independent of the code under test: the quarter-wave closed forms (Macleod, *Thin-Film
Optical Filters*, ch. 4), ``tmm.coh_tmm`` on the stack files the command writes, and
colour-science for CIELAB / ΔE2000. Each case runs the command once (one L-BFGS-B compilation,
the needle case three): these tests are slow mostly by XLA compile time.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import tmm

import layerstack_jax as ls
from layerstack_cli import main
from layerstack_jax.io import load_stack

INF = np.inf
LAM0, NS = 550.0, 1.52

QUARTER_WAVE = """
description = "single-layer MgF2 antireflection coating on glass"

[[layers]]
name = "MgF2"
n = { material = "MgF2", source = "Li-o" }
thickness_nm = { value = 80, free = true, min = 0, max = 200 }
coherent = true

[substrate]
n = 1.52

[[targets]]
name = "AR at 550 nm"
quantity = "R"
wavelength_nm = 550
value = 0.0
tolerance = 0.02
"""


def _tmm_R(stack, wl, angle_deg=0.0):
    """Natural-light specular reflectance of a loaded stack (ambient n = 1) with tmm.coh_tmm."""
    def index(material, lam):
        return complex(np.broadcast_to(np.asarray(material(np.array([lam]))), (1,))[0])

    out = []
    for lam in np.atleast_1d(wl):
        n = [1.0] + [index(layer.index, lam) for layer in stack.layers] + [index(stack.exit.index, lam)]
        d = [INF] + [float(layer.thickness) for layer in stack.layers] + [INF]
        th = np.deg2rad(angle_deg)
        out.append(0.5 * sum(tmm.coh_tmm(p, n, d, th, lam)["R"] for p in "sp"))
    return np.asarray(out)


def _report_number(text: str, pattern: str) -> float:
    m = re.search(pattern, text)
    assert m, f"{pattern!r} not in\n{text}"
    return float(m.group(1))


def _run(tmp_path, capsys, design: str, *extra):
    src = tmp_path / "design_in.toml"
    src.write_text(design)
    out = tmp_path / "out" / "design.toml"
    code = main(["design", str(src), "-o", str(out), *extra])
    captured = capsys.readouterr()
    return code, captured.out, captured.err, out


def test_quarter_wave_ar(tmp_path, capsys):
    """d = λ0/(4 n1) within 0.1 nm; reported R = ((n0 n_s − n1²)/(n0 n_s + n1²))²; the written
    stack file gives the reported R and merit again (tmm) and works with `layerstack predict`;
    --plot writes a PNG."""
    png = tmp_path / "design.png"
    code, text, err, out = _run(tmp_path, capsys, QUARTER_WAVE, "--plot", str(png))
    assert code == 0, text + err
    n1 = float(np.real(ls.material("MgF2", "Li-o")(np.array([LAM0]))[0]))
    R_closed = ((NS - n1**2) / (NS + n1**2)) ** 2

    stack = load_stack(out)
    (layer,) = stack.layers
    assert layer.name == "MgF2" and layer.coherent
    assert abs(float(layer.thickness) - LAM0 / (4 * n1)) < 0.1
    R_reported = _report_number(text, r"R = ([0-9.eE+-]+);")
    assert R_reported == pytest.approx(R_closed, rel=5e-6)  # printed to 6 significant digits
    R_file = float(_tmm_R(stack, LAM0)[0])
    assert abs(R_file - R_closed) < 1e-9
    merit_reported = _report_number(text, r"-> ([0-9.eE+-]+) \(design\)")
    assert merit_reported == pytest.approx((R_file / 0.02) ** 2, rel=1e-5)
    start = ls.Stack(1.0, [ls.Layer(ls.material("MgF2", "Li-o"), 80.0)], ls.Substrate(NS))
    assert _report_number(text, r"merit: ([0-9.eE+-]+) \(start\)") == pytest.approx(
        (float(_tmm_R(start, LAM0)[0]) / 0.02) ** 2, rel=1e-5)

    header = [line[2:] for line in out.read_text().splitlines() if line.startswith("# ")]
    assert any("result: all targets met" in line for line in header)
    assert any(line.startswith("merit:") for line in header)
    assert 'n = { material = "MgF2", source = "Li-o" }' in out.read_text()  # the database reference kept

    csv = tmp_path / "R.csv"
    assert main(["predict", str(out), "-w", "550", "-g", "specular:0:R", "-o", str(csv)]) == 0
    R_predict = float(csv.read_text().splitlines()[1].split(",")[1])
    assert abs(R_predict - R_closed) < 1e-9
    assert png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


COLOUR = """
[[layers]]
name = "film"
n = 2.0
thickness_nm = {{ value = {start}, free = true, min = 120, max = 240 }}
coherent = true

[substrate]
n = 4.0
k = 0.05

[[targets]]
type = "colour"
name = "interference colour"
lab = [{L:.6f}, {a:.6f}, {b:.6f}]
illuminant = "D65"
observer = "2"
tolerance = 0.5
"""


def test_colour_target_reached(tmp_path, capsys):
    """A film colour (computed with tmm + colour-science at 180 nm) is reached from 165 nm within
    ΔE2000 < 0.5 — checked on the written file with tmm + colour-science."""
    colour = pytest.importorskip("colour")
    wl = np.arange(380.0, 781.0, 5.0)
    d65 = colour.SDS_ILLUMINANTS["D65"]
    white = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(wl, np.ones_like(wl)))), illuminant=d65,
                             method="Integration")

    def lab(stack):
        sd = colour.SpectralDistribution(dict(zip(wl, _tmm_R(stack, wl))))
        XYZ = colour.sd_to_XYZ(sd, illuminant=d65, method="Integration") / 100
        return colour.XYZ_to_Lab(XYZ, colour.XYZ_to_xy(white / 100))

    truth = ls.Stack(1.0, [ls.Layer(2.0, 180.0)], ls.Substrate(ls.Index(4.0, 0.05)))
    target = lab(truth)
    design = COLOUR.format(start=165, L=target[0], a=target[1], b=target[2])
    start_dE = float(colour.delta_E(lab(ls.Stack(1.0, [ls.Layer(2.0, 165.0)], truth.exit)), target, method="CIE 2000"))
    assert start_dE > 3.0  # the start is visibly off
    code, text, err, out = _run(tmp_path, capsys, design)
    assert code == 0, text + err
    dE = float(colour.delta_E(lab(load_stack(out)), target, method="CIE 2000"))
    assert dE < 0.5, (dE, text)
    assert _report_number(text, r"ΔE2000 ([0-9.eE+-]+);") <= 0.5


NEEDLE = """
[[layers]]
name = "L"
n = 1.46
thickness_nm = { value = 100, free = true, min = 0, max = 300 }
coherent = true

[[layers]]
name = "H"
n = 2.35
thickness_nm = { value = 100, free = true, min = 0, max = 300 }
coherent = true

[substrate]
n = 1.52

[[targets]]
name = "broadband AR"
band_nm = [450, 650]
step_nm = 25
max = 0.0005
tolerance = 0.005

[optimizer.needle]
materials = [{ name = "SiO2", n = 1.46 }, { name = "TiO2", n = 2.35 }]
iterations = 1
points_per_layer = 8
"""


def test_needle_improves_two_layer_start_and_exit_status(tmp_path, capsys):
    """One needle lowers the merit of the refined 2-layer design; the written file reproduces the
    reported merit (tmm); the unmet R <= 0.05 % bound gives exit status 1."""
    code, text, err, out = _run(tmp_path, capsys, NEEDLE)
    m = re.search(r"needle: 1 insertion \((SiO2|TiO2)\) .*; merit ([0-9.eE+-]+) -> ([0-9.eE+-]+)", text)
    assert m, text + err
    two_layer, needled = float(m.group(2)), float(m.group(3))
    assert needled < 0.9 * two_layer
    stack = load_stack(out)
    assert len(stack.layers) >= 3
    wl = np.arange(450.0, 651.0, 25.0)
    R = _tmm_R(stack, wl)
    merit = np.mean((np.maximum(R - 0.0005, 0.0) / 0.005) ** 2)
    assert _report_number(text, r"-> ([0-9.eE+-]+) \(design\)") == pytest.approx(merit, rel=1e-5)
    assert needled == pytest.approx(merit, rel=1e-5)
    assert np.max(R) > 0.0005  # a bound this tight is out of reach of a few layers ...
    assert code == 1 and "NOT met" in text  # ... and the command says so


GOOD_TARGET = """
[[targets]]
quantity = "R"
band_nm = [450, 650]
value = 0
"""
LAYER = """
[[layers]]
name = "film"
n = {n}
thickness_nm = {thickness}
coherent = true

[substrate]
n = 1.52
"""
FREE = "{ value = 100, free = true, min = 0, max = 400 }"


@pytest.mark.parametrize(
    "design, needles",
    [
        (LAYER.format(n=1.38, thickness=FREE) + GOOD_TARGET.replace('"R"', '"X"'), ["key 'quantity'", "'X'"]),
        (LAYER.format(n=1.38, thickness=FREE) + GOOD_TARGET.replace("[450, 650]", "[650, 450]"),
         ["key 'band_nm'", "inverted"]),
        (LAYER.format(n=1.38, thickness=100) + GOOD_TARGET, ["key 'thickness_nm'", "no free layer"]),
        (LAYER.format(n='{ material = "Unobtainium" }', thickness=FREE) + GOOD_TARGET,
         ["[[layers]] no. 1", "key 'n'", "unknown material"]),
        (LAYER.format(n=1.38, thickness=FREE), ["'targets'", "missing"]),
        (LAYER.format(n=1.38, thickness=FREE) + GOOD_TARGET.replace("value = 0", "max = 5"),
         ["key 'max'", "fractions"]),
        (LAYER.format(n=1.38, thickness=FREE) + GOOD_TARGET + "[optimizer]\nstart = 4\n",
         ["[optimizer]", "unknown key 'start'", "did you mean 'starts'"]),
    ],
    ids=["quantity", "band", "no-free-layer", "material", "no-targets", "percent", "typo"],
)
def test_bad_design_files_exit_2(tmp_path, capsys, design, needles):
    code, text, err, out = _run(tmp_path, capsys, design)
    assert code == 2, text + err
    assert err.startswith("layerstack: error: ") and "design_in.toml" in err
    for needle in needles:
        assert needle in err, err
    assert not out.exists()


def test_save_stack_round_trip_and_table_paths(tmp_path):
    """io.save_stack writes TOML that load_stack reads back to the same optics; the design
    writer's table-path rebasing keeps a relative table valid from another directory."""
    from fitting._design_run import _rebase_tables
    from layerstack_jax.io import save_stack, stack_from_dict, stack_to_dict

    examples = Path(__file__).resolve().parent.parent / "examples"
    stack = load_stack(examples / "thin_film_on_metal.toml")
    out = save_stack(tmp_path / "a" / "copy.toml", stack, header='first line\nsecond "line"')
    assert out.read_text().startswith('# first line\n# second "line"\n')
    assert stack_to_dict(load_stack(out)) == stack_to_dict(stack)  # same numbers, bit for bit

    raw = {"layers": [{"name": "SiO2", "n": 1.46, "thickness_nm": 120.0, "coherent": True}],
           "substrate": {"n": {"table": "aluminium_nk.csv"}}}
    src = tmp_path / "src"
    src.mkdir()
    (src / "aluminium_nk.csv").write_bytes((examples / "aluminium_nk.csv").read_bytes())
    for out_dir, expected in ((tmp_path / "b", "../src/aluminium_nk.csv"), (src, "aluminium_nk.csv")):
        moved = _rebase_tables(raw, src, out_dir)
        assert moved["substrate"]["n"]["table"] == expected
        again = load_stack(save_stack(out_dir / "moved.toml", moved))
        assert stack_to_dict(again) == stack_to_dict(stack_from_dict(raw, src))
