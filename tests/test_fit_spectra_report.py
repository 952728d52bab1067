"""Fitted spectra are reported with their σ at every wavelength (issue 27, "Reports hide what users
plot"): in the result, the JSON and the plot; long spectra are summarised in the text report.

References: for a spectrum free per wavelength the basis is the identity, so σ(λ) must equal the
per-value standard errors the fit reports for the coefficients themselves; for a spectrum on a
B-spline basis, σ(λ)² is re-derived here from the covariance of the named coefficient components
and a finite-difference Jacobian of the spectrum with respect to them (perturbing one coefficient
at a time through ``Parameter.spectrum``) — a different assembly from ``spectrum_stderr``'s block
reshaping.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import fitting as ft
from test_structured import _calibration, slab_problem


@pytest.fixture(scope="module")
def slab_fit():
    return ft.fit(slab_problem(24))


def test_free_spectrum_sigma_equals_its_values_sigma(slab_fit):
    r = slab_fit
    for name in ("n[slab]", "alpha[slab]"):
        np.testing.assert_allclose(r.spectra_stderr[name], r.stderr[name], rtol=1e-12)
        assert np.all(np.isfinite(r.spectra_stderr[name])) and np.all(r.spectra_stderr[name] > 0)


def test_long_spectra_are_summarised_in_the_report_and_complete_in_the_json(slab_fit, tmp_path):
    r = slab_fit
    text = r.report()
    line = next(x for x in text.splitlines() if x.lstrip().startswith("alpha[slab]"))
    assert "24 values" in line and "σ(λ)" in line and "every value in the JSON" in line
    assert len(text.splitlines()) < 60  # not one line per wavelength
    d = json.loads(r.to_json())
    np.testing.assert_allclose(d["parameters"]["alpha[slab]"]["spectrum_stderr"], r.spectra_stderr["alpha[slab]"],
                               rtol=1e-15)
    fig = r.plot(tmp_path / "fit.png")
    titles = [ax.get_title() for ax in fig.get_axes()]
    assert "alpha[slab] (±1σ band)" in titles and "n[slab] (±1σ band)" in titles
    assert (tmp_path / "fit.png").stat().st_size > 10_000


def test_basis_spectrum_sigma_by_finite_differences():
    obj = _calibration(31, 8)[0]
    r = ft.fit(obj)
    layout = obj.layout
    p = next(q for q in layout.params if q.name.startswith("alpha"))
    comps = [k for k, n in enumerate(r.names) if n.startswith(p.name + "[") or n == p.name]
    c0 = np.asarray(r.values[p.name], float)
    J = np.empty((obj.wavelength.size, len(comps)))
    h = 1e-3 * np.max(np.abs(c0))
    free = [int(n.rsplit("[", 1)[1].rstrip("]")) for n in (r.names[k] for k in comps)]
    for j, i in enumerate(free):
        up, down = c0.copy(), c0.copy()
        up[i] += h
        down[i] -= h
        J[:, j] = (p.spectrum(up) - p.spectrum(down)) / (2 * h)
    C = r.covariance[np.ix_(comps, comps)]
    expected = np.sqrt(np.einsum("lj,jk,lk->l", J, C, J))
    np.testing.assert_allclose(r.spectra_stderr[p.name], expected, rtol=1e-6)
    assert "spectrum" in r.report()  # a short basis lists its coefficients and one spectrum line
    # one known thickness breaks the alpha·h trade-off: no "fix one of them" advice for a series
    assert not any("both free" in w for w in r.warnings), r.warnings


def test_plot_is_a_grid_of_at_most_three_panels_per_row(slab_fit):
    fig = slab_fit.plot()
    # 2 datasets + 2 spectra = 4 panels: two rows of subfigures
    widths = {round(sf.bbox.width) for sf in fig.subfigs}
    assert len(fig.subfigs) == 6 and len(widths) == 1
    assert sum(sf.get_visible() for sf in fig.subfigs) == 4
