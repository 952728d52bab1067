"""Effective-medium layers (Bruggeman, Looyenga) against their defining equations solved here in
numpy, their limits, and pyElli's BruggemanEMA / LooyengaEMA on the same inputs; the void fraction of a
rough (50 % void) Bruggeman layer is differentiable.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import layerstack_jax as ls
from layerstack_jax._media.effective_medium import Bruggeman, Looyenga
from layerstack_jax._media.oscillators import Lorentz

WL = np.linspace(250.0, 1000.0, 7)

#: (phase a, phase b): absorbing semiconductor/void, metal/dielectric, dielectric/void,
#: metal/absorbing dielectric, dispersive oscillator/void.
PAIRS = [
    (ls.Index(3.9, 0.02), ls.Index(1.0)),
    (ls.Index(0.2, 3.4), ls.Index(1.46)),
    (ls.Index(1.5), ls.Index(1.0)),
    (ls.Index(0.05, 4.0), ls.Index(2.0, 0.5)),
    (Lorentz(A=30.0, E0=4.0, gamma=0.6, eps_inf=2.0), ls.Index(1.0)),
]
FRACTIONS = [0.0, 0.1, 0.3, 0.5, 0.7, 0.95, 1.0]


def _eps(m):
    return np.broadcast_to(np.asarray(m(WL)) ** 2, WL.shape).astype(complex)


def _bruggeman_roots_np(ea, eb, fa):
    """Both roots of 2ε² − bε − εaεb = 0 (numpy, per wavelength)."""
    b = (3 * fa - 1) * ea + (3 * (1 - fa) - 1) * eb
    return np.stack([np.roots([2.0, -bi, -ea_i * eb_i]) for bi, ea_i, eb_i in zip(b, ea, eb)])


@pytest.mark.parametrize("pair", range(len(PAIRS)))
def test_bruggeman_solves_its_equation_on_the_passive_branch(pair):
    """ε solves Σ f_i (ε_i − ε)/(ε_i + 2ε) = 0 (numpy roots), is the root with Im ε ≥ 0 (the
    positive one when both are real), k ≥ 0, and tends to each phase at f = 0, 1."""
    a, b = PAIRS[pair]
    ea, eb = _eps(a), _eps(b)
    for f in FRACTIONS:
        eps = np.asarray(Bruggeman([a, b], f).permittivity(WL)) * np.ones_like(WL)
        roots = _bruggeman_roots_np(ea, eb, f)
        best = np.where(
            np.abs(roots[:, 0].imag - roots[:, 1].imag) > 1e-12 * np.abs(roots).sum(1),
            np.where(roots[:, 0].imag > roots[:, 1].imag, roots[:, 0], roots[:, 1]),
            np.where(roots[:, 0].real >= roots[:, 1].real, roots[:, 0], roots[:, 1]),
        )
        np.testing.assert_allclose(eps, best, rtol=1e-12, atol=1e-14)
        assert np.all(eps.imag >= -1e-15)
        assert np.all(np.asarray(Bruggeman([a, b], f)(WL)).imag >= 0)
    np.testing.assert_allclose(np.asarray(Bruggeman([a, b], 1.0).permittivity(WL)) * np.ones_like(WL), ea, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(Bruggeman([a, b], 0.0).permittivity(WL)) * np.ones_like(WL), eb, rtol=1e-12)


@pytest.mark.parametrize("pair", range(len(PAIRS)))
def test_looyenga_closed_form(pair):
    """ε^{1/3} = f εa^{1/3} + (1 − f) εb^{1/3} with principal cube roots (numpy)."""
    a, b = PAIRS[pair]
    ea, eb = _eps(a), _eps(b)
    for f in FRACTIONS:
        eps = np.asarray(Looyenga([a, b], f).permittivity(WL)) * np.ones_like(WL)
        ref = (f * ea ** (1 / 3) + (1 - f) * eb ** (1 / 3)) ** 3  # numpy's principal power
        np.testing.assert_allclose(eps, ref, rtol=1e-12)
        assert np.all(eps.imag >= -1e-15)


def test_against_pyelli_same_inputs():
    """Bruggeman and Looyenga equal pyElli's BruggemanEMA / LooyengaEMA (host b, guest a,
    fraction of the guest) to <= 1e-9 on every pair and fraction."""
    elli = pytest.importorskip("elli")
    worst = 0.0
    for a, b in PAIRS:
        host = elli.IsotropicMaterial(elli.Table(lbda=WL, n=np.broadcast_to(np.asarray(b(WL)), WL.shape)))
        guest = elli.IsotropicMaterial(elli.Table(lbda=WL, n=np.broadcast_to(np.asarray(a(WL)), WL.shape)))
        for f in FRACTIONS[1:-1]:
            for ours, theirs in ((Bruggeman, elli.BruggemanEMA), (Looyenga, elli.LooyengaEMA)):
                ref = np.sqrt(theirs(host, guest, f).get_tensor(WL)[:, 0, 0])
                got = np.asarray(ours([a, b], f)(WL))
                worst = max(worst, float(np.max(np.abs(got - ref) / np.abs(ref))))
    assert worst <= 1e-9


def test_three_phases():
    """m = 3: the Newton solution satisfies the three-phase equation to 1e-12; splitting one
    phase in two identical parts gives the two-phase result; Looyenga's is its closed form."""
    si, ox, void = ls.Index(3.9, 0.02), ls.Index(1.46), ls.Index(1.0)
    m = Bruggeman([si, ox, void], [0.3, 0.3])
    eps = complex(np.asarray(m.permittivity(WL)).ravel()[0])
    e = np.array([complex(si(WL)) ** 2, complex(ox(WL)) ** 2, 1.0])
    f = np.array([0.3, 0.3, 0.4])
    assert abs(np.sum(f * (e - eps) / (e + 2 * eps))) <= 1e-12
    assert eps.imag >= 0
    split = Bruggeman([si, void, void], [0.3, 0.3])
    two = Bruggeman([si, void], 0.3)
    np.testing.assert_allclose(np.asarray(split(WL)), np.asarray(two(WL)), rtol=1e-12)
    ref = np.sum(f * e ** (1 / 3)) ** 3
    assert complex(np.asarray(Looyenga([si, ox, void], [0.3, 0.3]).permittivity(WL)).ravel()[0]) == pytest.approx(ref, rel=1e-12)


def test_fraction_is_fittable_gradient_matches_central_difference():
    """d(ψ, Δ)/d(void fraction) of a rough layer on silicon vs central differences."""
    si = ls.Index(3.9, 0.02)

    def f(frac):
        rough = ls.Layer(Bruggeman([si, 1.0], frac), 4.0)
        e = ls.ellipsometry(ls.Stack(1.0, [rough], ls.Substrate(si)), WL, 70.0)
        return jnp.concatenate([e.psi_deg, e.delta_deg])

    g = np.asarray(jax.jit(jax.jacfwd(f))(0.5))
    fj = jax.jit(f)
    fd = (np.asarray(fj(0.5 + 1e-6)) - np.asarray(fj(0.5 - 1e-6))) / 2e-6
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-8)


def test_bad_input_raises():
    with pytest.raises(ls.LayerstackError, match="at least two"):
        Bruggeman([1.5], [])
    with pytest.raises(ls.LayerstackError, match="fractions"):
        Bruggeman([1.5, 1.0], 1.2)
    with pytest.raises(ls.LayerstackError, match="fractions"):
        Looyenga([1.5, 1.0, 2.0], [0.7, 0.6])
    with pytest.raises(ls.LayerstackError, match="fractions"):
        Bruggeman([1.5, 1.0, 2.0], 0.5)
