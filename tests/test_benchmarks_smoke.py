"""Smoke tests: the benchmark runners and sections work on tiny inputs (timings are not asserted).

Where a section computes physics (P3, scaling, accuracy), its numbers are checked against an
independent reference (tmm, scipy quad in tests/reference.py, the closed form of glass), so a
benchmark cannot silently time a wrong model.
"""

import numpy as np
import pytest
import tmm

import reference as ref
from benchmarks import _ours, accuracy, memory, mixed, radiometric, scaling, targets


def test_radiometric_runner_tiny():
    res = radiometric.run(batch=4, block=2, nodes=8, float32=False, accuracy=False, quick=True)
    assert res["forward"]["spectra_per_s"] > 0
    assert np.isfinite(res["grad_jacfwd"]["ratio_to_forward"])
    assert "| forward |" in "\n".join(radiometric.markdown(res))


def test_coherent_adapter_matches_tmm():
    import jax.numpy as jnp

    n = np.array([[1.0], [2.35], [1.46 + 0.1j], [1.52]], complex)
    d = np.array([80.0, 120.0])
    wl = np.array([550.0])
    th = np.array([0.0, 0.7])
    R, T = _ours.coherent_rt(jnp.asarray(n), jnp.asarray(d), jnp.asarray(wl), jnp.asarray(th))
    assert R.shape == (2, 2, 1)
    for ip, pol in enumerate("sp"):
        for ia, a in enumerate(th):
            ref_ = tmm.coh_tmm(pol, list(n[:, 0]), [np.inf, *d, np.inf], a, 550.0)
            assert float(R[ip, ia, 0]) == pytest.approx(ref_["R"], abs=1e-12)
            assert float(T[ip, ia, 0]) == pytest.approx(ref_["T"], abs=1e-12)


def test_p3_model_matches_tmm_and_quad_reference():
    """P3 45/0 value vs tmm.inc_tmm + scipy quad (eq. 79), specular R(45°) vs tmm.inc_tmm."""
    wl = np.array([420.0, 650.0])
    model, specular, _ = mixed.build(wl)
    h = mixed.samples(1)[0]
    ours, ours_s = np.asarray(model(h)), np.asarray(specular(h))
    for i, lam in enumerate(wl):
        rf, rs = mixed.reference_values(h, float(lam))
        assert ours[i] == pytest.approx(rf, abs=1e-10)
        assert ours_s[i] == pytest.approx(rs, abs=1e-12)


def test_p3_runner_tiny():
    # physics is checked in test_p3_model_matches_tmm_and_quad_reference; this covers the runner
    res = mixed.run(quick=True, batch=2, block=1, n_wavelengths=3, check_points=(0, 0))
    for key in ("forward", "value_and_grad", "jacfwd"):
        assert res[key]["finite"] and res[key]["spectra_per_s"] > 0
    assert res["reference_check"] is None
    assert "Reference check" in "\n".join(mixed.markdown(res))


def test_memory_child_tiny():
    res = memory.child(n=12, chunk=5)
    assert res["finite"] and res["peak_rss_bytes"] > 0 and res["spectra_per_s"] > 0
    assert res["output_bytes"] == 12 * 401 * 8


def test_scaling_point_matches_tmm():
    fwd, vg, d = scaling.coherent_problem(layers=3, wavelengths=2, angles=2)
    R = np.asarray(fwd(d))  # (angle, pol, wl)
    wl = np.linspace(400.0, 1000.0, 2)
    th = np.deg2rad(np.linspace(0.0, 80.0, 2))
    n = [1.0, 2.35, 1.46, 2.35, 1.52]
    for ia, a in enumerate(th):
        for ip, pol in enumerate("sp"):
            for iw, lam in enumerate(wl):
                expect = tmm.coh_tmm(pol, n, [np.inf, *np.asarray(d), np.inf], a, lam)["R"]
                assert R[ia, ip, iw] == pytest.approx(expect, abs=1e-12)
    row = scaling._coherent_point(2, 3, 2, quick=True, grad=True)
    assert row["min_s"] > 0 and row["grad_min_s"] > 0 and row["points"] == 12


def test_accuracy_rules_against_closed_form():
    fwd, rev, lam, ref_fn, _ = accuracy.cases()["glass"]
    exact = ref.diffuse_interface_closed(1.5, 1.0)
    assert ref_fn() == exact
    assert abs(accuracy.default_rule(fwd, lam, 24) - exact) < 1e-9
    plain = accuracy.plain_rule(rev, lam, [64, 256])
    # plain Gauss-Legendre converges slowly (PHYSICS.md trap 4: 256 nodes still ~3e-4)
    assert 1e-5 < abs(plain[1] - exact) < 1e-2
    assert accuracy.total_nodes(fwd, "back", 8) >= 8


def test_targets_judgement():
    rows = [
        {"case": "P1", "impl": "layerstack_jax", "kind": "forward", "min_s": 0.2, "median_s": 0.25, "compile_s": 6.0},
        {"case": "P1", "impl": "layerstack_jax", "kind": "value_and_grad", "min_s": 0.9, "median_s": 1.0, "compile_s": 1.0},
        {"case": "P1", "impl": "tmm-fast", "kind": "forward", "min_s": 0.1, "median_s": 0.1},
    ]
    t = {x["name"]: x["met"] for x in targets.targets({"rows": rows, "sections": {}})}
    assert t["P1 forward"] is True
    assert t["P1 forward faster than tmm-fast"] is False
    assert t["P1 value-and-gradient"] is True
    assert t["P1 gradient / forward"] is False  # 4.5 > 3
    assert t["compile: P1 forward"] is False
    assert t["P2 forward throughput"] is None  # not run: never reported as met
    assert "**NO**" in "\n".join(targets.markdown(targets.targets({"rows": rows, "sections": {}})))


def test_design_case_runs_on_a_tiny_grid(capsys):
    from benchmarks import design_case

    assert design_case.main(["--repeats", "1", "--wavelengths", "8", "--angles", "2"]) == 0
    assert "gradient / value" in capsys.readouterr().out


def test_ellipsometry_fit_runner_tiny():
    """E1 on 16 wavelengths: layerstack's ψ, Δ at the truth equal pyElli's (the data's source) to
    ≤ 1e-9°, both codes fit the same values, the truth is recovered, and the report renders."""
    pytest.importorskip("elli")
    from benchmarks import ellipsometry_fit

    res = ellipsometry_fit.run(n_wavelengths=16, repeats=1, starts=1)  # starts > 1: one more compile (~1 min loaded)
    assert res["model_check_deg"] <= 1e-9
    assert res["all_converged"]
    assert res["max_disagreement_in_stderr"] <= ellipsometry_fit.AGREEMENT_STDERR
    assert res["max_error_in_stderr"] <= 5.0
    machine = {"timestamp": "t", "git": "g", "cpu_model": "cpu", "cpu_count": 2, "mem_total_gib": 1.0,
               "versions": {"jax": "x", "scipy": "y"}, "pyelli": "z"}
    text = "\n".join(ellipsometry_fit.markdown(res, [res], machine, "up 1 day"))
    assert "| compile (first fit − median further fit) |" in text and "pyElli" in text


@pytest.mark.slow
def test_cli_predict_benchmark_tiny(tmp_path, monkeypatch):
    """The command line and the library compute the same batch (difference exactly 0)."""
    from benchmarks import cli_predict

    monkeypatch.setattr(cli_predict, "RESULTS", tmp_path)
    res = cli_predict.main(["--n", "12"])
    assert res["max_abs_diff"] == 0.0
    assert (tmp_path / "cli_predict.md").read_text().count("|") > 10


def test_kubelka_munk_fit_runner_tiny(tmp_path):
    """K1 on 6 pixels: the NumPy yardstick's forward (written from the equations in the
    benchmark) equals ``ls.predict`` to ≤ 1e-12, and the yardstick and ``fit_batch`` fit the same
    values (within 0.01 standard errors: both stop within ~1e-3 σ of the minimum); the report
    renders."""
    from benchmarks import kubelka_munk_fit

    res = kubelka_munk_fit.main(["--pixels", "6", "--repeats", "1", "--scipy-pixels", "2", "--chunk-size", "6",
                                 "--no-float32", "--out-dir", str(tmp_path)])
    assert res["forward_max_abs_diff"] <= 1e-12
    assert res["ours_float64"]["converged"] == 6 and res["yardstick"]["success"] == 2
    assert max(res["yardstick"]["max_abs_diff_over_sigma_vs_ours"]) <= 1e-2
    assert "yardstick: NumPy + scipy" in (tmp_path / "kubelka_munk_fit.md").read_text()


@pytest.mark.slow
def test_derivative_modes_runner_tiny(tmp_path):
    """Every mode's table row is written, each ratio finite and positive (a few samples)."""
    from benchmarks import derivative_modes

    out = tmp_path / "modes.md"
    assert derivative_modes.main(["--rounds", "1", "--p2-batch", "2", "--p3-batch", "8", "--out", str(out)]) == 0
    rows = [line for line in out.read_text().splitlines() if line.startswith("| ") and "ms" not in line]
    assert len(rows) == len(derivative_modes.ROWS)
    assert all(float(r.split("|")[3]) > 0 and float(r.split("|")[5]) > 0 for r in rows)
