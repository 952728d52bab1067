"""Helpers shared by the commands: precision switch, argument types, geometry columns, plots."""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path

import numpy as np

from layerstack_jax import BRDF, Directional, Index, LambertianBackground, LayerstackError, Specular, Sphere, Stack, \
    Tabulated, parse_geometry

PROG = "layerstack"

@contextlib.contextmanager
def _precision(float32: bool):
    """float64 unless ``float32``; restores the previous JAX setting afterwards."""
    import jax

    previous = bool(jax.config.read("jax_enable_x64"))
    jax.config.update("jax_enable_x64", not float32)
    try:
        yield
    finally:
        jax.config.update("jax_enable_x64", previous)


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def _parse_geometries(texts: list[str]) -> list[tuple[str, object]]:
    """``[(column name, Geometry)]`` for the requested geometries, validated before any work.

    ``specular:θ`` expands into three columns ``R_θ, T_θ, A_θ``; ``specular:θ:Q`` gives ``Q_θ``.
    Other geometries give one column named after the geometry string.
    """
    columns: list[tuple[str, object]] = []
    for text in texts:
        text = text.strip()
        g = parse_geometry(text)  # raises LayerstackError with the list of accepted forms
        angles = (g.angle_deg,) if isinstance(g, Specular) else (g.incidence_deg,) if isinstance(g, Sphere) else (
            g.incidence_deg,
            g.viewing_deg,
        )
        for a in angles:
            if not 0.0 <= float(a) < 90.0:
                raise LayerstackError(f"geometry {text!r}: angles must lie in [0, 90) degrees, got {float(a):g}")
        if isinstance(g, Specular):
            parts = text.split(":")
            angle = parts[1].strip()
            quantities = ("R", "T", "A") if len(parts) == 2 else (g.quantity,)
            columns += [(f"{q}_{angle}", Specular(g.angle_deg, q)) for q in quantities]
        else:
            columns.append((text, g))
    names = [name for name, _ in columns]
    for name in names:
        if names.count(name) > 1:
            raise LayerstackError(f"geometry {name!r} requested twice")
    return columns


def _describe(stack: Stack) -> str:
    """One-line summary of a stack for plot titles: ``air | SiO2 120 nm | substrate``."""

    def index(m):
        if isinstance(m, Index) and np.ndim(m.n) == 0:
            return f"n={float(np.asarray(m.n)):g}"
        if isinstance(m, Tabulated):
            return m.name.split(" (")[0]
        return type(m).__name__

    parts = [f"ambient {index(stack.ambient)}"]
    for layer in stack.layers:
        d = float(np.asarray(layer.thickness))
        size = f"{d / 1000:g} µm" if d >= 1000 else f"{d:g} nm"
        parts.append(f"{layer.name or 'layer'} {size}{'' if layer.coherent else ' (incoherent)'}")
    if isinstance(stack.exit, LambertianBackground):
        parts.append(f"Lambertian background {index(stack.exit.index)}")
    else:
        parts.append(f"substrate {index(stack.exit.index)}")
    return " | ".join(parts)


def _quantity_label(geometry) -> str:
    if geometry is None:  # --ellipsometry columns
        return "degrees"
    if isinstance(geometry, BRDF):
        return "BRDF (1/sr)"
    if isinstance(geometry, Directional):
        return "reflectance factor"
    if isinstance(geometry, Sphere):
        return "reflectance"
    return {"R": "reflectance", "T": "transmittance", "A": "absorptance"}[geometry.quantity]


def _plot(path: Path, wavelength, columns: dict, geometries: dict, title: str, subtitle: str) -> None:
    """Spectra as a PNG (matplotlib object API with the Agg canvas: no global backend change)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 4.8), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    brdf = [name for name in columns if isinstance(geometries[name], BRDF)]
    others = [name for name in columns if name not in brdf]
    ax_brdf = ax if not others else (ax.twinx() if brdf else None)
    styles = {"R": "-", "T": "--", "A": ":"}
    lines = []
    for i, name in enumerate(others + brdf):
        g = geometries[name]
        target = ax_brdf if name in brdf else ax
        style = styles[g.quantity] if isinstance(g, Specular) else "-"
        label = f"{name} ({_quantity_label(g)})" if name in brdf and others else name
        (line,) = target.plot(wavelength, columns[name], style, color=f"C{i}", lw=1.8, label=label)
        lines.append(line)
    kinds = list(dict.fromkeys(_quantity_label(geometries[n]) for n in others))
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel(" / ".join(kinds) if others else "BRDF (1/sr)")
    if brdf and others:
        ax_brdf.set_ylabel("BRDF (1/sr)")
        ax_brdf.set_ylim(bottom=0)
    if len(wavelength) > 1:
        ax.set_xlim(float(wavelength[0]), float(wavelength[-1]))
    lo = min(float(np.nanmin(columns[n])) for n in (others or brdf))
    ax.set_ylim(bottom=min(0.0, lo))
    ax.grid(True, alpha=0.3)
    ax.legend(handles=lines, loc="best", frameon=False)
    ax.set_title(f"{title}\n{subtitle}", fontsize=10)
    fig.savefig(path)


