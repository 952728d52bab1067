"""Generate the SYNTHETIC calibration-series measurement shipped in examples/.

A varnish (Cauchy n ≈ 1.54, synthetic yellowing absorption α(λ)) brushed at four thicknesses
(10, 20, 40, 80 µm) over a real measured background: the "moderate red" patch of the
ColorChecker (Ohta's measurement, as shipped by colour-science, 380–780 nm every 5 nm), taken
as the 45°/0° reading of the bare paint. ρg follows from it by Simonot's eq. 87
(``layerstack_jax.invert_background``); the coated samples are computed with the forward model
(``layerstack_jax.reflectance``, 45°/0°) and Gaussian noise of σ = 0.002 is added (seed 2026).

Writes (next to this script)
  calibration_series.csv      wavelength_nm, background, h10um, h20um, h40um, h80um
  calibration_rho_g.csv       ρg inverted from the noisy background column (for the CLI stack file)
  calibration_truth.json      the true thicknesses and α(λ) — for checking a fit, never used by it

Run: python examples/make_calibration_series.py
"""

from __future__ import annotations

import json
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import colour  # noqa: E402
import numpy as np  # noqa: E402

import layerstack_jax as ls  # noqa: E402

HERE = Path(__file__).resolve().parent
WL = np.arange(380.0, 781.0, 5.0)
THICKNESS_NM = np.array([10_000.0, 20_000.0, 40_000.0, 80_000.0])
SIGMA = 0.002
GEOMETRY = ls.Directional(45.0, 0.0)
N_BINDER = 1.5


def varnish_alpha(wavelength_nm):
    """Synthetic yellowing varnish: absorbs in the blue (1/nm)."""
    return 2e-5 * np.exp(-(wavelength_nm - 380.0) / 35.0) + 5e-8


def varnish(h):
    return ls.Layer(ls.Cauchy(1.525, 0.0045), h, coherent=False, alpha=varnish_alpha(WL), name="varnish")


def main() -> None:
    sd = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]["moderate red"]
    background = np.interp(WL, sd.wavelengths, sd.values)  # measured 45/0 reading of the bare paint
    bare = ls.Stack(1.0, [], ls.LambertianBackground(N_BINDER, 0.0))
    rho_g = np.clip(np.asarray(ls.invert_background(bare, WL, background, GEOMETRY)), 0.0, 1.0)
    samples = [np.asarray(ls.reflectance(ls.Stack(1.0, [varnish(h)], ls.LambertianBackground(N_BINDER, rho_g)), WL,
                                         GEOMETRY)) for h in THICKNESS_NM]
    rng = np.random.default_rng(2026)
    clean = np.stack([background, *samples])
    noisy = np.clip(clean + SIGMA * rng.standard_normal(clean.shape), 0.0, None)
    names = ["background"] + [f"h{int(h / 1000)}um" for h in THICKNESS_NM]
    header = (
        "# SYNTHETIC measurement (not real data): 45/0 reflectance factors of a varnish at 10/20/40/80 um over the\n"
        "# ColorChecker 'moderate red' patch (Ohta, colour-science), computed with layerstack_jax + Gaussian noise\n"
        f"# sigma = {SIGMA}; made by examples/make_calibration_series.py (true values in calibration_truth.json)\n"
    )
    rows = "\n".join(",".join(f"{v:.6f}" for v in [w, *col]) for w, col in zip(WL, noisy.T))
    (HERE / "calibration_series.csv").write_text(header + "wavelength_nm," + ",".join(names) + "\n" + rows + "\n")
    rho_noisy = np.clip(np.asarray(ls.invert_background(bare, WL, noisy[0], GEOMETRY)), 0.0, 1.0)
    (HERE / "calibration_rho_g.csv").write_text(
        "# SYNTHETIC: rho_g inverted (Simonot eq. 87) from the noisy 'background' column of calibration_series.csv\n"
        "wavelength_nm,rho_g\n" + "\n".join(f"{w:g},{r:.6f}" for w, r in zip(WL, rho_noisy)) + "\n"
    )
    truth = {"thickness_nm": THICKNESS_NM.tolist(), "wavelength_nm": WL.tolist(),
             "alpha_per_nm": varnish_alpha(WL).tolist(), "rho_g": rho_g.tolist(), "sigma": SIGMA,
             "geometry": "45/0", "n_binder": N_BINDER}
    (HERE / "calibration_truth.json").write_text(json.dumps(truth, indent=1))
    print(f"wrote {HERE / 'calibration_series.csv'} ({len(names)} spectra × {WL.size} wavelengths)")


if __name__ == "__main__":
    main()
