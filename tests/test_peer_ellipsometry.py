"""ψ/Δ against the peer ellipsometry codes pyElli (2x2 solver) and refellips on twelve models:
bare substrates, single and multiple films, dielectrics, semiconductors, metals, a Tauc–Lorentz
film and a Bruggeman roughness layer (the same parameters given to both codes), 6 angles.

Both codes report Δ as ellipsometers do; ``ls.ellipsometry`` must equal them to ≤ 1e-9°
(Δ compared modulo 360°, weighted by sin 2ψ where Δ is ill-conditioned: ψ → 0). pyElli and
refellips are optional test dependencies (``pytest.importorskip``).
"""

from __future__ import annotations

import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_jax._media.effective_medium import Bruggeman
from layerstack_jax._media.oscillators import TaucLorentz

WL = np.array([250.0, 400.0, 550.0, 633.0, 800.0, 1200.0])
ANGLES = np.array([0.0, 45.0, 55.0, 65.0, 70.0, 75.0])
TOL_DEG = 1e-9

# the coarse test grid (6 wavelengths) triggers the library's fringe-aliasing warning: expected here
pytestmark = pytest.mark.filterwarnings("ignore:.*aliases")

SI, SIO2, TIO2 = 3.88 + 0.02j, 1.46 + 0j, 2.4 + 0.01j
AU, AL, GLASS = 0.18 + 3.4j, 1.2 + 7.3j, 1.52 + 0j

#: name -> (ambient n, [(n, d_nm), ...], substrate n); n complex, constant over wavelength.
MODELS = {
    "bare_si": (1.0, [], SI),
    "bare_gold": (1.0, [], AU),
    "bare_glass": (1.0, [], GLASS),
    "native_oxide": (1.0, [(SIO2, 2.0)], SI),
    "thermal_oxide": (1.0, [(SIO2, 103.5)], SI),
    "tio2_on_si": (1.0, [(TIO2, 55.0)], SI),
    "oxide_on_gold": (1.0, [(SIO2, 80.0)], AU),
    "thin_gold_on_glass": (1.0, [(AU, 12.0)], GLASS),
    "bragg_pair_x3": (1.0, [(TIO2, 60.0), (SIO2, 95.0)] * 3, GLASS),
    "aluminium_under_oxides": (1.0, [(SIO2, 30.0), (2.0 + 0.05j, 20.0), (AL, 8.0)], SI),
    "water_ambient": (1.333, [(SIO2, 150.0)], SI),
}


def _layerstack(ambient, layers, substrate):
    idx = [ls.Index(n.real, n.imag) for n, _ in layers]
    return ls.Stack(ambient, [ls.Layer(m, d) for m, (_, d) in zip(idx, layers)],
                    ls.Substrate(ls.Index(substrate.real, substrate.imag)))


def _ours(stack):
    e = ls.ellipsometry(stack, WL, ANGLES)
    return np.asarray(e.psi_deg), np.asarray(e.delta_deg)  # (angle, wl)


def _assert_close(psi, delta, psi_ref, delta_ref):
    assert np.max(np.abs(psi - psi_ref)) <= TOL_DEG
    d = np.abs((delta - delta_ref + 180.0) % 360.0 - 180.0) * np.sin(2 * np.deg2rad(psi_ref))
    assert np.max(d) <= TOL_DEG


def _pyelli_result(elli, ambient, layers, substrate, angle):
    def mat(n):
        return elli.IsotropicMaterial(elli.ConstantRefractiveIndex(n=n))

    structure = elli.Structure(mat(ambient), [elli.Layer(mat(n), d) for n, d in layers], mat(substrate))
    return structure.evaluate(WL, angle, solver=elli.Solver2x2)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_equals_pyelli(name):
    elli = pytest.importorskip("elli")
    ambient, layers, substrate = MODELS[name]
    psi, delta = _ours(_layerstack(ambient, layers, substrate))
    for i, a in enumerate(ANGLES):
        r = _pyelli_result(elli, complex(ambient), layers, substrate, float(a))
        _assert_close(psi[i], delta[i], np.asarray(r.psi), np.asarray(r.delta))


@pytest.mark.parametrize("name", sorted(MODELS))
def test_equals_refellips(name):
    pytest.importorskip("refnx")
    rm = pytest.importorskip("refellips.reflect_modelSE")
    ambient, layers, substrate = MODELS[name]
    psi, delta = _ours(_layerstack(ambient, layers, substrate))
    # refellips' slab table: rows (thickness Å, n, k, roughness), fronting first, backing last
    table = np.array([[0.0, ambient, 0.0, 0.0]] + [[10 * d, n.real, n.imag, 0.0] for n, d in layers]
                     + [[0.0, substrate.real, substrate.imag, 0.0]])
    for j, w in enumerate(WL):
        p, d = rm.Delta_Psi_TMM(ANGLES, table.copy(), w, 0.0)
        _assert_close(psi[:, j], delta[:, j], np.asarray(p), np.asarray(d))


def test_dispersive_models_equal_pyelli():
    """Tauc–Lorentz film under a 50 % void Bruggeman roughness layer on silicon: the same
    dispersion and mixing parameters given to pyElli; ψ, Δ equal to ≤ 1e-9°."""
    elli = pytest.importorskip("elli")
    tl = TaucLorentz(Eg=3.2, A=[180.0], E0=[4.5], C=[1.2], eps_inf=2.1)
    rough = Bruggeman([tl, 1.0], 0.5)
    si = ls.Index(SI.real, SI.imag)
    stack = ls.Stack(1.0, [ls.Layer(rough, 3.0), ls.Layer(tl, 45.0)], ls.Substrate(si))
    psi, delta = _ours(stack)
    tl_e = (elli.TaucLorentz(Eg=3.2).add(A=180.0, E=4.5, C=1.2) + 2.1).get_mat()
    void = elli.IsotropicMaterial(elli.ConstantRefractiveIndex(n=1.0))
    rough_e = elli.BruggemanEMA(void, tl_e, 0.5)  # host void, guest TL, fraction of the guest
    si_e = elli.IsotropicMaterial(elli.ConstantRefractiveIndex(n=SI))
    for i, a in enumerate(ANGLES):
        r = elli.Structure(elli.AIR, [elli.Layer(rough_e, 3.0), elli.Layer(tl_e, 45.0)], si_e).evaluate(
            WL, float(a), solver=elli.Solver2x2
        )
        _assert_close(psi[i], delta[i], np.asarray(r.psi), np.asarray(r.delta))
