r"""Files: stack descriptions (TOML), spectra (CSV) and wavelength grids.

Stack files
-----------
A stack is described in a TOML file, read with :func:`load_stack` (or, from a dict already in
memory, :func:`stack_from_dict`). Layers are listed from the side the light comes from::

    description = "optional free text"

    [ambient]                 # optional; default: air, n = 1.0
    n = 1.0                   # real (light comes from here): a number or a dispersion (below)

    [[layers]]                # zero or more, top to bottom
    name = "varnish"          # optional; used in messages (default "layer 1", "layer 2" ...)
    n = 1.52                  # refractive index: number or dispersion (below)
    k = 0.0                   # optional extinction coefficient >= 0 (number)
    thickness_nm = 20000      # required, >= 0
    coherent = false          # required: true for a thin film (interference), false for a
                              # thick layer (intensities add; Beer's law)
    alpha_per_nm = 2e-5       # optional, incoherent layers only: absorption coefficient in
                              # 1/nm, a number, { table = "alpha.csv" } (columns
                              # wavelength_nm, alpha_per_nm) or inline
                              # { wavelength_nm = [...], values = [...] }

    [substrate]               # either a specular semi-infinite substrate ...
    n = 1.52                  # number or dispersion (below)
    k = 0.0                   # optional

    [background]              # ... or a Lambertian (diffusing) background: exactly one of the two
    n = 1.5                   # real index of the background's binder
    rho_g = 0.8               # intrinsic reflectance in [0, 1]: a number, { table = "rho.csv" }
                              # (columns wavelength_nm, rho_g) or inline
                              # { wavelength_nm = [...], values = [...] }

Free parameters (for ``layerstack fit``): a layer's ``thickness_nm``, ``alpha_per_nm``, ``n`` and
``k`` (numbers) and the background's ``rho_g`` may be written as an inline table that adds
fitting information to the value::

    thickness_nm = { value = 30000, free = true, min = 0, max = 1e5 }
    alpha_per_nm = { table = "alpha.csv", free = true, basis = 8 }   # spectrum on 8 B-splines
    rho_g = { value = 0.5, free = true, basis = "free" }              # one value per wavelength

Keys: ``value`` (or, for spectra, ``table`` / ``wavelength_nm`` + ``values``), ``free`` (bool),
``min``/``max`` (bounds; defaults thickness ≥ 0, α ≥ 0, 0 ≤ ρg ≤ 1, n ≥ 1), ``basis`` (spectra:
number of B-spline functions or ``"free"``), ``per_sample`` (``layerstack fit --joint``: one value
per spectrum) and ``smoothness`` (penalty weight). :func:`load_stack` ignores these keys (the
value is used); :func:`load_fit_stack` also returns the declarations.

Dispersion: wherever ``n`` is accepted it may also be an inline table with exactly one of

* ``n = { cauchy = [A, B, C] }`` — :math:`n = A + B/\lambda^2 + C/\lambda^4`, λ in µm
  (1 to 3 coefficients; ``k`` from the ``k`` key, constant);
* ``n = { sellmeier = { B = [...], C = [...] } }`` — :math:`n^2 = 1 + \sum B_i\lambda^2/(\lambda^2 - C_i)`,
  λ in µm, :math:`C_i` in µm² (``k`` from the ``k`` key, constant);
* ``n = { table = "file.csv" }`` — CSV with columns ``wavelength_nm, n`` and optionally ``k``
  (if the file has no ``k`` column, the ``k`` key gives a constant k);
* ``n = { wavelength_nm = [...], n = [...], k = [...] }`` — the same table inline (k optional);
* ``n = { material = "Au", source = "Johnson" }`` — a real material from the
  refractiveindex.info database shipped offline (:func:`~layerstack_jax.material`): ``material``
  is the database's material id (or a ``"shelf/book/page"`` path), ``source`` the page id or
  words of its title (``"Johnson and Christy"``), needed when the material has several pages;
  optional ``shelf``. n and k both come from the database (no ``k`` key); wavelengths outside
  the data's range are an error.

Tables are linearly interpolated and never extrapolated: predicting outside a table's range is
an error. Relative file names are taken relative to the directory of the TOML file.

CSV files need a header row naming the columns (any order, case-insensitive); lines starting
with ``#`` before the header and blank lines are ignored; wavelengths must increase strictly.

Every problem in a file (missing or unknown key — unknown keys are rejected to catch typos —,
both or neither of ``[substrate]`` and ``[background]``, a negative number, a malformed CSV …)
raises :class:`~layerstack_jax.LayerstackError` with a message naming the file, the table and
key, and what is wrong.

Writing: :func:`save_stack` writes a :class:`Stack` (via :func:`stack_to_dict`) or a stack dict as
a TOML stack file, with optional ``#`` header lines.

Design files
------------
``layerstack design DESIGN.toml -o design.toml [--plot design.png]`` optimises layer
thicknesses (implementation: :mod:`fitting._design_file` on :mod:`fitting._design`). A design
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

Spectra and wavelengths
-----------------------
:func:`save_spectra_csv` writes ``wavelength_nm`` and named columns; :func:`parse_wavelengths`
turns ``"380:780:5"`` (start:stop:step in nm, stop included when on the grid), ``"550"`` or
``"450,550,650"`` into an array.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from pathlib import Path
from typing import Iterable, Mapping, Optional

import numpy as np

from ._materials import Cauchy, Index, Material, Sellmeier, Tabulated
from ._stack import LambertianBackground, Layer, Stack, Substrate, TabulatedSpectrum
from ._validate import LayerstackError, is_concrete

__all__ = [
    "load_stack",
    "load_fit_stack",
    "stack_from_dict",
    "stack_to_dict",
    "save_stack",
    "read_csv_columns",
    "read_spectra_csv",
    "save_spectra_csv",
    "parse_wavelengths",
]

_TOP_KEYS = ("description", "ambient", "layers", "substrate", "background")
_LAYER_KEYS = ("name", "n", "k", "thickness_nm", "coherent", "alpha_per_nm")
_SUBSTRATE_KEYS = ("n", "k")
_BACKGROUND_KEYS = ("n", "rho_g")
_AMBIENT_KEYS = ("n",)
_DISPERSION_KEYS = ("cauchy", "sellmeier", "table", "material")


# ----------------------------------------------------------------------------- helpers
class _Where:
    """Where we are in a file, for error messages: ``<file>: <table>: key '<key>': <what>``."""

    def __init__(self, source: str, table: str):
        self.source = source
        self.table = table

    def error(self, what: str, key: Optional[str] = None) -> LayerstackError:
        place = f"{self.table}: key {key!r}" if key else self.table
        return LayerstackError(f"{self.source}: {place}: {what}")


def _reject_unknown(where: _Where, table: Mapping, allowed: Iterable[str]) -> None:
    allowed = tuple(allowed)
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise where.error(f"unknown key {key!r}{hint}; allowed keys: {', '.join(allowed)}")


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _number(where: _Where, key: str, x, *, minimum: Optional[float] = None, maximum: Optional[float] = None,
            positive: bool = False, what: str = "") -> float:
    label = f" ({what})" if what else ""
    if not _is_number(x):
        raise where.error(f"must be a number{label}, got {x!r}", key)
    v = float(x)
    if not math.isfinite(v):
        raise where.error(f"must be finite{label}, got {v!r}", key)
    if positive and v <= 0:
        raise where.error(f"must be > 0{label}, got {v!r}", key)
    if minimum is not None and v < minimum:
        raise where.error(f"must be >= {minimum:g}{label}, got {v!r}", key)
    if maximum is not None and v > maximum:
        raise where.error(f"must be <= {maximum:g}{label}, got {v!r}", key)
    return v


def _number_list(where: _Where, key: str, x, what: str) -> np.ndarray:
    if not isinstance(x, list) or not x or not all(_is_number(v) for v in x):
        raise where.error(f"{what} must be a non-empty list of numbers, got {x!r}", key)
    a = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(a)):
        raise where.error(f"{what} must be finite numbers, got {x!r}", key)
    return a


def _check_grid(where: _Where, key: str, wl: np.ndarray, what: str) -> None:
    if wl.size < 2:
        raise where.error(f"{what}: needs at least 2 wavelengths, got {wl.size}", key)
    if np.any(wl <= 0):
        raise where.error(f"{what}: wavelengths must be > 0 nm", key)
    if np.any(np.diff(wl) <= 0):
        i = int(np.argmax(np.diff(wl) <= 0))
        raise where.error(
            f"{what}: wavelengths must increase strictly (wavelength_nm {wl[i]:g} is followed by {wl[i + 1]:g})", key
        )


def _check_range(where: _Where, key: str, values: np.ndarray, what: str, lo=None, hi=None) -> None:
    if lo is not None and np.any(values < lo):
        raise where.error(f"{what}: values must be >= {lo:g}, got min {values.min():g}", key)
    if hi is not None and np.any(values > hi):
        raise where.error(f"{what}: values must be <= {hi:g}, got max {values.max():g}", key)


# --------------------------------------------------------------------------------- CSV
def _content_lines(path: Path) -> list[tuple[int, str]]:
    """``[(line number, stripped text)]`` of a text file, blank and ``#`` lines dropped."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise LayerstackError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise LayerstackError(f"{path}: cannot read: {e}") from None
    lines = [(i + 1, line.strip()) for i, line in enumerate(text.splitlines())]
    return [(i, line) for i, line in lines if line and not line.startswith("#")]


def _numeric_rows(path, lines, names) -> np.ndarray:
    """Data rows ``[(line_no, text), …]`` of a CSV as a ``(rows, len(names))`` float array; every
    problem raises :class:`LayerstackError` naming the file and line."""
    rows = []
    for line_no, line in lines:
        fields = [f.strip() for f in line.split(",")]
        if len(fields) != len(names):
            raise LayerstackError(f"{path}: line {line_no}: {len(fields)} fields for {len(names)} columns ({', '.join(names)})")
        try:
            row = [float(f) for f in fields]
        except ValueError:
            raise LayerstackError(f"{path}: line {line_no}: not a number in {line!r}") from None
        if not all(math.isfinite(v) for v in row):
            raise LayerstackError(f"{path}: line {line_no}: NaN or infinite value in {line!r}")
        rows.append(row)
    if not rows:
        raise LayerstackError(f"{path}: no data rows after the header")
    return np.asarray(rows, dtype=float)


def read_csv_columns(path, required: Iterable[str], optional: Iterable[str] = ()) -> dict[str, np.ndarray]:
    """Read a numeric CSV file with a header row into ``{column: float array}``.

    Columns are matched case-insensitively and may come in any order; ``required`` ones must be
    present, ``optional`` ones may be, any other column is an error. Blank lines and lines
    starting with ``#`` are skipped. Raises :class:`LayerstackError` naming the file (and line)
    for a missing file, a missing header, a short or non-numeric row, or non-finite values.
    Does not check the wavelength order (callers do).
    """
    path = Path(path)
    required = [c.lower() for c in required]
    optional = [c.lower() for c in optional]
    expected = ", ".join(required + [f"[{c}]" for c in optional])
    lines = _content_lines(path)
    if not lines:
        raise LayerstackError(f"{path}: empty file (expected a header row {expected} and data rows)")
    header_line, header = lines[0]
    names = [h.strip().lower() for h in header.split(",")]

    def _is_float(s):
        try:
            float(s)
            return True
        except ValueError:
            return False

    if all(_is_float(h) for h in names):
        raise LayerstackError(f"{path}: line {header_line}: header row required (columns {expected}), got numbers")
    for name in names:
        if name not in required and name not in optional:
            raise LayerstackError(f"{path}: line {header_line}: unknown column {name!r}; expected columns {expected}")
        if names.count(name) > 1:
            raise LayerstackError(f"{path}: line {header_line}: column {name!r} appears twice")
    for name in required:
        if name not in names:
            raise LayerstackError(f"{path}: line {header_line}: missing column {name!r}; expected columns {expected}")
    data = _numeric_rows(path, lines[1:], names)
    return {name: data[:, j] for j, name in enumerate(names)}


def read_spectra_csv(path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Read measured spectra: a header row ``wavelength_nm, name1, name2, …`` then numbers.

    Returns ``(wavelength_nm, {name: values})``: wavelengths in nm and each spectrum as it is in
    the file (no unit conversion), all 1-D arrays of shape ``(wl,)``. Lines starting with ``#`` (e.g. a note that the
    data are synthetic) and blank lines are skipped. Raises :class:`LayerstackError` naming the
    file and line for a missing ``wavelength_nm`` column, no spectrum column, a duplicate name,
    a short or non-numeric row, NaN, or wavelengths that do not increase strictly.
    """
    path = Path(path)
    lines = _content_lines(path)
    if not lines:
        raise LayerstackError(f"{path}: empty file (expected a header wavelength_nm,<spectrum names…> and data rows)")
    header_line, header = lines[0]
    names = [h.strip() for h in header.split(",")]
    if not names or names[0].lower() != "wavelength_nm":
        raise LayerstackError(f"{path}: line {header_line}: the first column must be wavelength_nm, got {names[0]!r}")
    if len(names) < 2:
        raise LayerstackError(f"{path}: line {header_line}: no spectrum column after wavelength_nm")
    for n in names[1:]:
        if not n:
            raise LayerstackError(f"{path}: line {header_line}: empty column name")
        if names.count(n) > 1:
            raise LayerstackError(f"{path}: line {header_line}: column {n!r} appears twice")
    data = _numeric_rows(path, lines[1:], names)
    wl = data[:, 0]
    if np.any(wl <= 0) or np.any(np.diff(wl) <= 0):
        raise LayerstackError(f"{path}: wavelength_nm must be > 0 and increase strictly")
    return wl, {n: data[:, j + 1] for j, n in enumerate(names[1:])}


def _read_table(where: _Where, key: str, base_dir: Path, filename, required, optional=()) -> tuple[Path, dict]:
    if not isinstance(filename, str) or not filename:
        raise where.error(f"table must be a file name (string), got {filename!r}", key)
    path = Path(filename)
    if not path.is_absolute():
        path = base_dir / path
    if not path.is_file():
        raise where.error(f"table file {filename!r} not found (looked for {path})", key)
    try:
        cols = read_csv_columns(path, required, optional)
    except LayerstackError as e:
        raise where.error(f"bad table: {e}", key) from None
    return path, cols


# --------------------------------------------------------------------------- materials
def _material(where: _Where, table: Mapping, base_dir: Path, *, allow_k: bool, label: str) -> Material:
    """The material of a table with an ``n`` key (and optionally ``k``)."""
    if "n" not in table:
        raise where.error("missing (refractive index: a number or a dispersion table)", "n")
    spec = table["n"]
    k_given = "k" in table
    if k_given and not allow_k:
        raise where.error("not allowed here: this medium must be transparent (real index, no k)", "k")
    k = _number(where, "k", table["k"], minimum=0.0, what="extinction coefficient") if k_given else 0.0

    if _is_number(spec):
        return Index(_number(where, "n", spec, positive=True, what="refractive index"), k)
    if not isinstance(spec, dict):
        raise where.error(f"must be a number or an inline table such as {{ cauchy = [A, B] }}, got {spec!r}", "n")

    inline_keys = ("wavelength_nm", "n", "k")
    if "wavelength_nm" in spec:
        _reject_unknown(_Where(where.source, f"{where.table}: key 'n'"), spec, inline_keys)
        wl = _number_list(where, "n", spec["wavelength_nm"], "wavelength_nm")
        if "n" not in spec:
            raise where.error("inline table needs 'n' (and optionally 'k') lists next to 'wavelength_nm'", "n")
        nn = _number_list(where, "n", spec["n"], "n")
        kk = _number_list(where, "n", spec["k"], "k") if "k" in spec else None
        return _tabulated(where, wl, nn, kk, k_given, k, allow_k, f"{label} (inline table)")

    chosen = [name for name in spec if name in _DISPERSION_KEYS]
    extra = ("source", "shelf") if "material" in spec else ()
    _reject_unknown(_Where(where.source, f"{where.table}: key 'n'"), spec, _DISPERSION_KEYS + extra)
    if len(chosen) != 1:
        raise where.error(
            "give exactly one of cauchy = [...], sellmeier = {B=[...], C=[...]}, table = \"file.csv\", "
            f"material = \"name\" or an inline wavelength_nm/n/k table; got {spec!r}",
            "n",
        )
    kind = chosen[0]
    value = spec[kind]
    if kind == "material":
        return _database_material(where, spec, k_given, allow_k)
    if kind == "cauchy":
        coef = _number_list(where, "n", value, "cauchy coefficients [A, B, C]")
        if coef.size > 3:
            raise where.error(f"cauchy takes 1 to 3 coefficients [A, B, C] (λ in µm), got {coef.size}", "n")
        if coef[0] <= 0:
            raise where.error(f"cauchy A must be > 0, got {coef[0]:g}", "n")
        A, B, C = (list(coef) + [0.0, 0.0])[:3]
        return Cauchy(A, B, C, k)
    if kind == "sellmeier":
        if not isinstance(value, dict):
            raise where.error(f"sellmeier must be an inline table {{ B = [...], C = [...] }}, got {value!r}", "n")
        _reject_unknown(_Where(where.source, f"{where.table}: key 'n': sellmeier"), value, ("B", "C"))
        if "B" not in value or "C" not in value:
            raise where.error("sellmeier needs both B = [...] and C = [...] (C in µm²)", "n")
        B = _number_list(where, "n", value["B"], "sellmeier B")
        C = _number_list(where, "n", value["C"], "sellmeier C")
        if B.shape != C.shape:
            raise where.error(f"sellmeier B and C must have the same length, got {B.size} and {C.size}", "n")
        return Sellmeier(B, C, k)
    # table
    path, cols = _read_table(where, "n", base_dir, value, ("wavelength_nm", "n"), ("k",))
    return _tabulated(where, cols["wavelength_nm"], cols["n"], cols.get("k"), k_given, k, allow_k,
                      f"{path.name} ({label})", file=str(value))


def _database_material(where: _Where, spec: Mapping, k_given: bool, allow_k: bool) -> Material:
    """``n = { material = "Au", source = "Johnson", shelf = "main" }``: the refractiveindex.info
    database (n and k from the same page; no separate ``k`` key)."""
    from ._database import material

    for key in ("material", "source", "shelf"):
        if key in spec and not isinstance(spec[key], str):
            raise where.error(f"{key} must be a string, got {spec[key]!r}", "n")
    if k_given:
        raise where.error("k comes from the material database with n = { material = ... }; remove the k key", "k")
    try:
        m = material(spec["material"], spec.get("source"), shelf=spec.get("shelf"))
    except LayerstackError as e:
        raise where.error(str(e), "n") from None
    k_table = getattr(m, "k", None)
    if not allow_k and k_table is not None and np.any(np.asarray(k_table) != 0):
        raise where.error(f"{m.name} absorbs (k > 0 in the database), but this medium must be transparent", "n")
    return m


def _tabulated(where, wl, n, k_col, k_given, k, allow_k, name, file=None) -> Tabulated:
    what = f"table {file!r}" if file else "inline table"
    _check_grid(where, "n", wl, what)
    for col, v in (("n", n), ("k", k_col)):
        if v is not None and v.shape != wl.shape:
            raise where.error(f"{what}: column {col} has {v.size} values for {wl.size} wavelengths", "n")
    _check_range(where, "n", n, f"{what}: column n", lo=np.finfo(float).tiny)
    if k_col is not None:
        if k_given:
            raise where.error(f"k is given both as a key and as a column of the {what}; keep one", "k")
        _check_range(where, "n", k_col, f"{what}: column k", lo=0.0)
        if not allow_k and np.any(k_col != 0):
            raise where.error(f"{what}: this medium must be transparent (k = 0)", "n")
    elif k_given:
        k_col = np.full_like(wl, k)
    return Tabulated(wl, n, k_col, name=name)


def _spectrum(where: _Where, key: str, spec, base_dir: Path, column: str, label: str, *, lo, hi):
    """A number or a tabulated spectrum (file or inline) for ``alpha_per_nm`` or ``rho_g``."""
    if _is_number(spec):
        return _number(where, key, spec, minimum=lo, maximum=hi)
    if not isinstance(spec, dict):
        raise where.error(
            f"must be a number, {{ table = \"file.csv\" }} or {{ wavelength_nm = [...], values = [...] }}, got {spec!r}",
            key,
        )
    if "table" in spec:
        _reject_unknown(_Where(where.source, f"{where.table}: key {key!r}"), spec, ("table",))
        path, cols = _read_table(where, key, base_dir, spec["table"], ("wavelength_nm", column))
        wl, values, what, name = cols["wavelength_nm"], cols[column], f"table {spec['table']!r}", f"{path.name} ({label})"
    else:
        _reject_unknown(_Where(where.source, f"{where.table}: key {key!r}"), spec, ("wavelength_nm", "values", "table"))
        if "wavelength_nm" not in spec or "values" not in spec:
            raise where.error("give { table = \"file.csv\" } or both wavelength_nm = [...] and values = [...]", key)
        wl = _number_list(where, key, spec["wavelength_nm"], "wavelength_nm")
        values = _number_list(where, key, spec["values"], "values")
        what, name = "inline table", f"{label} (inline table)"
        if values.shape != wl.shape:
            raise where.error(f"{what}: {values.size} values for {wl.size} wavelengths", key)
    _check_grid(where, key, wl, what)
    _check_range(where, key, values, what, lo=lo, hi=hi)
    return TabulatedSpectrum(wl, values, name=name)


_FREE_KEYS = ("value", "free", "min", "max", "basis", "per_sample", "smoothness")


def _split_free(where: _Where, key: str, spec, path: tuple, kind: str, free: Optional[list], *, spectral: bool):
    """Strip the free-parameter keys of ``spec`` (module docstring), record the declaration in
    ``free`` (when a list) and return the plain value spec."""
    if not isinstance(spec, dict) or not any(k in spec for k in _FREE_KEYS):
        return spec
    decl = {k: spec[k] for k in _FREE_KEYS if k in spec}
    rest = {k: v for k, v in spec.items() if k not in _FREE_KEYS}
    if "value" in decl:
        if rest:
            raise where.error(f"give either value = ... or {', '.join(rest)}, not both", key)
        plain = decl.pop("value")
        if not _is_number(plain):
            raise where.error(f"value must be a number, got {plain!r}", key)
    elif rest and spectral:
        plain = rest
    else:
        raise where.error("missing value = <number> next to free/min/max", key)
    is_free = decl.get("free", False)
    if not isinstance(is_free, bool):
        raise where.error(f"free must be true or false, got {is_free!r}", key)
    bounds = {}
    for b in ("min", "max"):
        if b in decl:
            v = decl[b]
            if not _is_number(v) or math.isnan(float(v)):
                raise where.error(f"{b} must be a number, got {v!r}", key)
            bounds[b] = float(v)
    if "min" in bounds and "max" in bounds and not bounds["min"] < bounds["max"]:
        raise where.error(f"bounds inverted: min {bounds['min']:g} must be < max {bounds['max']:g}", key)
    basis = decl.get("basis")
    if basis is not None:
        if not spectral:
            raise where.error("basis is for spectra (alpha_per_nm, rho_g) only", key)
        if not (basis == "free" or (isinstance(basis, int) and not isinstance(basis, bool) and basis >= 1)):
            raise where.error(f"basis must be a number of B-spline functions >= 1 or \"free\", got {basis!r}", key)
    per_sample = decl.get("per_sample", False)
    if not isinstance(per_sample, bool):
        raise where.error(f"per_sample must be true or false, got {per_sample!r}", key)
    smooth = decl.get("smoothness", 0.0)
    if not _is_number(smooth) or smooth < 0:
        raise where.error(f"smoothness must be a number >= 0, got {smooth!r}", key)
    extra = [k for k in ("min", "max", "basis", "per_sample", "smoothness") if k in decl]
    if extra and not is_free:
        raise where.error(f"{', '.join(extra)} given but free is not true", key)
    if is_free and free is not None:
        free.append({"path": path, "kind": kind, "name": f"{key}[{path[1]}]" if path[0] == "layers" else key,
                     "lower": bounds.get("min"), "upper": bounds.get("max"), "basis": basis,
                     "per_sample": per_sample, "smoothness": float(smooth), "where": f"{where.source}: {where.table}"})
    return plain


def _layer(where: _Where, table: Mapping, base_dir: Path, name: str, index: int = 0, free: Optional[list] = None) -> Layer:
    _reject_unknown(where, table, _LAYER_KEYS)
    if "thickness_nm" not in table:
        raise where.error("missing (layer thickness in nm)", "thickness_nm")
    table = dict(table)
    spec = _split_free(where, "thickness_nm", table["thickness_nm"], ("layers", name, "thickness"), "thickness", free,
                       spectral=False)
    thickness = _number(where, "thickness_nm", spec, minimum=0.0, what="nm")
    for key, field, kind in (("n", "n", "n"), ("k", "k", "coefficient")):
        if key in table and isinstance(table[key], dict) and any(k in table[key] for k in _FREE_KEYS):
            table[key] = _split_free(where, key, table[key], ("layers", name, "index", field), kind, free, spectral=False)
    if "coherent" not in table:
        raise where.error(
            "missing: say coherent = true for a thin film (interference) or false for a thick layer "
            "(thicker than the coherence length, ~ a few µm)",
            "coherent",
        )
    coherent = table["coherent"]
    if not isinstance(coherent, bool):
        raise where.error(f"must be true or false, got {coherent!r}", "coherent")
    index = _material(where, table, base_dir, allow_k=True, label=f"layer {name!r} n")
    alpha = None
    if "alpha_per_nm" in table:
        if coherent:
            raise where.error(
                "is only for incoherent layers (coherent = false); give a coherent film an extinction coefficient k",
                "alpha_per_nm",
            )
        spec = _split_free(where, "alpha_per_nm", table["alpha_per_nm"], ("layers", name, "alpha"), "alpha", free,
                           spectral=True)
        alpha = _spectrum(where, "alpha_per_nm", spec, base_dir, "alpha_per_nm",
                          f"layer {name!r} alpha", lo=0.0, hi=None)
    return Layer(index, thickness, coherent=coherent, alpha=alpha, name=name)


# ------------------------------------------------------------------------------ stacks
def stack_from_dict(d: Mapping, base_dir=".", *, source: str = "<stack dict>", free: Optional[list] = None) -> Stack:
    """Build a :class:`Stack` from the parsed contents of a stack file (schema: module docstring).

    Args:
        d: the dict (as from ``tomllib``).
        base_dir: directory against which relative table file names are resolved.
        source: name used in error messages (the file name when called by :func:`load_stack`).
        free: if a list, the free-parameter declarations found are appended to it (dicts with
            ``path``, ``kind``, ``name``, ``lower``, ``upper``, ``basis``, ``per_sample``,
            ``smoothness``); layers are named in the paths.

    Units are those of the file: ``thickness_nm`` in nm, ``alpha_per_nm`` in 1/nm, ``rho_g`` a
    fraction in [0, 1]. Numbers stay scalars; tables become :class:`Tabulated` /
    :class:`TabulatedSpectrum` leaves of shape ``(table,)``, so the stack can be evaluated on
    any grid ``(wl,)`` inside the tables' range.
    """
    base_dir = Path(base_dir)
    top = _Where(source, "top level")
    if not isinstance(d, Mapping):
        raise top.error(f"expected a table of keys, got {type(d).__name__}")
    _reject_unknown(top, d, _TOP_KEYS)
    if "description" in d and not isinstance(d["description"], str):
        raise top.error("must be a string", "description")

    def _table(key):
        t = d[key]
        if not isinstance(t, Mapping):
            raise top.error(f"must be a table [{key}], got {t!r}", key)
        return t

    try:
        if "ambient" in d:
            where = _Where(source, "[ambient]")
            amb = _table("ambient")
            _reject_unknown(where, amb, _AMBIENT_KEYS + ("k",))
            ambient = _material(where, amb, base_dir, allow_k=False, label="ambient n")
        else:
            ambient = Index(1.0)

        raw_layers = d.get("layers", [])
        if not isinstance(raw_layers, list) or not all(isinstance(t, Mapping) for t in raw_layers):
            raise top.error("must be an array of tables, written [[layers]]", "layers")
        layers = []
        for i, t in enumerate(raw_layers):
            name = t.get("name", f"layer {i + 1}")
            label = f"[[layers]] no. {i + 1}"
            if not isinstance(name, str) or not name:
                raise _Where(source, label).error(f"must be a non-empty string, got {name!r}", "name")
            layers.append(_layer(_Where(source, f"{label} ({name!r})"), t, base_dir, name, i, free))

        has_sub, has_bg = "substrate" in d, "background" in d
        if has_sub and has_bg:
            raise top.error("give either [substrate] (specular) or [background] (Lambertian), not both")
        if not (has_sub or has_bg):
            raise top.error("missing the exit medium: add a [substrate] (specular) or a [background] (Lambertian) table")
        if has_sub:
            where = _Where(source, "[substrate]")
            sub = _table("substrate")
            _reject_unknown(where, sub, _SUBSTRATE_KEYS)
            exit_ = Substrate(_material(where, sub, base_dir, allow_k=True, label="substrate n"))
        else:
            where = _Where(source, "[background]")
            bg = _table("background")
            _reject_unknown(where, bg, _BACKGROUND_KEYS + ("k",))
            index = _material(where, bg, base_dir, allow_k=False, label="background n")
            if "rho_g" not in bg:
                raise where.error("missing (intrinsic reflectance of the background, in [0, 1])", "rho_g")
            spec = _split_free(where, "rho_g", bg["rho_g"], ("exit", "reflectance"), "rho_g", free, spectral=True)
            rho = _spectrum(where, "rho_g", spec, base_dir, "rho_g", "background rho_g", lo=0.0, hi=1.0)
            exit_ = LambertianBackground(index, rho)
        return Stack(ambient=ambient, layers=layers, exit=exit_)
    except LayerstackError as e:
        msg = str(e)
        if msg.startswith(f"{source}:"):
            raise
        raise LayerstackError(f"{source}: {msg}") from None


def _read_toml(path: Path) -> dict:
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise LayerstackError(f"{path}: stack file not found") from None
    except tomllib.TOMLDecodeError as e:
        raise LayerstackError(f"{path}: invalid TOML: {e}") from None
    except (OSError, UnicodeDecodeError) as e:
        raise LayerstackError(f"{path}: cannot read stack file: {e}") from None


def load_fit_stack(path) -> tuple[Stack, list]:
    """Read a stack file and its free-parameter declarations (module docstring, "Free
    parameters"): returns ``(stack, declarations)``, each declaration a dict with ``path``
    (layers by name), ``kind``, ``name``, ``lower``, ``upper`` (None: default), ``basis``,
    ``per_sample``, ``smoothness``. Bounds are in the parameter's file unit (nm for
    ``thickness_nm``, 1/nm for ``alpha_per_nm``, a fraction in [0, 1] for ``rho_g``); the stack is
    as from :func:`load_stack` (scalars, or tables of shape ``(table,)``)."""
    path = Path(path)
    free: list = []
    stack = stack_from_dict(_read_toml(path), path.parent, source=str(path), free=free)
    return stack, free


def load_stack(path) -> Stack:
    """Read a stack file (TOML, schema in the module docstring). Relative table file names are
    resolved against the file's directory. Raises :class:`LayerstackError` naming the file and
    the offending table/key for any problem. Units and shapes as in :func:`stack_from_dict`
    (thicknesses in nm, α in 1/nm; tables become leaves of shape ``(table,)``)."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            d = tomllib.load(f)
    except FileNotFoundError:
        raise LayerstackError(f"{path}: stack file not found") from None
    except tomllib.TOMLDecodeError as e:
        raise LayerstackError(f"{path}: invalid TOML: {e}") from None
    except (OSError, UnicodeDecodeError) as e:
        raise LayerstackError(f"{path}: cannot read stack file: {e}") from None
    return stack_from_dict(d, path.parent, source=str(path))


def _scalar(x, what: str) -> float:
    if not is_concrete(x) or np.ndim(x) != 0:
        raise LayerstackError(f"stack_to_dict: {what} must be a concrete scalar, got {x!r}")
    return float(np.asarray(x))


def _material_to_dict(m: Material, what: str, out: dict) -> None:
    if isinstance(m, Index):
        if np.ndim(m.n) or np.ndim(m.k):
            raise LayerstackError(f"stack_to_dict: {what} is sampled on a wavelength grid; use a Tabulated material")
        out["n"] = _scalar(m.n, f"{what} n")
        k = _scalar(m.k, f"{what} k")
    elif isinstance(m, Cauchy):
        out["n"] = {"cauchy": [_scalar(m.A, f"{what} A"), _scalar(m.B, f"{what} B"), _scalar(m.C, f"{what} C")]}
        k = _scalar(m.k, f"{what} k")
    elif isinstance(m, Sellmeier):
        out["n"] = {"sellmeier": {"B": np.atleast_1d(np.asarray(m.B, float)).tolist(),
                                  "C": np.atleast_1d(np.asarray(m.C, float)).tolist()}}
        k = _scalar(m.k, f"{what} k")
    elif isinstance(m, Tabulated):
        table = {"wavelength_nm": list(m.wavelength_nm), "n": np.asarray(m.n, float).tolist()}
        if m.k is not None:
            table["k"] = np.asarray(m.k, float).tolist()
        out["n"] = table
        k = 0.0
    else:
        raise LayerstackError(f"stack_to_dict: cannot write {what} of type {type(m).__name__}")
    if k != 0.0:
        out["k"] = k


def _spectrum_to_dict(x, what: str):
    if isinstance(x, TabulatedSpectrum):
        return {"wavelength_nm": list(x.wavelength_nm), "values": np.asarray(x.values, float).tolist()}
    if callable(x) or np.ndim(x):
        raise LayerstackError(f"stack_to_dict: {what} must be a scalar or a TabulatedSpectrum")
    return _scalar(x, what)


def stack_to_dict(stack: Stack) -> dict:
    """The inverse of :func:`stack_from_dict`: a dict in the stack-file schema, tables inline.

    Works for stacks made of scalars, :class:`Index` (scalar), :class:`Cauchy`,
    :class:`Sellmeier`, :class:`Tabulated` and :class:`TabulatedSpectrum`; raises
    :class:`LayerstackError` for arrays sampled on a grid or traced values.
    """
    d: dict = {"ambient": {}}
    _material_to_dict(stack.ambient, "ambient", d["ambient"])
    layers = []
    for i, layer in enumerate(stack.layers):
        t: dict = {"name": layer.name or f"layer {i + 1}"}
        _material_to_dict(layer.index, f"layer {i + 1}", t)
        t["thickness_nm"] = _scalar(layer.thickness, f"layer {i + 1} thickness")
        t["coherent"] = bool(layer.coherent)
        if layer.alpha is not None:
            t["alpha_per_nm"] = _spectrum_to_dict(layer.alpha, f"layer {i + 1} alpha")
        layers.append(t)
    d["layers"] = layers
    if isinstance(stack.exit, Substrate):
        d["substrate"] = {}
        _material_to_dict(stack.exit.index, "substrate", d["substrate"])
    else:
        d["background"] = {}
        _material_to_dict(stack.exit.index, "background", d["background"])
        d["background"]["rho_g"] = _spectrum_to_dict(stack.exit.reflectance, "background rho_g")
    return d


# --------------------------------------------------------------------------- TOML writer
_BARE_KEY = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-")


def _toml_key(key) -> str:
    key = str(key)
    return key if key and set(key) <= _BARE_KEY else _toml_string(key)


def _toml_string(text: str) -> str:
    escapes = {'"': '\\"', "\\": "\\\\", "\n": "\\n", "\t": "\\t", "\r": "\\r", "\b": "\\b", "\f": "\\f"}
    out = []
    for c in text:
        if c in escapes:
            out.append(escapes[c])
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            out.append(f"\\u{ord(c):04X}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'


def _toml_value(x, what: str) -> str:
    """One TOML value (inline: strings, booleans, finite numbers, arrays, inline tables)."""
    if isinstance(x, (bool, np.bool_)):
        return "true" if x else "false"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        v = float(x)
        if not math.isfinite(v):
            raise LayerstackError(f"save_stack: {what} is not finite ({v!r})")
        return repr(v)  # shortest round-trip representation
    if isinstance(x, str):
        return _toml_string(x)
    if isinstance(x, np.ndarray):
        x = x.tolist()
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(_toml_value(v, what) for v in x) + "]"
    if isinstance(x, Mapping):
        if not x:
            return "{}"
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v, f'{what}.{k}')}" for k, v in x.items()) + " }"
    raise LayerstackError(f"save_stack: cannot write {what} of type {type(x).__name__}")


def _toml_table(d: Mapping, what: str) -> list[str]:
    return [f"{_toml_key(k)} = {_toml_value(v, f'{what}.{k}')}" for k, v in d.items()]


def _dumps_stack(d: Mapping, header: str = "") -> str:
    """A stack dict (schema in the module docstring, e.g. from :func:`stack_to_dict`) as TOML
    text, ``header`` written first as ``#`` comment lines."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    if lines:
        lines.append("")
    for key, value in d.items():
        if not isinstance(value, (Mapping, list)) or (isinstance(value, list) and key != "layers"):
            lines.append(f"{_toml_key(key)} = {_toml_value(value, key)}")
    for key in ("ambient", "layers", "substrate", "background"):
        if key not in d:
            continue
        if key == "layers":
            for layer in d["layers"]:
                lines += ["", "[[layers]]", *_toml_table(layer, "layers")]
        else:
            lines += ["", f"[{key}]", *_toml_table(d[key], key)]
    return "\n".join(lines) + "\n"


def save_stack(path, stack, *, header: str = "") -> Path:
    """Write a stack file (TOML) readable by :func:`load_stack`.

    Args:
        path: output file; missing parent directories are created.
        stack: a :class:`Stack` (converted by :func:`stack_to_dict`: materials inline) or a dict
            in the stack-file schema (kept as given, e.g. ``{ material = "Au" }`` references;
            relative table file names must then be valid from the output's directory).
        header: free text written first as ``#`` comment lines.
    Returns the path written.

    Units as in the stack-file schema (``thickness_nm`` in nm, ``alpha_per_nm`` in 1/nm). A
    :class:`Stack`'s leaves must be scalars or tables with their own wavelengths
    (:class:`Tabulated`, :class:`TabulatedSpectrum`, shape ``(table,)``): arrays sampled on a
    model grid or traced values raise :class:`LayerstackError` (see :func:`stack_to_dict`).
    """
    d = stack_to_dict(stack) if isinstance(stack, Stack) else stack
    if not isinstance(d, Mapping):
        raise LayerstackError(f"save_stack: expected a Stack or a dict, got {type(stack).__name__}")
    text = _dumps_stack(d, header)
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------ spectra, wavelengths
def save_spectra_csv(path, wavelength_nm, columns: Mapping[str, object], *, fmt: str = "%.10g") -> Path:
    """Write ``wavelength_nm`` and the named spectra as a CSV file with a header row.

    Args:
        path: output file; missing parent directories are created.
        wavelength_nm: ``(wl,)`` wavelengths in nm (first column).
        columns: ``{name: (wl,) values}`` in column order.
    Returns the path written.
    """
    path = Path(path)
    wl = np.asarray(wavelength_nm, dtype=float)
    if wl.ndim != 1:
        raise LayerstackError(f"save_spectra_csv: wavelength_nm must be 1-D, got shape {wl.shape}")
    names = ["wavelength_nm"]
    data = [wl]
    for name, values in columns.items():
        name = str(name)
        if not name or any(c in name for c in ',"\n\r'):
            raise LayerstackError(f"save_spectra_csv: bad column name {name!r} (no commas, quotes or newlines)")
        if name in names:
            raise LayerstackError(f"save_spectra_csv: column {name!r} given twice")
        v = np.asarray(values, dtype=float)
        if v.shape != wl.shape:
            raise LayerstackError(f"save_spectra_csv: column {name!r} has shape {v.shape}, expected {wl.shape}")
        names.append(name)
        data.append(v)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(path, np.column_stack(data), delimiter=",", header=",".join(names), comments="", fmt=fmt)
    return path


def parse_wavelengths(text) -> np.ndarray:
    """Wavelength grid in nm from ``"start:stop:step"`` (stop included when it falls on the
    grid), a single value ``"550"`` or a comma list ``"450,550,650"`` (strictly increasing).
    Returns a 1-D float array of shape ``(wl,)`` in nm.
    """
    t = str(text).strip()
    bad = LayerstackError(
        f"bad wavelengths {text!r}: use start:stop:step in nm (e.g. 380:780:5), one value (550) "
        "or a comma list (450,550,650)"
    )
    try:
        if ":" in t:
            parts = t.split(":")
            if len(parts) != 3:
                raise bad
            start, stop, step = (float(p) for p in parts)
            if not all(map(math.isfinite, (start, stop, step))):
                raise bad
            if step <= 0:
                raise LayerstackError(f"bad wavelengths {text!r}: step must be > 0")
            if stop < start:
                raise LayerstackError(f"bad wavelengths {text!r}: stop must be >= start")
            count = int(math.floor((stop - start) / step + 1e-9)) + 1
            wl = start + step * np.arange(count)
        else:
            wl = np.asarray([float(p) for p in t.split(",")], dtype=float)
    except ValueError:
        raise bad from None
    if wl.size == 0 or not np.all(np.isfinite(wl)):
        raise bad
    if np.any(wl <= 0):
        raise LayerstackError(f"bad wavelengths {text!r}: wavelengths must be > 0 nm")
    if np.any(np.diff(wl) <= 0):
        raise LayerstackError(f"bad wavelengths {text!r}: wavelengths must increase strictly")
    return wl
