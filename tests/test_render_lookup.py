"""Table interpolation and sampling of the render plugin (no Mitsuba needed).

References: scipy's RegularGridInterpolator (an independent multilinear interpolator) for the
values; quadrature over the hemisphere for the normalization of the sampling pdf; the mean of
f·cos/pdf over sampled directions against that quadrature (an estimator that is biased if
sample and pdf disagree)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from layerstack_jax._base.validate import LayerstackError
from layerstack_jax.render._lookup import DEFENSIVE, CoatingTables, TableSurface, _azimuth


def _tables(seed=0, A=7, B=6, P=5, L=9):
    rng = np.random.default_rng(seed)
    wl = np.sort(rng.uniform(380, 780, L))
    ct = np.sort(rng.uniform(0.05, 1.0, A))
    co = np.sort(rng.uniform(0.05, 1.0, B))
    ph = np.sort(rng.uniform(0.0, np.pi, P))
    k_r = rng.uniform(0.0, 0.4, (A, L))
    k_d = rng.uniform(0.0, 0.1, (A, B, P, L))
    return CoatingTables(wl, ct, k_r, np.zeros_like(k_r), ph, co, k_d, 0.0)


def _direction(cos_t, phi):
    s = math.sqrt(1 - cos_t * cos_t)
    return (s * math.cos(phi), s * math.sin(phi), cos_t)


def test_values_match_scipy_multilinear():
    t = _tables()
    surf = TableSurface(t)
    rng = np.random.default_rng(1)
    kr_ref = RegularGridInterpolator((t.cos_theta, t.wavelength_nm), t.k_r)
    kd_ref = RegularGridInterpolator((t.cos_theta, t.cos_theta_out, t.phi_out, t.wavelength_nm), t.k_d)
    err_r = err_d = 0.0
    for _ in range(200):
        # points inside every grid (outside, the lookup clamps: tested below)
        ci = rng.uniform(t.cos_theta[0], t.cos_theta[-1])
        co = rng.uniform(t.cos_theta_out[0], t.cos_theta_out[-1])
        dphi = rng.uniform(t.phi_out[0], t.phi_out[-1])
        wls = rng.uniform(t.wavelength_nm[0], t.wavelength_nm[-1], 4)
        phi_i = rng.uniform(-np.pi, np.pi)
        sign = rng.choice([-1.0, 1.0])
        wi, wo = _direction(ci, phi_i), _direction(co, phi_i + math.pi + sign * dphi)  # φ from the mirror side
        got_r = surf.specular(ci, wls)
        got_d = surf.brdf(wi, wo, wls)
        err_r = max(err_r, np.abs(np.array(got_r) - kr_ref(np.stack([np.full(4, ci), wls], -1))).max())
        pts = np.stack([np.full(4, ci), np.full(4, co), np.full(4, dphi), wls], -1)
        err_d = max(err_d, np.abs(np.array(got_d) - kd_ref(pts)).max())
    assert err_r < 1e-12 and err_d < 1e-12


def test_clamped_outside_grids_and_below_horizon():
    t = _tables()
    surf = TableSurface(t)
    assert surf.specular(1.0, [300.0, 900.0]) == pytest.approx([t.k_r[-1, 0], t.k_r[-1, -1]], abs=1e-15)
    assert surf.specular(1e-3, [t.wavelength_nm[2]]) == pytest.approx([t.k_r[0, 2]], abs=1e-15)
    assert surf.specular(-0.2, [500.0]) == [0.0]
    assert surf.brdf((0, 0, 1.0), (0.6, 0, -0.8), [500.0]) == [0.0]


def test_azimuth_convention():
    """φ = 0 on the forward (specular) side, π back towards the source (_render_tables)."""
    wi = _direction(0.8, 0.3)
    mirror = (-wi[0], -wi[1], wi[2])
    assert _azimuth(wi, mirror) == pytest.approx(0.0, abs=1e-7)
    assert _azimuth(wi, _direction(0.5, 0.3)) == pytest.approx(math.pi)
    assert _azimuth(wi, _direction(0.5, 0.3 + math.pi + 1.0)) == pytest.approx(1.0)
    assert _azimuth(wi, _direction(0.5, 0.3 + math.pi - 1.0)) == pytest.approx(1.0)
    assert _azimuth((0, 0, 1.0), _direction(0.5, 2.0)) == 0.0


def _hemisphere_integral(fn, n_mu=200, n_phi=400):
    """∫ fn(wo) dω over the upper hemisphere by the midpoint rule in (cos θ, φ)."""
    mu = (np.arange(n_mu) + 0.5) / n_mu
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    total = 0.0
    for m in mu:
        for p in phi:
            total += fn(_direction(m, p))
    return total * (1.0 / n_mu) * (2 * np.pi / n_phi)


@pytest.mark.parametrize("cos_v", [0.93, 0.4])
def test_pdf_normalized_and_sampling_unbiased(cos_v):
    """The lobe is sampled for a light direction given the view: the pdf integrates to 1 over the
    light's hemisphere, and the mean of k_d(light → view) cos θ_l / pdf over drawn light
    directions is the albedo seen from the view (quadrature)."""
    t = _tables(seed=3, L=3)
    surf = TableSurface(t)
    view = _direction(cos_v, 0.7)
    wls = [450.0, 550.0, 650.0]
    norm = _hemisphere_integral(lambda light: surf.lobe_pdf(view, light), 100, 200)
    assert norm == pytest.approx(1.0, abs=2e-3)
    albedo = _hemisphere_integral(lambda light: surf.brdf(light, view, wls)[1] * light[2], 100, 200)
    rng = np.random.default_rng(4)
    n = 40000
    u = rng.random((n, 3))
    est = np.empty(n)
    for j in range(n):
        light = surf.sample_lobe(view, u[j, 0], (u[j, 1], u[j, 2]))
        pdf = surf.lobe_pdf(view, light)
        est[j] = surf.brdf(light, view, wls)[1] * light[2] / pdf if pdf > 0 else 0.0
    sigma = est.std() / math.sqrt(n)
    assert abs(est.mean() - albedo) < 4 * sigma + 2e-3 * albedo


def test_sampling_follows_the_light_given_the_view():
    """For a table that depends on the light only through a narrow band of incidence angles
    (k_d > 0 only for θ_l near 60°), every light direction drawn by the table part of the
    sampler lies in that band, whatever the view: the density is built over the incidence axis."""
    t = _tables(seed=5, A=10, B=6, P=5, L=3)
    ct = np.cos(np.radians(np.linspace(85.0, 0.0, 10)))
    band = np.abs(np.degrees(np.arccos(ct)) - 56.7) < 10.0
    k_d = np.where(band[:, None, None, None], 0.05, 0.0) * np.ones((10, 6, 5, 3))
    surf = TableSurface(t._replace(cos_theta=ct, k_d=k_d, k_r=np.zeros((10, 3)), k_t=np.zeros((10, 3)),
                                   wavelength_nm=np.array([400.0, 550.0, 700.0])))
    rng = np.random.default_rng(6)
    lo, hi = ct[band].min(), ct[band].max()
    cell = np.diff(ct).max()
    for cos_v in (0.95, 0.5, 0.15):
        view = _direction(cos_v, 0.2)
        for _ in range(300):
            u = rng.random(3)
            u[0] = DEFENSIVE + (1 - DEFENSIVE) * u[0]  # the table part (not the cosine share)
            light = surf.sample_lobe(view, u[0], (u[1], u[2]))
            assert lo - cell <= light[2] <= hi + cell
            assert surf.lobe_pdf(view, light) > 0


def test_specular_probability_and_flags():
    t = _tables()
    surf = TableSurface(t)
    p = surf.specular_probability(0.7)
    assert 0.0 < p < 1.0
    smooth = TableSurface(t._replace(k_d=np.zeros_like(t.k_d)))
    assert smooth.specular_probability(0.7) == 1.0 and not smooth.has_diffuse
    lobe_only = TableSurface(t._replace(k_r=np.zeros_like(t.k_r)))
    assert lobe_only.specular_probability(0.7) == 0.0 and not lobe_only.has_specular
    assert DEFENSIVE > 0


def test_specular_only_tables():
    t = _tables()
    surf = TableSurface(t._replace(cos_theta_out=np.zeros(0), phi_out=np.zeros(0), k_d=np.zeros((t.k_r.shape[0], 0, 0, t.k_r.shape[1]))))
    assert not surf.has_diffuse and surf.specular_probability(0.5) == 1.0
    assert surf.brdf(_direction(0.5, 0), _direction(0.5, 1), [500.0]) == [0.0]


def test_single_node_grids():
    t = _tables(A=1, B=1, P=1, L=1)
    surf = TableSurface(t)
    assert surf.specular(0.3, [400.0, 700.0]) == pytest.approx([t.k_r[0, 0]] * 2)
    light, view = _direction(0.9, 0.0), _direction(0.2, 2.0)
    assert surf.brdf(light, view, [500.0]) == pytest.approx([t.k_d[0, 0, 0, 0]])
    norm = _hemisphere_integral(lambda w: surf.lobe_pdf(view, w), 400, 40)
    assert norm == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize(
    "field, value, match",
    [
        ("cos_theta", lambda t: t.cos_theta[::-1], "cos_theta must be strictly ascending"),
        ("cos_theta_out", lambda t: t.cos_theta_out + 1.0, "cos_theta_out must lie in"),
        ("phi_out", lambda t: t.phi_out * 2, "phi_out must lie in"),
        ("k_r", lambda t: t.k_r[:, :-1], "k_r must have shape"),
        ("k_d", lambda t: -t.k_d, "k_d must be >= 0"),
        ("k_r", lambda t: np.where(t.k_r > 0.2, np.nan, t.k_r), "k_r contains NaN"),
    ],
)
def test_bad_tables_name_the_field(field, value, match):
    t = _tables()
    with pytest.raises(LayerstackError, match=match):
        TableSurface(t._replace(**{field: value(t)}))


def test_missing_field_and_warnings():
    with pytest.raises(LayerstackError, match="k_d"):
        TableSurface(object())
    t = _tables()
    with pytest.warns(UserWarning, match="k_t is non-zero"):
        TableSurface(t._replace(k_t=np.full_like(t.k_r, 0.1)))
    with pytest.warns(UserWarning, match="creates energy"):
        TableSurface(t._replace(k_d=t.k_d * 50))


def test_teapot_mesh_is_outward_and_well_formed():
    """The generated teapot: indices in range, no degenerate-heavy mesh, and the body's triangles
    wound outwards (positive signed volume by the divergence theorem, close to the volume of
    revolution of its profile is not required: only its sign and magnitude order)."""
    from layerstack_jax.render._scenes import teapot_mesh

    v, f = teapot_mesh(24)
    assert f.min() >= 0 and f.max() < len(v)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert 0.3 < volume < 2.0  # a pot ~1.2 wide and ~1 high, with spout and handle
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    assert np.mean(area < 1e-12) < 0.05


def test_missing_mitsuba_names_the_extra(monkeypatch):
    import sys

    from layerstack_jax.render import coated_bsdf

    monkeypatch.setitem(sys.modules, "mitsuba", None)  # `import mitsuba` raises ImportError
    with pytest.raises(ImportError, match=r"pip install 'layerstack-jax\[render\]'"):
        coated_bsdf(_tables())
