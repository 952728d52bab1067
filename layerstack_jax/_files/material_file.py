r"""Materials and spectra in stack files: ``n`` (a number, a dispersion model, an effective
medium, a table, a database entry) with its ``k`` — :func:`read_material` —, and the spectra
``alpha_per_nm``, ``rho_g``, K and S (a number, a table file or an inline table) —
:func:`read_spectrum`. Schema: :mod:`layerstack_jax.io`; a model coefficient may carry fitting
words (:mod:`.annotations`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Mapping, Optional

import numpy as np

from .._base.validate import LayerstackError, LayerstackWarning
from .._media.effective_medium import Bruggeman, Looyenga
from .._media.materials import Cauchy, Index, Material, Sellmeier, Tabulated
from .._media.oscillators import CauchyUrbach, CodyLorentz, Drude, Lorentz, TaucLorentz
from .._stacks.stack import TabulatedSpectrum
from .annotations import annotated
from .file_grammar import (
    FileLocation,
    check_grid,
    check_range,
    is_number,
    read_number,
    read_number_list,
    reject_unknown_keys,
)
from .spectra_csv import read_csv_columns

__all__ = ["MODELS", "MIXTURES", "NEGATIVE_RTOL", "read_material", "read_spectrum"]

#: Dispersion models read by name, their coefficients by field name, each a number, a list
#: (one per oscillator) or a free-parameter table: ``n = { tauc_lorentz = { Eg = 3.2, A = {
#: value = 150, free = true, min = 10, max = 500 }, E0 = 4.2, C = 1.5, eps_inf = 2.2 } }``.
MODELS = {"lorentz": Lorentz, "drude": Drude, "tauc_lorentz": TaucLorentz, "cody_lorentz": CodyLorentz,
          "cauchy_urbach": CauchyUrbach}
#: Effective media read by name: ``n = { bruggeman = { materials = [<n>, <n>], fractions = 0.5 } }``,
#: each constituent written as ``n`` is (a number, a dispersion table, ``{ material = ... }``) or as
#: ``{ n = ..., k = ... }``; ``fractions`` as the class's (first m − 1 materials; the last fills the rest).
MIXTURES = {"bruggeman": Bruggeman, "looyenga": Looyenga}
_DISPERSION_KEYS = ("cauchy", "sellmeier", "table", "material") + tuple(MODELS) + tuple(MIXTURES)


def _read_table(where: FileLocation, key: str, base_dir: Path, filename, required, optional=()) -> tuple[Path, dict]:
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
def _coefficient(where: FileLocation, model: str, field: str, spec, path: Optional[tuple], annotations: Optional[list],
                 *, lower=None, upper=None):
    """One coefficient of a dispersion model: a number, a list of numbers (one per oscillator or
    term), or a table with fitting words — the coefficient itself, recorded in ``annotations``
    under ``path + (field,)`` as ``model.field[layer]``, or one entry of a list, under ``path +
    (field, i)`` as ``model.field1[layer]``, ``model.field2[layer]`` … (1-based, as vendor
    software numbers terms). ``lower``/``upper``: the coefficient's physical range (recorded as
    the annotation's ``value_range``)."""
    key = f"{model}.{field}"
    if isinstance(spec, dict):
        return _free_coefficient(where, key, spec, path, (field,), annotations, lower, upper)
    if isinstance(spec, list) and any(isinstance(v, dict) for v in spec):
        spec = [_free_coefficient(where, f"{key}{i + 1}", v, path, (field, i), annotations, lower, upper)
                if isinstance(v, dict) else v for i, v in enumerate(spec)]
    if is_number(spec):
        return float(spec)
    return read_number_list(where, "n", spec, f"{model} {field}")


def _free_coefficient(where: FileLocation, key: str, spec: dict, path: Optional[tuple], field: tuple,
                      annotations: Optional[list], lower, upper) -> float:
    """A coefficient written as a table with fitting words (:func:`_coefficient`): its value."""
    if path is None:
        raise where.error(f"{key}: free coefficients are declared in [[layers]] only", "n")
    value_range = None if lower is None and upper is None else (lower, upper)
    spec = annotated(where, key, spec, path + field, "other", annotations, spectral=False, value_range=value_range)
    return read_number(where, "n", spec, what=key)


def _model_material(where: FileLocation, kind: str, value, path: Optional[tuple], annotations: Optional[list],
                    prefix: str = "") -> Material:
    """``n = { <model> = { coefficient = ..., ... } }`` (:data:`MODELS`)."""
    cls = MODELS[kind]
    fields = [f for f in dataclasses.fields(cls) if f.init]
    names = tuple(f.name for f in fields)
    if not isinstance(value, dict):
        raise where.error(f"{kind} must be an inline table of its coefficients {{ {', '.join(names)} }}", "n")
    reject_unknown_keys(FileLocation(where.source, f"{where.table}: key 'n': {kind}"), value, names)
    missing = [f.name for f in fields if f.default is dataclasses.MISSING and f.name not in value]
    if missing:
        raise where.error(f"{kind} needs {', '.join(missing)} (coefficients: {', '.join(names)})", "n")
    coefficients = {name: _coefficient(where, prefix + kind, name, value[name], path, annotations)
                    for name in names if name in value}
    try:
        return cls(**coefficients)
    except LayerstackError as e:
        raise where.error(f"{kind}: {e}", "n") from None


def read_material(where: FileLocation, table: Mapping, base_dir: Path, *, allow_k: bool, label: str,
                  path: Optional[tuple] = None, annotations: Optional[list] = None, prefix: str = "") -> Material:
    """The material of a table with an ``n`` key (and optionally ``k``). ``path``: where the
    material sits in the stack (``("layers", name, "index")``) when its coefficients may be
    declared free; their :class:`Annotation` records are appended to ``annotations``, named
    ``prefix`` + e.g. ``cauchy.A[layer]`` (``prefix``: the constituent of an effective medium, ``"bruggeman.materials1."``)."""
    if "n" not in table:
        raise where.error("missing (refractive index: a number or a dispersion table)", "n")
    spec = table["n"]
    k_given = "k" in table
    if k_given and not allow_k:
        raise where.error("not allowed here: this medium must be transparent (real index, no k)", "k")
    k = read_number(where, "k", table["k"], minimum=0.0, what="extinction coefficient") if k_given else 0.0

    if is_number(spec):
        return Index(read_number(where, "n", spec, positive=True, what="refractive index"), k)
    if not isinstance(spec, dict):
        raise where.error(f"must be a number or an inline table such as {{ cauchy = [A, B] }}, got {spec!r}", "n")

    inline_keys = ("wavelength_nm", "n", "k")
    if "wavelength_nm" in spec:
        reject_unknown_keys(FileLocation(where.source, f"{where.table}: key 'n'"), spec, inline_keys)
        wl = read_number_list(where, "n", spec["wavelength_nm"], "wavelength_nm")
        if "n" not in spec:
            raise where.error("inline table needs 'n' (and optionally 'k') lists next to 'wavelength_nm'", "n")
        nn = read_number_list(where, "n", spec["n"], "n")
        kk = read_number_list(where, "n", spec["k"], "k") if "k" in spec else None
        return _tabulated(where, wl, nn, kk, k_given, k, allow_k, f"{label} (inline table)")

    chosen = [name for name in spec if name in _DISPERSION_KEYS]
    extra = ("source", "shelf") if "material" in spec else ()
    reject_unknown_keys(FileLocation(where.source, f"{where.table}: key 'n'"), spec, _DISPERSION_KEYS + extra)
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
    if kind in MODELS or kind in MIXTURES:
        if k_given:
            raise where.error(f"not allowed with n = {{ {kind} = ... }}: the model gives k itself", "k")
        if kind in MIXTURES:
            return _mixture(where, kind, value, base_dir, label, path, annotations, prefix, allow_k)
        return _model_material(where, kind, value, path, annotations, prefix)
    if kind == "cauchy":
        if isinstance(value, list) and any(isinstance(v, dict) for v in value):  # free coefficients
            if len(value) > 3:
                raise where.error(f"cauchy takes 1 to 3 coefficients [A, B, C] (λ in µm), got {len(value)}", "n")
            value = [_coefficient(where, prefix + "cauchy", c, v, path, annotations) for c, v in zip("ABC", value)]
        coef = read_number_list(where, "n", value, "cauchy coefficients [A, B, C]")
        if coef.size > 3:
            raise where.error(f"cauchy takes 1 to 3 coefficients [A, B, C] (λ in µm), got {coef.size}", "n")
        if coef[0] <= 0:
            raise where.error(f"cauchy A must be > 0, got {coef[0]:g}", "n")
        A, B, C = (list(coef) + [0.0, 0.0])[:3]
        return Cauchy(A, B, C, k)
    if kind == "sellmeier":
        if not isinstance(value, dict):
            raise where.error(f"sellmeier must be an inline table {{ B = [...], C = [...] }}, got {value!r}", "n")
        reject_unknown_keys(FileLocation(where.source, f"{where.table}: key 'n': sellmeier"), value, ("B", "C"))
        if "B" not in value or "C" not in value:
            raise where.error("sellmeier needs both B = [...] and C = [...] (C in µm²)", "n")
        B, C = (_coefficient(where, prefix + "sellmeier", c, value[c], path, annotations) if isinstance(value[c], list)
                else read_number_list(where, "n", value[c], f"sellmeier {c}") for c in ("B", "C"))
        if B.shape != C.shape:
            raise where.error(f"sellmeier B and C must have the same length, got {B.size} and {C.size}", "n")
        return Sellmeier(B, C, k)
    # table
    path, cols = _read_table(where, "n", base_dir, value, ("wavelength_nm", "n"), ("k",))
    return _tabulated(where, cols["wavelength_nm"], cols["n"], cols.get("k"), k_given, k, allow_k,
                      f"{path.name} ({label})", file=str(value))


def _mixture(where: FileLocation, kind: str, value, base_dir: Path, label: str, path: Optional[tuple],
             annotations: Optional[list], prefix: str, allow_k: bool) -> Material:
    """``n = { bruggeman = { materials = [<n>, <n>, ...], fractions = f } }`` (:data:`MIXTURES`):
    each constituent as ``n`` is written (or ``{ n = ..., k = ... }``), its free coefficients
    named ``bruggeman.materials1.cauchy.A[layer]``; ``fractions`` the volume fraction(s) of the
    first m − 1 materials (a number for two, else a list; the last fills the rest), each in
    [0, 1] and free like any coefficient (default bounds [0, 1]) as ``bruggeman.fractions[layer]``
    or, in a list, ``bruggeman.fractions1[layer]`` …"""
    cls = MIXTURES[kind]
    inner = FileLocation(where.source, f"{where.table}: key 'n': {kind}")
    if not isinstance(value, dict):
        raise where.error(f"{kind} must be an inline table {{ materials = [<n>, <n>], fractions = <number> }}", "n")
    reject_unknown_keys(inner, value, ("materials", "fractions"))
    mats, fractions = value.get("materials"), value.get("fractions")
    if not isinstance(mats, list) or len(mats) < 2:
        raise where.error(f"{kind} needs materials = [<n>, <n>, ...] (two or more, each written as n is), "
                          f"got {mats!r}", "n")
    if fractions is None:
        raise where.error(f"{kind} needs fractions = <volume fraction of the first material> "
                          f"(a list of {len(mats) - 1} for {len(mats)} materials; the last fills the rest)", "n")
    materials = []
    for i, m in enumerate(mats):
        table = m if isinstance(m, dict) and "n" in m and set(m) <= {"n", "k"} else {"n": m}
        at = FileLocation(where.source, f"{where.table}: {kind} material {i + 1}")
        materials.append(read_material(at, table, base_dir, allow_k=allow_k, label=f"{label} {kind} material {i + 1}",
                                       path=None if path is None else path + ("materials", i), annotations=annotations,
                                       prefix=f"{prefix}{kind}.materials{i + 1}."))
    f = _coefficient(where, prefix + kind, "fractions", fractions, path, annotations, lower=0.0, upper=1.0)
    try:
        return cls(materials, f)
    except LayerstackError as e:
        raise where.error(f"{kind}: {e}", "n") from None


def _database_material(where: FileLocation, spec: Mapping, k_given: bool, allow_k: bool) -> Material:
    """``n = { material = "Au", source = "Johnson", shelf = "main" }``: the refractiveindex.info
    database (n and k from the same page; no separate ``k`` key)."""
    from .._media.database import material

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


#: A negative entry of a table that must be >= 0 (α, ρg, the k column of an index table) no
#: larger in magnitude than this fraction of the table's largest value is rounding or baseline
#: noise of a measured table (an α from −ln T / h, T known to 1e-3, dips a few 1e-9 /nm below
#: zero where the sheet is clear, against 1e-5–1e-4 /nm where it absorbs): it is clipped to 0,
#: with a :class:`LayerstackWarning` naming the table and column; a larger one is refused.
NEGATIVE_RTOL = 1e-3


def _clip_rounding_negatives(where: FileLocation, key: str, values: np.ndarray, what: str) -> np.ndarray:
    """``values`` with negatives within :data:`NEGATIVE_RTOL` of the largest value set to 0
    (warned about); larger negatives are left for :func:`check_range` to refuse."""
    low = values < 0
    if not np.any(low):
        return values
    top = float(np.max(np.abs(values)))
    if float(np.min(values)) < -NEGATIVE_RTOL * top or top == 0:
        return values
    import warnings

    warnings.warn(f"{where.source}: {where.table}: key {key!r}: {what}: {int(low.sum())} negative value(s) down to "
                  f"{float(np.min(values)):.3g} (within {NEGATIVE_RTOL:g} of the largest value, {top:.3g}: rounding "
                  "or baseline noise) set to 0", LayerstackWarning, stacklevel=3)
    return np.where(low, 0.0, values)


def _tabulated(where, wl, n, k_col, k_given, k, allow_k, name, file=None) -> Tabulated:
    what = f"table {file!r}" if file else "inline table"
    check_grid(where, "n", wl, what)
    for col, v in (("n", n), ("k", k_col)):
        if v is not None and v.shape != wl.shape:
            raise where.error(f"{what}: column {col} has {v.size} values for {wl.size} wavelengths", "n")
    check_range(where, "n", n, f"{what}: column n", lo=np.finfo(float).tiny)
    if k_col is not None:
        if k_given:
            raise where.error(f"k is given both as a key and as a column of the {what}; keep one", "k")
        k_col = _clip_rounding_negatives(where, "n", k_col, f"{what}: column k")
        check_range(where, "n", k_col, f"{what}: column k", lo=0.0)
        if not allow_k and np.any(k_col != 0):
            raise where.error(f"{what}: this medium must be transparent (k = 0)", "n")
    elif k_given:
        k_col = np.full_like(wl, k)
    return Tabulated(wl, n, k_col, name=name)


def read_spectrum(where: FileLocation, key: str, spec, base_dir: Path, column: str, label: str, *, lo, hi):
    """A number or a tabulated spectrum (file or inline) for ``alpha_per_nm`` or ``rho_g``."""
    if is_number(spec):
        return read_number(where, key, spec, minimum=lo, maximum=hi)
    if not isinstance(spec, dict):
        raise where.error(
            f"must be a number, {{ table = \"file.csv\" }} or {{ wavelength_nm = [...], values = [...] }}, got {spec!r}",
            key,
        )
    if "table" in spec:
        reject_unknown_keys(FileLocation(where.source, f"{where.table}: key {key!r}"), spec, ("table",))
        path, cols = _read_table(where, key, base_dir, spec["table"], ("wavelength_nm", column))
        wl, values, what, name = cols["wavelength_nm"], cols[column], f"table {spec['table']!r}", f"{path.name} ({label})"
    else:
        reject_unknown_keys(FileLocation(where.source, f"{where.table}: key {key!r}"), spec, ("wavelength_nm", "values", "table"))
        if "wavelength_nm" not in spec or "values" not in spec:
            raise where.error("give { table = \"file.csv\" } or both wavelength_nm = [...] and values = [...]", key)
        wl = read_number_list(where, key, spec["wavelength_nm"], "wavelength_nm")
        values = read_number_list(where, key, spec["values"], "values")
        what, name = "inline table", f"{label} (inline table)"
        if values.shape != wl.shape:
            raise where.error(f"{what}: {values.size} values for {wl.size} wavelengths", key)
    check_grid(where, key, wl, what)
    if lo == 0.0:
        values = _clip_rounding_negatives(where, key, values, f"{what}: column {column}")
    check_range(where, key, values, what, lo=lo, hi=hi)
    return TabulatedSpectrum(wl, values, name=name)
