"""Make the small example cube of ``examples/cube/`` (run from the repository root:
``python examples/cube/make_film_cube.py``).

Provenance: synthetic, computed here by the public forward model :func:`layerstack_jax.predict`
(float64) for a dielectric film on glass (substrate n = 1.52) seen in specular reflection at 8°
(geometry ``specular:8:R``), on 31 bands 400–700 nm every 10 nm. The truth is known exactly:

* film thickness (nm): a ramp across the columns, 110 nm at x = 0 to 190 nm at x = 15;
* film index n (dimensionless, k = 0): a ramp down the rows, 1.90 at y = 0 to 2.20 at y = 11.

Gaussian noise of standard deviation 1e-3 (seed 19) is added, pixel (2, 3) gets a NaN band
(a dead detector element: left out of that pixel's fit, which uses its 30 other bands), and
``film_mask.npy`` leaves out the
3 x 3 pixels of the bottom-right corner (status 1). Files written (float32 cube, ~24 kB):
``film_cube.npy`` (12 rows, 16 columns, 31 bands), ``film_mask.npy`` (12 x 16 booleans).
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import layerstack_jax as ls  # noqa: E402

HERE = Path(__file__).resolve().parent
WL = np.arange(400.0, 701.0, 10.0)
NY, NX = 12, 16


def main() -> None:
    thickness = np.broadcast_to(np.linspace(110.0, 190.0, NX), (NY, NX))
    n = np.broadcast_to(np.linspace(1.90, 2.20, NY)[:, None], (NY, NX))
    film = ls.Layer(ls.Index(n[..., None]), thickness[..., None], coherent=True, name="film")
    cube = np.asarray(ls.predict(ls.Stack(1.0, [film], ls.Substrate(1.52)), WL, ls.Specular(8.0, "R")))
    cube = cube + np.random.default_rng(19).normal(0.0, 1e-3, cube.shape)
    cube[2, 3, 10] = np.nan
    mask = np.ones((NY, NX), bool)
    mask[-3:, -3:] = False
    np.save(HERE / "film_cube.npy", cube.astype(np.float32))
    np.save(HERE / "film_mask.npy", mask)
    print(f"wrote {HERE / 'film_cube.npy'} {cube.shape} and {HERE / 'film_mask.npy'} {mask.shape}")


if __name__ == "__main__":
    main()
