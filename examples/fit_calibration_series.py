"""Fit the synthetic calibration series of examples/ and print the report.

Joint fit (fitting.calibration_series): the four varnish samples share α(λ) (10 B-splines) and
ρg(λ) (one value per wavelength, started from the inversion of the bare-background column,
Simonot eq. 87, and fitted together with that column as a bare-background dataset); each has
its own thickness, the first (10 µm) taken as known — an incoherent layer's spectra
depend on α and h only through α·h, so one thickness must be measured independently.

Run: python examples/fit_calibration_series.py   (after make_calibration_series.py, or with the
CSV shipped in examples/)
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import fitting  # noqa: E402
import layerstack_jax as ls  # noqa: E402

HERE = Path(__file__).resolve().parent


def main() -> None:
    wl, columns = ls.read_spectra_csv(HERE / "calibration_series.csv")
    names = [n for n in columns if n != "background"]
    spectra = np.stack([columns[n] for n in names])
    template = ls.Stack(1.0, [ls.Layer(ls.Cauchy(1.525, 0.0045), 10_000.0, coherent=False, alpha=1e-5, name="varnish")],
                        ls.LambertianBackground(1.5, 0.5))
    geometry = ls.Directional(45.0, 0.0)
    objective = fitting.calibration_series(
        template, wl, spectra, geometry, layer="varnish", thicknesses=[10_000.0, 15_000.0, 30_000.0, 60_000.0],
        known=(0,), alpha_basis=10, rho_g_basis="free", background=columns["background"], sigma=0.002,
    )
    start = time.perf_counter()
    result = fitting.fit(objective)
    print(result.report())
    print(f"\nfit time (compile included): {time.perf_counter() - start:.1f} s")
    truth_file = HERE / "calibration_truth.json"
    if truth_file.exists():
        truth = json.loads(truth_file.read_text())
        h = result.values["thickness[varnish]"]
        e = result.stderr["thickness[varnish]"]
        print("\nagainst the synthetic truth (calibration_truth.json):")
        for name, hv, ev, ht in zip(names, h, e, truth["thickness_nm"]):
            print(f"  {name}: fitted {hv:9.1f} ± {ev:6.1f} nm   true {ht:9.1f} nm")
        a = result.spectra["alpha[varnish]"]
        at = np.asarray(truth["alpha_per_nm"])
        print(f"  alpha(λ): max |fitted − true| = {np.max(np.abs(a - at)):.2e} 1/nm (true max {at.max():.2e})")
    out = Path("out")
    if out.is_dir():
        result.plot(out / "calibration_series_fit.png", title="calibration series")
        print(f"wrote {out / 'calibration_series_fit.png'}")


if __name__ == "__main__":
    main()
