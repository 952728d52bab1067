r"""Design files: ``layerstack design DESIGN.toml -o design.toml``.

A design file is a stack file (:mod:`layerstack_jax.io`) whose optimised layers carry
``thickness_nm = { value = ..., free = true, min = ..., max = ... }``, plus ``[[targets]]``, an
optional ``[optimizer]`` and an optional ``[robustness]`` table. This module owns the format (the
stack-file part is :mod:`layerstack_jax.io`'s, read with the same grammar).

Format
------
``layerstack design DESIGN.toml -o design.toml [--plot design.png]`` optimises layer
thicknesses (implementation: :mod:`fitting._design_file` reads the file, :mod:`fitting._design_run`
runs it on :mod:`fitting._design`). A design
file is a stack file — same ``description``, ``[ambient]``, ``[[layers]]``, ``[substrate]``
tables — whose layers to optimise say so, plus what the coating must do::

    [[layers]]
    name = "MgF2"
    n = { material = "MgF2", source = "Li-o" }
    thickness_nm = { value = 100, free = true, min = 0, max = 400 }   # optimised in [min, max]
    coherent = true                 # (defaults min = 0, max = 1000 nm; a plain number stays fixed)

    [substrate]                     # a specular substrate ([background] is not supported)
    n = 1.52

    [[targets]]                     # one or more; type = "spectral" (default) or "colour"
    name = "visible AR"             # optional, used in the report
    quantity = "R"                  # R, T or A: specular, light from the ambient
    band_nm = [420, 680]            # a band, both ends included ...
    step_nm = 10                    #   ... sampled every step_nm (default 5)
    # wavelength_nm = 550           # ... or one wavelength or a list [450, 550, 650]
    angle_deg = 0                   # angle of incidence or list of angles, degrees (default 0)
    polarization = "natural"        # natural (default), s or p
    value = 0.0                     # aim; passes where |Q − value| <= tolerance everywhere ...
    tolerance = 0.005               #   (default 0.01; also the merit's unit of deviation)
    # max = 0.005 / min = 0.9       # ... or one-sided bound(s): pass where min <= Q <= max
    weight = 1.0                    # weight in the merit (default 1)

    [[targets]]
    type = "colour"                 # CIELAB of the natural-light specular reflectance
    lab = [60.0, 20.0, -30.0]       # target L*, a*, b* (or one triple per angle)
    angle_deg = [0, 45]
    illuminant = "D65"              # colour-science names: D65, D50, A, F2 ... (default D65)
    observer = "2"                  # "2" (CIE 1931, default) or "10" (CIE 1964)
    tolerance = 1.0                 # ΔE2000: passes where ΔE2000 <= tolerance at every angle
    weight = 1.0                    # (step_nm = 5: the 380–780 nm colorimetry grid)

    [optimizer]                     # optional
    method = "scipy"                # L-BFGS-B within the bounds, exact gradients: "scipy" (default:
                                    #   SciPy's, starts in turn, seconds to start) or "jaxopt" (starts
                                    #   vmapped in one compiled solve: many starts, GPU)
    starts = 8                      # the file's thicknesses plus 7 random starts (default 1)
    seed = 0
    max_steps = 500                 # iteration cap per start (default 500)
    gradient_tolerance = 1e-9       # on the projected gradient (default 1e-9)

    [optimizer.needle]              # optional: grow the design by the needle method
    materials = [{ name = "SiO2", n = 1.46 }, { name = "TiO2", n = { material = "TiO2", source = "Sarkar" } }]
    iterations = 3                  # needle insertions at most (default 3)
    min_thickness_nm = 0.5          # thinner films are removed (default 0.5)
    max_thickness_nm = 400          # bound of every film once needles are in (default: largest max)
    max_layers = 12                 # optional cap
    points_per_layer = 32           # needle-function samples per film (default 32)

    [robustness]                    # optional: random thickness errors N(0, (sigma_nm + relative·d)²)
    sigma_nm = 1.0
    relative = 0.01
    samples = 200                   # draws (default 200) → yield = fraction meeting every target
    seed = 0
    optimize = false                # true: minimise the mean merit over the draws (robust design)
    min_yield = 0.9                 # optional requirement on the yield

The merit is Σ weight · mean((Q − value)/tolerance)² over targets (one-sided bounds count only
the excess; colour targets (ΔE2000/tolerance)²). With a needle table every coherent layer
must be free (and no incoherent one): the needle method refines every thin film, first within
the layers' own bounds, then in [0, max_thickness_nm]. Materials (layers and needle
candidates) must cover every target's wavelengths.

The output is a stack file (for :func:`load_stack`, ``layerstack predict``): the layers as
written (database references kept, relative table paths rebased), plain designed thicknesses,
needle layers named after their material, repeated names numbered; its ``#`` header holds the
report — merit before and after, each target's result (mean/min/max of Q, Lab and ΔE2000) and
the yield. ``layerstack design`` exits with status 0 when every target (and ``min_yield``) is
met, 1 when not (the file is still written), 2 for a bad file.


Data flow, one way:

* :func:`load_design` — file → :class:`DesignFile` (the stack, which layers are free and their
  bounds, :class:`DesignTarget` list built on :class:`~fitting.SpectralTarget` /
  :class:`~fitting.ColourTarget`, optimizer, needle and robustness settings); every problem is a
  :class:`~layerstack_jax.LayerstackError` naming the file, table and key;
* :func:`run_design` — :func:`~fitting.optimize_thicknesses` (multi-start L-BFGS-B), then
  optionally :func:`~fitting.needle_design` and a robust refinement, then the evaluation of
  every target and the thickness-error yield (:func:`~fitting.thickness_yield`) →
  :class:`DesignOutcome`;
* :func:`design_report` (text), :func:`design_stack_dict` (the designed stack as a stack-file
  dict keeping the materials as written, e.g. database references) and :func:`plot_design`.

Pass/fail ("within spec"): a ``value`` target passes where :math:`|Q - \text{value}| \le`
``tolerance`` at every wavelength and angle; a ``min`` / ``max`` target where
:math:`\text{min} \le Q \le \text{max}` (the ``tolerance`` then only scales the merit); a colour
target where ΔE2000 ≤ ``tolerance`` at every angle. The yield counts the thickness-error draws
whose design passes every target.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Mapping, Optional

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import layerstack_jax as ls
from layerstack_jax import LayerstackError
from layerstack_jax.io import (
    ANNOTATION_KEYS,
    FileLocation,
    is_number,
    named_tables,
    read_material,
    read_number,
    read_toml,
    reject_unknown_keys,
    stack_from_dict,
)

from ._design import RobustSpec
from ._design_targets import ColourTarget, SpectralTarget
from ._fit_file import parameter_of

__all__ = ["DesignTarget", "NeedleSettings", "DesignFile", "load_design", "QUANTITY"]

_DESIGN_KEYS = ("targets", "optimizer", "robustness")
_SPECTRAL_KEYS = ("type", "name", "quantity", "wavelength_nm", "band_nm", "step_nm", "angle_deg", "polarization",
                  "value", "min", "max", "tolerance", "weight")
_COLOUR_KEYS = ("type", "name", "lab", "angle_deg", "illuminant", "observer", "step_nm", "tolerance", "weight")
_OPTIMIZER_KEYS = ("method", "starts", "seed", "max_steps", "gradient_tolerance", "needle")
_NEEDLE_KEYS = ("materials", "iterations", "min_thickness_nm", "max_thickness_nm", "max_layers", "points_per_layer")
_ROBUST_KEYS = ("sigma_nm", "relative", "samples", "seed", "optimize", "min_yield")
_DEFAULT_MAX_NM = 1000.0
_BOUND_SLACK = 1e-9  # a min/max target passes up to this rounding slack
QUANTITY = {"R": "reflectance", "T": "transmittance", "A": "absorptance"}


# ---------------------------------------------------------------------------- the model
class DesignTarget(eqx.Module):
    """One ``[[targets]]`` entry: the library targets it stands for.

    ``parts``: the targets whose merits add up (a ``min`` + ``max`` band is a 'below' and an
    'above' :class:`SpectralTarget`); ``checks``: the same with a one-sided bound's tolerance
    shrunk to rounding, so that ``within_spec`` means min ≤ Q ≤ max; ``spec``: the pass
    criterion in words.
    """

    name: str = eqx.field(static=True)
    parts: tuple
    checks: tuple
    spec: str = eqx.field(static=True)

    @property
    def is_colour(self) -> bool:
        return isinstance(self.parts[0], ColourTarget)


@dataclasses.dataclass(frozen=True)
class NeedleSettings:
    """``[optimizer.needle]``: candidate materials (with their stack-file specs and names)."""

    materials: tuple
    names: tuple
    specs: tuple  # stack-file entries {n[, k]} of the candidates
    iterations: int
    min_thickness_nm: float
    max_thickness_nm: float
    max_layers: Optional[int]
    points_per_layer: int


@dataclasses.dataclass(frozen=True)
class DesignFile:
    """A parsed design file. Layers of ``stack`` are named by keys of ``layer_specs`` (``"L0"``,
    ``"L1"``… for the file's layers, ``"N0"``… for needle materials) so that a designed stack,
    however grown, maps back to the tables the file wrote."""

    path: Path
    description: str
    stack: ls.Stack
    raw: dict  # the stack part of the file (ambient, layers, substrate, description)
    layer_specs: dict  # key -> (display name, stack-file layer table without thickness)
    free: tuple
    lower_nm: np.ndarray
    upper_nm: np.ndarray
    targets: tuple
    method: str = "scipy"
    starts: int = 1
    seed: int = 0
    max_steps: int = 500
    gradient_tolerance: float = 1e-9
    needle: Optional[NeedleSettings] = None
    robustness: Optional[RobustSpec] = None
    optimize_robust: bool = False
    min_yield: Optional[float] = None

    @property
    def library_targets(self) -> list:
        return [p for t in self.targets for p in t.parts]

    @property
    def check_targets(self) -> list:
        return [c for t in self.targets for c in t.checks]


# ------------------------------------------------------------------------------- parsing
def _table(where: FileLocation, d: Mapping, key: str) -> Mapping:
    t = d.get(key, {})
    if not isinstance(t, Mapping):
        raise where.error(f"must be a table [{key}], got {t!r}", key)
    return t


def _integer(where: FileLocation, key: str, x, minimum: int) -> int:
    if not isinstance(x, int) or isinstance(x, bool) or x < minimum:
        raise where.error(f"must be an integer >= {minimum}, got {x!r}", key)
    return int(x)


def _boolean(where: FileLocation, key: str, x) -> bool:
    if not isinstance(x, bool):
        raise where.error(f"must be true or false, got {x!r}", key)
    return x


def _string(where: FileLocation, key: str, x) -> str:
    if not isinstance(x, str) or not x.strip():
        raise where.error(f"must be a non-empty string, got {x!r}", key)
    return x.strip()


def _numbers(where: FileLocation, key: str, x, what: str) -> np.ndarray:
    """A number or a non-empty list of finite numbers, as a 1-D array."""
    values = [x] if is_number(x) else x
    if not isinstance(values, list) or not values or not all(is_number(v) for v in values):
        raise where.error(f"must be a number or a non-empty list of numbers ({what}), got {x!r}", key)
    a = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(a)):
        raise where.error(f"must be finite ({what}), got {x!r}", key)
    return a


def _angles(where: FileLocation, t: Mapping) -> np.ndarray:
    a = _numbers(where, "angle_deg", t.get("angle_deg", 0.0), "angles of incidence in degrees")
    if np.any(a < 0) or np.any(a >= 90):
        raise where.error(f"angles must lie in [0, 90) degrees, got {a.tolist()}", "angle_deg")
    return a


def _grid(where: FileLocation, t: Mapping) -> np.ndarray:
    """``wavelength_nm`` (number or list) or ``band_nm = [lo, hi]`` with ``step_nm``."""
    if ("wavelength_nm" in t) == ("band_nm" in t):
        raise where.error("give exactly one of wavelength_nm = 550 / [450, 550, 650] or band_nm = [lo, hi] "
                          "(with step_nm)")
    if "wavelength_nm" in t:
        if "step_nm" in t:
            raise where.error("step_nm goes with band_nm, not with wavelength_nm", "step_nm")
        wl = _numbers(where, "wavelength_nm", t["wavelength_nm"], "nm")
        if np.any(wl <= 0) or np.any(np.diff(wl) <= 0):
            raise where.error(f"wavelengths must be > 0 nm and increase strictly, got {wl.tolist()}", "wavelength_nm")
        return wl
    band = _numbers(where, "band_nm", t["band_nm"], "[lo, hi] in nm")
    if band.size != 2:
        raise where.error(f"must be [lo, hi] in nm, got {t['band_nm']!r}", "band_nm")
    lo, hi = band
    if lo <= 0 or not hi > lo:
        raise where.error(f"band inverted or empty: lo {lo:g} nm must be > 0 and < hi {hi:g} nm", "band_nm")
    step = read_number(where, "step_nm", t.get("step_nm", 5.0), positive=True, what="nm")
    wl = lo + step * np.arange(int(math.floor((hi - lo) / step + 1e-9)) + 1)
    return wl if abs(wl[-1] - hi) <= 1e-9 * hi else np.append(wl, hi)  # both band edges are targets


def _per_wavelength(where: FileLocation, key: str, x, n_wl: int) -> np.ndarray:
    v = _numbers(where, key, x, f"one number, or one per wavelength ({n_wl})")
    if v.size not in (1, n_wl):
        raise where.error(f"has {v.size} values for {n_wl} wavelengths", key)
    if np.any(v < 0) or np.any(v > 1):
        raise where.error(f"R, T and A are fractions in [0, 1] (not %), got {v.tolist()}", key)
    return v if v.size > 1 else v[0]


def _fmt_values(v) -> str:
    return f"{float(v):g}" if np.ndim(v) == 0 else "profile"


def _spectral_target(where: FileLocation, t: Mapping, name: str) -> DesignTarget:
    reject_unknown_keys(where, t, _SPECTRAL_KEYS)
    quantity = t.get("quantity", "R")
    if quantity not in QUANTITY:
        raise where.error(f"must be 'R', 'T' or 'A' (specular reflectance, transmittance, absorptance), "
                          f"got {quantity!r}", "quantity")
    polarization = t.get("polarization", "natural")
    if polarization not in ("natural", "s", "p"):
        raise where.error(f"must be 'natural', 's' or 'p', got {polarization!r}", "polarization")
    wl = _grid(where, t)
    angles = _angles(where, t)
    tol = read_number(where, "tolerance", t.get("tolerance", 0.01), positive=True)
    weight = read_number(where, "weight", t.get("weight", 1.0), positive=True)
    given = [k for k in ("value", "min", "max") if k in t]
    if not given:
        raise where.error("missing: give value = ... (with tolerance) or min = ... and/or max = ...", "value")
    if "value" in given and len(given) > 1:
        raise where.error("give either value = ... (two-sided, ± tolerance) or min/max bounds, not both", "value")
    v = {k: _per_wavelength(where, k, t[k], wl.size) for k in given}
    if "min" in v and "max" in v and np.any(np.asarray(v["min"]) > np.asarray(v["max"])):
        raise where.error("min must be <= max", "min")
    common = dict(quantity=quantity, angle_deg=angles, polarization=polarization, weight=weight)
    if "value" in v:
        part = SpectralTarget(jnp.asarray(wl), v["value"], tol, kind="equal", **common)
        return DesignTarget(name, (part,), (part,), f"{quantity} = {_fmt_values(v['value'])} ± {tol:g}")
    parts, checks, spec = [], [], []
    for key, kind, sign in (("min", "above", ">="), ("max", "below", "<=")):
        if key in v:
            parts.append(SpectralTarget(jnp.asarray(wl), v[key], tol, kind=kind, **common))
            checks.append(SpectralTarget(jnp.asarray(wl), v[key], _BOUND_SLACK, kind=kind, **common))
            spec.append(f"{quantity} {sign} {_fmt_values(v[key])}")
    return DesignTarget(name, tuple(parts), tuple(checks), ", ".join(spec))


def _colour_target(where: FileLocation, t: Mapping, name: str) -> DesignTarget:
    reject_unknown_keys(where, t, _COLOUR_KEYS)
    if "lab" not in t:
        raise where.error("missing: the target colour as [L*, a*, b*] (or one triple per angle)", "lab")
    lab = t["lab"]
    rows = lab if isinstance(lab, list) and lab and all(isinstance(r, list) for r in lab) else [lab]
    if not all(isinstance(r, list) and len(r) == 3 and all(is_number(x) for x in r) for r in rows):
        raise where.error(f"must be [L*, a*, b*] or a list of such triples (one per angle), got {lab!r}", "lab")
    lab_a = np.asarray(rows, dtype=float)
    if not np.all(np.isfinite(lab_a)) or np.any(lab_a[:, 0] < 0) or np.any(lab_a[:, 0] > 100):
        raise where.error(f"L* must lie in [0, 100] and all values be finite, got {lab!r}", "lab")
    angles = _angles(where, t)
    if lab_a.shape[0] not in (1, angles.size):
        raise where.error(f"{lab_a.shape[0]} Lab triples for {angles.size} angles", "lab")
    step = read_number(where, "step_nm", t.get("step_nm", 5.0), positive=True, what="nm")
    lo, hi = ls.VISIBLE_RANGE_NM
    wl = lo + step * np.arange(int(math.floor((hi - lo) / step + 1e-9)) + 1)
    if abs(wl[-1] - hi) > 1e-9 * hi:
        wl = np.append(wl, hi)
    illuminant = _string(where, "illuminant", t.get("illuminant", "D65"))
    observer = _string(where, "observer", str(t.get("observer", "2")))
    try:
        cs = ls.ColourSpace(wl, observer, illuminant)
    except LayerstackError as e:
        raise where.error(str(e), "observer" if "observer" in str(e) else "illuminant") from None
    tol = read_number(where, "tolerance", t.get("tolerance", 1.0), positive=True, what="ΔE2000")
    weight = read_number(where, "weight", t.get("weight", 1.0), positive=True)
    part = ColourTarget(cs, lab_a if lab_a.shape[0] > 1 else lab_a[0], angles, tolerance=tol, weight=weight)
    return DesignTarget(name, (part,), (part,), f"ΔE2000 <= {tol:g}")


def _targets(source: str, d: Mapping) -> tuple:
    raw = d.get("targets")
    top = FileLocation(source, "top level")
    if raw is None:
        raise top.error("missing: add at least one [[targets]] table (what the design should achieve)", "targets")
    if isinstance(raw, list) and not raw:
        raise top.error("must be an array of tables, written [[targets]]", "targets")
    out = []
    for i, (t, name, where) in enumerate(named_tables(source, raw, "targets", "target")):
        if "name" not in t:  # an unnamed target is called by its number alone
            where = FileLocation(source, f"[[targets]] no. {i + 1}")
        kind = t.get("type", "spectral")
        if kind == "spectral":
            out.append(_spectral_target(where, t, name))
        elif kind in ("colour", "color"):
            out.append(_colour_target(where, t, name))
        else:
            raise where.error(f"must be 'spectral' or 'colour', got {kind!r}", "type")
    return tuple(out)


def _free_thicknesses(source: str, annotations: list, stack: ls.Stack):
    """Indices and bounds of the layers with ``thickness_nm = { ..., free = true }`` (the file's
    fitting words, read as for a fit: :func:`fitting.parameter_of`)."""
    marked = [(a, p) for a, p in ((a, parameter_of(a)) for a in annotations) if p is not None]
    for a, p in marked:
        if p.kind != "thickness" or p.path[0] != "layers":
            raise LayerstackError(f"{a.where.source}: {a.where.table}: {p.name} is free, but a design optimises "
                                  "layer thicknesses only: mark thickness_nm free and give the others plain values")
    names = [layer.name for layer in stack.layers]
    free, lower, upper = [], [], []
    i = -1
    for _, p in marked:  # in the file's order, one per layer at most: names may repeat (SiO2, TiO2, SiO2 …)
        i = names.index(p.path[1], i + 1)
        where = FileLocation(source, f"[[layers]] no. {i + 1} ({names[i]!r})")
        lo = 0.0 if p.lower is None else float(p.lower)
        hi = _DEFAULT_MAX_NM if p.upper is None else float(p.upper)
        if lo < 0:
            raise where.error(f"min must be >= 0 nm, got {lo:g}", "thickness_nm")
        if not hi > lo:
            raise where.error(f"bounds inverted or empty: min {lo:g} nm, max {hi:g} nm", "thickness_nm")
        d = float(np.asarray(stack.layers[i].thickness))
        if not lo <= d <= hi:
            raise where.error(f"starting value {d:g} nm lies outside [min, max] = [{lo:g}, {hi:g}] nm", "thickness_nm")
        free.append(i)
        lower.append(lo)
        upper.append(hi)
    if not free:
        raise LayerstackError(f"{source}: [[layers]]: key 'thickness_nm': no free layer: mark the layers to optimise "
                              "with thickness_nm = { value = 100, free = true, min = 0, max = 400 }")
    return tuple(free), np.asarray(lower), np.asarray(upper)


def _needle(source: str, t, base_dir: Path, stack: ls.Stack, free: tuple, upper: np.ndarray) -> NeedleSettings:
    where = FileLocation(source, "[optimizer.needle]")
    if not isinstance(t, Mapping):
        raise FileLocation(source, "[optimizer]").error(f"must be a table [optimizer.needle], got {t!r}", "needle")
    reject_unknown_keys(where, t, _NEEDLE_KEYS)
    raw = t.get("materials")
    if not isinstance(raw, list) or not raw or not all(isinstance(m, Mapping) for m in raw):
        raise where.error("must be a non-empty list of materials such as [{ name = \"SiO2\", n = 1.46 }, "
                          "{ name = \"TiO2\", n = { material = \"TiO2\", source = \"Devore-o\" } }]", "materials")
    materials, names, specs = [], [], []
    for i, m in enumerate(raw):
        mw = FileLocation(source, f"[optimizer.needle]: materials no. {i + 1}")
        reject_unknown_keys(mw, m, ("name", "n", "k"))
        materials.append(read_material(mw, m, base_dir, allow_k=True, label=f"needle material {i + 1}"))
        n = m.get("n")
        default = (n.get("material") if isinstance(n, Mapping) and isinstance(n.get("material"), str)
                   else f"n={n:g}" if is_number(n) else f"needle material {i + 1}")
        names.append(_string(mw, "name", m.get("name", default)))
        specs.append({k: m[k] for k in ("n", "k") if k in m})
    for i, layer in enumerate(stack.layers):
        if layer.coherent != (i in free):
            what = "coherent (a thin film) but its thickness is not free" if layer.coherent else "incoherent but free"
            raise FileLocation(source, f"[[layers]] no. {i + 1} ({layer.name!r})").error(
                f"is {what}: the needle method refines the thickness of every thin film and only those; mark each "
                "coherent layer thickness_nm = { value = ..., free = true }", "thickness_nm")
    max_nm = read_number(where, "max_thickness_nm", t.get("max_thickness_nm", float(np.max(upper))), positive=True,
                     what="nm")
    if max_nm < np.max(upper):
        raise where.error(f"must be >= every free layer's max ({np.max(upper):g} nm): it bounds all films once "
                          "needles are in", "max_thickness_nm")
    max_layers = t.get("max_layers")
    return NeedleSettings(
        materials=tuple(materials), names=tuple(names), specs=tuple(specs),
        iterations=_integer(where, "iterations", t.get("iterations", 3), 1),
        min_thickness_nm=read_number(where, "min_thickness_nm", t.get("min_thickness_nm", 0.5), minimum=0.0, what="nm"),
        max_thickness_nm=max_nm,
        max_layers=None if max_layers is None else _integer(where, "max_layers", max_layers, len(stack.layers) + 2),
        points_per_layer=_integer(where, "points_per_layer", t.get("points_per_layer", 32), 1),
    )


def _check_grids(source: str, stack: ls.Stack, targets: tuple, needle: Optional[NeedleSettings]) -> None:
    """Every material covers every target's wavelengths (tables are never extrapolated)."""
    for i, target in enumerate(targets):
        part = target.parts[0]
        wl = np.asarray(part.colour_space.wavelength_nm if target.is_colour else part.wavelength_nm)
        candidates = zip(needle.names, needle.materials) if needle else ()
        try:
            ls.check_stack(stack, wl)
            for name, m in candidates:
                try:
                    m(wl)
                except LayerstackError as e:
                    raise LayerstackError(f"needle material {name!r}: {e}") from None
        except LayerstackError as e:
            grid = f"wavelength grid {wl[0]:g}–{wl[-1]:g} nm"
            raise LayerstackError(f"{source}: [[targets]] no. {i + 1}: {grid}: {e}") from None


def _layer_spec(t: Mapping) -> dict:
    """A file's layer table without its thickness and free-parameter keys."""
    def plain(spec):
        words = ("value",) + ANNOTATION_KEYS
        if isinstance(spec, Mapping) and any(k in spec for k in words):
            return spec["value"] if "value" in spec else {k: v for k, v in spec.items() if k not in words}
        return spec

    return {k: plain(v) for k, v in t.items() if k not in ("thickness_nm", "name")}


def load_design(path) -> DesignFile:
    """Read a design file (format: :mod:`layerstack_jax.io` docstring, "Design files")."""
    path = Path(path)
    source = str(path)
    d = read_toml(path, "design file")
    raw = {k: v for k, v in d.items() if k not in _DESIGN_KEYS}
    annotations: list = []
    stack = stack_from_dict(raw, path.parent, source=source, annotations=annotations)
    if stack.exit.diffuse:
        raise FileLocation(source, "[background]").error(
            "design targets are specular R / T / A of films on a [substrate]; a Lambertian [background] "
            "is not supported")
    raw_layers = raw.get("layers", [])
    free, lower, upper = _free_thicknesses(source, annotations, stack)
    targets = _targets(source, d)

    top = FileLocation(source, "top level")
    opt = _table(top, d, "optimizer")
    ow = FileLocation(source, "[optimizer]")
    reject_unknown_keys(ow, opt, _OPTIMIZER_KEYS)
    method = opt.get("method", "scipy")
    if method not in ("scipy", "jaxopt"):
        raise ow.error(f"must be 'scipy' (SciPy's L-BFGS-B, starts in turn) or 'jaxopt' (jaxopt's L-BFGS-B, "
                       f"starts vmapped), got {method!r}", "method")
    needle = _needle(source, opt["needle"], path.parent, stack, free, upper) if "needle" in opt else None
    _check_grids(source, stack, targets, needle)

    robust, optimize_robust, min_yield = None, False, None
    if "robustness" in d:
        rob = _table(top, d, "robustness")
        rw = FileLocation(source, "[robustness]")
        reject_unknown_keys(rw, rob, _ROBUST_KEYS)
        sigma = read_number(rw, "sigma_nm", rob.get("sigma_nm", 0.0), minimum=0.0, what="nm")
        rel = read_number(rw, "relative", rob.get("relative", 0.0), minimum=0.0, what="fraction of the thickness")
        if sigma == 0 and rel == 0:
            raise rw.error("give the thickness errors: sigma_nm (nm) and/or relative (fraction) > 0", "sigma_nm")
        robust = RobustSpec(sigma, rel, _integer(rw, "samples", rob.get("samples", 200), 1),
                            _integer(rw, "seed", rob.get("seed", 0), 0))
        optimize_robust = _boolean(rw, "optimize", rob.get("optimize", False))
        if "min_yield" in rob:
            min_yield = read_number(rw, "min_yield", rob["min_yield"], minimum=0.0, maximum=1.0, what="fraction")

    keyed = [ls.Layer(layer.index, layer.thickness, coherent=layer.coherent, alpha=layer.alpha, name=f"L{i}")
             for i, layer in enumerate(stack.layers)]
    specs = {f"L{i}": (layer.name, _layer_spec(t)) for i, (layer, t) in enumerate(zip(stack.layers, raw_layers))}
    if needle:
        for m, (name, spec) in enumerate(zip(needle.names, needle.specs)):
            specs[f"N{m}"] = (name, {**spec, "coherent": True})
    description = d.get("description", "")
    return DesignFile(
        path=path, description=description, stack=ls.Stack(stack.ambient, keyed, stack.exit), raw=raw,
        layer_specs=specs, free=free, lower_nm=lower, upper_nm=upper, targets=targets,
        method=method,
        starts=_integer(ow, "starts", opt.get("starts", 1), 1),
        seed=_integer(ow, "seed", opt.get("seed", 0), 0),
        max_steps=_integer(ow, "max_steps", opt.get("max_steps", 500), 1),
        gradient_tolerance=read_number(ow, "gradient_tolerance", opt.get("gradient_tolerance", 1e-9), positive=True),
        needle=needle, robustness=robust, optimize_robust=optimize_robust, min_yield=min_yield,
    )
