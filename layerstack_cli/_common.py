"""Helpers shared by the commands: precision switch, argument types, geometry columns, plots."""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path

import numpy as np

from layerstack_jax import Index, LayerstackError, Stack, Tabulated, parse_geometry

from ._columns import prediction_columns

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


def _positive_int_or_auto(text: str):
    """``"auto"`` or a positive integer (sizes chosen from the memory available, or given)."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return _positive_int(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected 'auto' or a positive integer, got {text!r}") from None


def _parse_geometries(texts: list[str]) -> list[tuple[str, object]]:
    """``[(column name, Geometry)]`` for the requested geometries, validated before any work
    (each geometry names its own columns: ``specular:θ`` gives ``R_θ, T_θ, A_θ``)."""
    columns: list[tuple[str, object]] = []
    for text in texts:
        text = text.strip()
        g = parse_geometry(text)  # raises LayerstackError with the accepted forms, or the bad angle
        columns += prediction_columns(g, text)
    names = [name for name, _ in columns]
    for name in names:
        if names.count(name) > 1:
            raise LayerstackError(f"geometry {name!r} requested twice")
    return columns


def _resolve_geometry(given, stated, *, source: str, origin: str, silent: str):
    """``(Geometry, origin text)`` of measured data: ``given`` (the ``-g`` text) if not None, else
    the one geometry that every spelling in ``stated`` names (a CSV's column names such as
    ``45/0``, a cube's ``geometry`` metadata), described by ``origin``. No silent default (it
    would change the physics): otherwise a :class:`LayerstackError` naming ``source``, listing
    the accepted spellings and saying why (``silent``, e.g. "the column names do not say")."""
    from layerstack_jax import geometry_kinds

    if given is not None:
        return parse_geometry(given), "given (-g)"
    found = set()
    for text in stated:
        try:
            found.add(parse_geometry(text).label)
        except LayerstackError:
            found.add(None)
    if len(found) == 1 and None not in found:
        return parse_geometry(found.pop()), origin
    spellings = ", ".join(k.spelling for k in geometry_kinds() if k.spelling)
    raise LayerstackError(f"{source}: which geometry were these spectra measured in? give -g GEOM ({spellings}); "
                          f"{silent}")


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
    parts.append(f"{stack.exit.label} {index(stack.exit.index)}")
    return " | ".join(parts)


def _quantity_label(geometry) -> str:
    """What a column holds: the geometry's own ``quantity_label``; "degrees" for ψ/Δ columns."""
    return "degrees" if geometry is None else geometry.quantity_label


def _plot(path: Path, wavelength, columns: dict, geometries: dict, title: str, subtitle: str) -> None:
    """Spectra as a PNG (matplotlib object API with the Agg canvas: no global backend change).
    Columns are grouped by what they hold (reflectance, reflectance factor, BRDF (1/sr) …): the
    first group on the left axis, a second on a right axis; legends name the columns."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 4.8), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    kinds = list(dict.fromkeys(_quantity_label(geometries[n]) for n in columns))
    fractions = [k for k in kinds if k in ("reflectance", "transmittance", "absorptance", "reflectance factor")]
    left = fractions or kinds[:1]
    right = [k for k in kinds if k not in left]
    ax_right = ax.twinx() if right else None
    styles = {"transmittance": "--", "absorptance": ":"}
    lines = []
    for i, name in enumerate(columns):
        kind = _quantity_label(geometries[name])
        target = ax if kind in left else ax_right
        label = f"{name} ({kind})" if right else name
        (line,) = target.plot(wavelength, columns[name], styles.get(kind, "-"), color=f"C{i}", lw=1.8, label=label)
        lines.append(line)
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel(" / ".join(left))
    if ax_right is not None:
        ax_right.set_ylabel(" / ".join(right))
    if len(wavelength) > 1:
        ax.set_xlim(float(wavelength[0]), float(wavelength[-1]))
    if all(k != "degrees" for k in left):
        lo = min(float(np.nanmin(columns[n])) for n in columns if _quantity_label(geometries[n]) in left)
        ax.set_ylim(bottom=min(0.0, lo))
    ax.grid(True, alpha=0.3)
    ax.legend(handles=lines, loc="best", frameon=False)
    ax.set_title(f"{title}\n{subtitle}", fontsize=10)
    fig.savefig(path)
