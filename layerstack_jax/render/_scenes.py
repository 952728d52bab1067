r"""Scenes of Hirayama et al.'s Figs. 8–9 for Mitsuba 3: spheres, a cylinder and a teapot under a
fluorescent lamp.

Fig. 8: two spheres side by side, the left one coated, the right one bare, for σ0 = 0, 25,
50 nm (τ = 300 nm). Fig. 9 (Table 1): a teapot (Al), a cylinder (Si) and a sphere (Cu), each
coated. The paper lights them with "a fluorescent lamp (N)" (Japanese neutral white,
≈ 5000 K); we take the CIE F-series illuminant of that colour temperature, FL8 (5000 K),
from colour-science (:func:`fluorescent_spectrum`).

The lamp is a large rectangular area emitter (5 m × 2 m) above and in front of the objects, plus
a dim uniform surround of the same spectrum (what the smooth, mirror-like objects reflect away
from the lamp), over a grey diffuse floor. A large, moderately bright lamp rather than a small
intense one: the floor's caustics (lamp → sphere → floor) and the lamp's mirror images are then
sampled without fireflies. By default the lamp's spectrum is carried by the camera's spectral
response and the emitters are flat — the same image in expectation, less colour noise
(:func:`camera`) — and the samples are stratified (``multijitter``). Scenes are plain Mitsuba dictionaries (``mi.load_dict``); the BSDFs
are passed in (:func:`layerstack_jax.render.coated_bsdf`, or any Mitsuba BSDF).

The teapot is no scanned mesh: it is generated here (no mesh file to license) as a surface of
revolution for the body, lid and knob, a swept tube for the spout and a torus arc for the
handle (:func:`teapot_mesh`), written as a PLY file.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from .._base.validate import LayerstackError
from ._mitsuba import import_mitsuba

__all__ = ["fluorescent_spectrum", "teapot_mesh", "write_ply", "fig8_scene", "fig9_scene", "lamp_emitters", "camera"]

#: CIE F-series illuminant used for the paper's "fluorescent lamp (N)" (neutral white, 5000 K).
LAMP = "FL8"


def fluorescent_spectrum(name: str = LAMP, scale: float = 1.0) -> dict:
    """A CIE F-series illuminant (colour-science's ``SDS_ILLUMINANTS[name]``, 380–780 nm, 5 nm)
    as a Mitsuba ``irregular`` spectrum, normalized to 1 at its mean over 380–780 nm and
    multiplied by ``scale`` (radiance in W/(m² sr nm) or irradiance, as the emitter reads it)."""
    try:
        import colour
    except ImportError as err:  # pragma: no cover
        raise ImportError("fluorescent_spectrum needs colour-science: pip install 'layerstack-jax[render]'") from err
    if name not in colour.SDS_ILLUMINANTS or not name.startswith("FL"):
        raise LayerstackError(f"name must be a CIE F-series illuminant of colour-science (FL1 … FL12, FL3.x), got {name!r}")
    sd = colour.SDS_ILLUMINANTS[name]
    values = np.asarray(sd.values, float)
    values = scale * values / values.mean()
    return {
        "type": "irregular",
        "wavelengths": ", ".join(f"{w:g}" for w in sd.wavelengths),
        "values": ", ".join(f"{v:.6g}" for v in values),
    }


# -- geometry --------------------------------------------------------------------------------
def _revolve(profile: np.ndarray, n_around: int):
    """Surface of revolution about z of a polyline ``profile`` ``(n, 2)`` of (radius, z):
    vertices ``(n * n_around, 3)`` and triangles ``(2 (n - 1) n_around, 3)``."""
    phi = np.linspace(0.0, 2.0 * np.pi, n_around, endpoint=False)
    r, z = profile[:, 0:1], profile[:, 1:2]
    v = np.stack([r * np.cos(phi), r * np.sin(phi), np.broadcast_to(z, (len(profile), n_around))], axis=-1).reshape(-1, 3)
    return v, _grid_faces(len(profile), n_around, wrap=True)


def _grid_faces(n_rows: int, n_cols: int, wrap: bool):
    """Two triangles per quad of a row-major vertex grid (columns wrap around if ``wrap``)."""
    faces = []
    cols = n_cols if wrap else n_cols - 1
    for i in range(n_rows - 1):
        for j in range(cols):
            a, b = i * n_cols + j, i * n_cols + (j + 1) % n_cols
            c, d = a + n_cols, b + n_cols
            faces += [(a, b, d), (a, d, c)]
    return np.asarray(faces, dtype=np.int64)


def _tube(center: np.ndarray, radius: np.ndarray, n_around: int):
    """A tube of varying ``radius`` ``(n,)`` swept along the polyline ``center`` ``(n, 3)``
    (rotation-minimizing frames)."""
    t = np.gradient(center, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    ref = np.array([0.0, 1.0, 0.0]) if abs(t[0, 1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(t[0], ref)
    u /= np.linalg.norm(u)
    rings = []
    phi = np.linspace(0.0, 2.0 * np.pi, n_around, endpoint=False)
    for k in range(len(center)):
        u = u - np.dot(u, t[k]) * t[k]
        u /= np.linalg.norm(u)
        w = np.cross(t[k], u)
        rings.append(center[k] + radius[k] * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w))
    return np.concatenate(rings), _grid_faces(len(center), n_around, wrap=True)


def teapot_mesh(resolution: int = 48):
    """A teapot of height ~1.3 (z up, standing on z = 0, spout towards +x): ``(vertices (V, 3),
    faces (F, 3))``, triangles wound with outward normals for the body.

    Body and lid: a surface of revolution of a smooth profile (the classic pot shape: wide belly,
    narrower shoulder, flat lid with a knob); spout: a tube tapering along a curve from the
    belly upwards; handle: a tube along a C-shaped arc at the back. ``resolution``: vertices
    around the body (the other counts follow it).
    """
    n = max(int(resolution), 8)
    s = np.linspace(0.0, 1.0, 2 * n)
    # body: bottom disc edge → belly → shoulder → rim, as radius(z)
    z_body = 0.9 * s
    r_body = 0.05 + 0.62 * np.sin(np.pi * (0.12 + 0.8 * s)) ** 0.8 * (1.0 - 0.25 * s)
    r_body[0] = 0.0  # closed bottom
    z_body[0] = 0.0
    # lid: from the rim inwards and up to a knob
    t = np.linspace(0.0, 1.0, n)
    r_lid = r_body[-1] * (1.0 - t) + 0.06 * t
    z_lid = 0.9 + 0.12 * np.sin(0.5 * np.pi * t)
    tk = np.linspace(0.0, 1.0, n // 2)
    r_knob = 0.06 + 0.06 * np.sin(np.pi * tk)
    r_knob[-1] = 0.0
    z_knob = 1.02 + 0.14 * tk
    profile = np.concatenate([np.stack([r_body, z_body], 1), np.stack([r_lid, z_lid], 1)[1:], np.stack([r_knob, z_knob], 1)[1:]])
    v_body, f_body = _revolve(profile, 2 * n)
    # spout: quadratic Bézier from the belly (+x) up and out
    u = np.linspace(0.0, 1.0, n)[:, None]
    p0, p1, p2 = np.array([0.55, 0.0, 0.35]), np.array([0.95, 0.0, 0.45]), np.array([1.1, 0.0, 0.85])
    spout = (1 - u) ** 2 * p0 + 2 * u * (1 - u) * p1 + u**2 * p2
    v_spout, f_spout = _tube(spout, 0.13 - 0.08 * u[:, 0], n // 2)
    # handle: C-shaped arc at the back (-x)
    a = np.linspace(-0.45 * np.pi, 0.45 * np.pi, n)
    handle = np.stack([-0.62 - 0.28 * np.cos(a), np.zeros_like(a), 0.5 + 0.3 * np.sin(a)], axis=1)
    v_handle, f_handle = _tube(handle, np.full(n, 0.05), n // 3)
    vertices = np.concatenate([v_body, v_spout, v_handle])
    faces = np.concatenate([f_body, f_spout + len(v_body), f_handle + len(v_body) + len(v_spout)])
    return vertices, faces


def write_ply(path: str, vertices: np.ndarray, faces: np.ndarray) -> str:
    """Write a binary little-endian PLY of float32 vertices and int32 triangles; returns ``path``."""
    v = np.ascontiguousarray(vertices, dtype="<f4")
    f = np.ascontiguousarray(faces, dtype="<i4")
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode("ascii")
    with open(path, "wb") as out:
        out.write(header)
        out.write(v.tobytes())
        rows = np.empty(len(f), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
        rows["n"], rows["idx"] = 3, f
        out.write(rows.tobytes())
    return path


def _teapot_file(resolution: int) -> str:
    """The teapot written afresh for this process (a temporary PLY file: Mitsuba loads meshes
    from files)."""
    path = os.path.join(tempfile.gettempdir(), f"layerstack_teapot_{resolution}_{os.getpid()}.ply")
    return write_ply(path, *teapot_mesh(resolution))


# -- lights, camera, scenes -------------------------------------------------------------------
def _uniform(value: float) -> dict:
    return {"type": "uniform", "value": float(value)}


def lamp_emitters(lamp: str = LAMP, lamp_radiance: float = 1.5, surround: float = 0.2, size=(5.0, 2.0),
                  spectrum_in_sensor: bool = False) -> dict:
    """The fluorescent lamp: a ``size`` (m) rectangle above and in front of the objects (radiance
    ``lamp_radiance`` × the normalized spectrum) and a uniform surround of ``surround`` × the
    same spectrum.

    ``spectrum_in_sensor``: the emitters are spectrally flat and the lamp's spectrum is left for
    the sensor's spectral response (:func:`camera`'s ``srf``): the same image in expectation,
    because every light source has that spectrum (see :func:`camera`)."""
    mi, _ = import_mitsuba()
    T = mi.ScalarTransform4f
    spectrum = (lambda x: _uniform(x)) if spectrum_in_sensor else (lambda x: fluorescent_spectrum(lamp, x))
    return {
        "lamp": {
            "type": "rectangle",
            "to_world": T().look_at(origin=[0.0, -2.5, 3.2], target=[0.0, 0.0, 0.3], up=[0, 0, 1])
            @ T().scale([0.5 * size[0], 0.5 * size[1], 1.0]),
            "emitter": {"type": "area", "radiance": spectrum(lamp_radiance)},
        },
        "surround": {"type": "constant", "radiance": spectrum(surround)},
    }


def camera(width: int, height: int, spp: int, origin=(0.0, -6.0, 2.0), target=(0.0, 0.0, 0.6), fov: float = 28.0,
           sampler: str = "multijitter", lamp: str | None = None) -> dict:
    """A perspective camera with an ``hdrfilm`` (linear sRGB output) and a ``sampler``
    (``"multijitter"``: stratified, jittered samples in every dimension — which lobe the coated
    BSDF picks, the wavelengths, the pixel position — far less noise than ``"independent"`` at
    the same samples per pixel).

    ``lamp``: a CIE F-series name puts that spectrum in the sensor's spectral response (``srf``):
    the camera weighs what it receives by the lamp's spectrum and draws its wavelengths from
    it. In a scene whose every emitter is spectrally flat (``lamp_emitters(...,
    spectrum_in_sensor=True)``) and lit by nothing else, the image equals, in expectation, that of
    emitters with the lamp's spectrum (the transport is linear in the emitted spectrum), with
    less colour noise: the wavelengths follow the lamp's mercury lines instead of missing them."""
    mi, _ = import_mitsuba()
    sensor = {
        "type": "perspective",
        "fov": fov,
        "to_world": mi.ScalarTransform4f().look_at(origin=list(origin), target=list(target), up=[0, 0, 1]),
        "film": {"type": "hdrfilm", "width": int(width), "height": int(height), "rfilter": {"type": "gaussian"}},
        "sampler": {"type": sampler, "sample_count": int(spp)},
    }
    if lamp is not None:
        sensor["srf"] = fluorescent_spectrum(lamp, 1.0)
    return sensor


def _floor() -> dict:
    mi, _ = import_mitsuba()
    return {
        "type": "rectangle",
        "to_world": mi.ScalarTransform4f().scale([20.0, 20.0, 1.0]),
        "bsdf": {"type": "diffuse", "reflectance": _uniform(0.25)},
    }


def fig8_scene(coated, bare, *, width: int = 160, height: int = 96, spp: int = 16, max_depth: int = 4, floor: bool = True,
               lamp: str = LAMP, sampler: str = "multijitter", spectrum_in_sensor: bool = True) -> dict:
    """Fig. 8: a coated sphere (left) beside a bare one (right), radius 0.6, under the lamp.

    ``coated``, ``bare``: Mitsuba BSDFs (e.g. :func:`coated_bsdf` of the coated and of the bare
    tables). ``lamp``: the CIE F-series illuminant; ``spectrum_in_sensor``: its spectrum carried
    by the sensor rather than by the emitters (the same image, less colour noise: :func:`camera`).
    Returns the scene dictionary for ``mi.load_dict``."""
    mi, _ = import_mitsuba()
    T = mi.ScalarTransform4f
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(max_depth)},
        "sensor": camera(width, height, spp, origin=(0.0, -6.0, 1.6), target=(0.0, 0.0, 0.6), fov=24.0, sampler=sampler,
                         lamp=lamp if spectrum_in_sensor else None),
        "coated": {"type": "sphere", "to_world": T().translate([-0.7, 0.0, 0.6]) @ T().scale(0.6), "bsdf": coated},
        "bare": {"type": "sphere", "to_world": T().translate([0.7, 0.0, 0.6]) @ T().scale(0.6), "bsdf": bare},
        **lamp_emitters(lamp, spectrum_in_sensor=spectrum_in_sensor),
    }
    if floor:
        scene["floor"] = _floor()
    return scene


def fig9_scene(teapot, cylinder, sphere, *, width: int = 192, height: int = 128, spp: int = 16, max_depth: int = 4,
               teapot_resolution: int = 32, lamp: str = LAMP, sampler: str = "multijitter",
               spectrum_in_sensor: bool = True) -> dict:
    """Fig. 9 (Table 1): a teapot (left), a cylinder (middle, capped) and a sphere (right), each
    with its BSDF, under the lamp, on the floor (options as in :func:`fig8_scene`)."""
    mi, _ = import_mitsuba()
    T = mi.ScalarTransform4f
    cyl = T().translate([0.25, 0.9, 0.0]) @ T().scale([0.42, 0.42, 1.1])
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(max_depth)},
        "sensor": camera(width, height, spp, origin=(0.0, -6.5, 2.2), target=(-0.05, 0.3, 0.55), fov=34.0, sampler=sampler,
                         lamp=lamp if spectrum_in_sensor else None),
        "teapot": {"type": "ply", "filename": _teapot_file(teapot_resolution),
                   "to_world": T().translate([-1.35, 0.0, 0.0]) @ T().rotate([0, 0, 1], -30.0) @ T().scale(0.8),
                   "face_normals": False, "bsdf": teapot},
        "cylinder": {"type": "cylinder", "to_world": cyl, "bsdf": cylinder},
        "cylinder_cap": {"type": "disk", "to_world": T().translate([0.25, 0.9, 1.1]) @ T().scale(0.42), "bsdf": cylinder},
        "sphere": {"type": "sphere", "to_world": T().translate([1.35, -0.2, 0.5]) @ T().scale(0.5), "bsdf": sphere},
        "floor": _floor(),
        **lamp_emitters(lamp, spectrum_in_sensor=spectrum_in_sensor),
    }
