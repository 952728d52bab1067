"""`layerstack fit MODEL.toml MEASUREMENT` on real instrument files (issue 15): geometry, angles
and σ come from the file; ψ/Δ are fitted as N, C, S (free of Δ's wrap and reporting range).

The files are real measurements shipped in examples/data (provenance and licences in its
README): the same RC2 scan of "2nm SiO2 on Si" exported by CompleteEASE and converted to NeXus.
The documented thickness is the sample's own description, 2 nm.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from layerstack_cli import main

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "examples" / "data"
MODEL = ROOT / "examples" / "sio2_on_si_fit.toml"


@pytest.mark.parametrize("name", ["woollam_completeease_2nm_SiO2_on_Si.dat", "nexus_2nm_SiO2_on_Si_nx_opt.nxs"])
def test_fit_measured_ellipsometry_file_recovers_documented_thickness(tmp_path, capsys, name):
    pytest.importorskip("h5py")
    out = tmp_path / "r.json"
    code = main(["fit", str(MODEL), str(DATA / name), "-w", "400:820:20", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "geometry: ellipsometry:50,60,70:N,C,S" in text and "sigma: from the file" in text
    fit = json.loads(out.read_text())
    d = fit["fits"][0]["parameters"]["thickness_nm[SiO2]"]["value"]
    assert d == pytest.approx(2.0, abs=0.1), d  # documented: 2 nm SiO2 on Si


def test_instrument_file_refuses_csv_only_options(tmp_path, capsys):
    data = DATA / "woollam_completeease_2nm_SiO2_on_Si.dat"
    assert main(["fit", str(MODEL), str(data), "-g", "45/0", "-o", str(tmp_path / "r.json")]) == 2
    assert "the file says how it was measured" in capsys.readouterr().err
