"""The shipped pigment set (examples/data/pigments_synthetic.csv): synthetic, and exactly the
curves examples/data/README.md documents (written out here from that table, not read from code)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import layerstack_jax as ls

DATA = Path(__file__).resolve().parents[1] / "examples" / "data"
PIGMENTS = ("white", "red", "blue")


def _documented(wl):
    band = lambda mu, w: np.exp(-0.5 * ((wl - mu) / w) ** 2)  # noqa: E731
    return {"white": (2e-6 + 4e-5 * band(380, 15), 3e-3 * 550 / wl),
            "red": (4e-4 * (band(470, 45) + 0.8 * band(530, 35)) + 2e-6, 2e-4 * 550 / wl),
            "blue": (3e-4 * band(610, 55) + 2e-5 * band(420, 30) + 2e-6, 1.5e-4 * 550 / wl)}


def _read():
    columns = [f"{p}_{q}_per_nm" for p in PIGMENTS for q in "ks"]  # read lower-cased
    return ls.read_csv_columns(DATA / "pigments_synthetic.csv", ["wavelength_nm", *columns])


def test_the_file_holds_the_documented_curves():
    t = _read()
    wl = t["wavelength_nm"]
    np.testing.assert_array_equal(wl, np.arange(380.0, 781.0, 10.0))
    for name, (K, S) in _documented(wl).items():
        np.testing.assert_allclose(t[f"{name}_k_per_nm"], K, rtol=1e-10)
        np.testing.assert_allclose(t[f"{name}_s_per_nm"], S, rtol=1e-10)
    text = (DATA / "pigments_synthetic.csv").read_text()
    assert text.startswith("# SYNTHETIC")
    assert "synthetic, not measured" in (DATA / "README.md").read_text()


def test_the_white_is_white_and_the_colours_absorb_where_documented():
    t = _read()
    wl = t["wavelength_nm"]
    paint = {p: ls.Paint(t[f"{p}_k_per_nm"], t[f"{p}_s_per_nm"], name=p) for p in PIGMENTS}
    # R_inf = 1 + K/S - sqrt((K/S)^2 + 2 K/S) (Kubelka), against the library's opaque body
    for p in PIGMENTS:
        ks = t[f"{p}_k_per_nm"] / t[f"{p}_s_per_nm"]
        r_inf = 1 + ks - np.sqrt(ks * ks + 2 * ks)
        body = ls.KubelkaMunk(1.5, paint[p], None, 0.0)
        np.testing.assert_allclose(np.asarray(body.lower(wl)).ravel(), r_inf, rtol=1e-12)
        if p == "white":
            assert r_inf[wl >= 450].min() > 0.95
    ks_red = t["red_k_per_nm"] / t["red_s_per_nm"]
    assert 470.0 <= wl[np.argmax(ks_red)] <= 530.0  # the red absorbs blue-green (its two K bands)
    ks_blue = t["blue_k_per_nm"] / t["blue_s_per_nm"]
    assert 580.0 <= wl[np.argmax(ks_blue)] <= 660.0  # the blue absorbs orange-red
