r"""Stack files: the TOML schema of a :class:`~layerstack_jax.Stack` (documented in
:mod:`layerstack_jax.io`), read by :func:`load_stack` / :func:`stack_from_dict`, written by
:func:`save_stack` / :func:`stack_to_dict`. This module is the schema's one owner. A value may
carry fitting words beside it (``{ value = ..., free = true, min = ..., max = ... }``,
:data:`ANNOTATION_KEYS`): the reader takes the value and returns the words unread, as
:class:`Annotation` records; :mod:`fitting` reads them.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Mapping, NamedTuple, Optional

import numpy as np

from .._base.leaves import file_fields
from .._base.validate import LayerstackError, LayerstackWarning, is_concrete
from .._media.effective_medium import Bruggeman, Looyenga
from .._media.materials import Cauchy, Index, Material, Sellmeier, Tabulated
from .._media.oscillators import CauchyUrbach, CodyLorentz, Drude, Lorentz, TaucLorentz
from .._stacks.kubelka_munk import KubelkaMunk, Mixture, Paint
from .._stacks.stack import LambertianBackground, Layer, Stack, Substrate, TabulatedSpectrum
from .file_grammar import (
    FileLocation,
    check_grid,
    check_range,
    is_number,
    named_tables,
    read_number,
    read_number_list,
    read_toml,
    reject_unknown_keys,
)
from .spectra_csv import read_csv_columns

__all__ = ["ANNOTATION_KEYS", "Annotation", "InstrumentSettings", "read_material", "stack_from_dict", "load_stack",
           "instrument_settings", "load_instrument", "instrument_geometry", "check_instrument_used", "stack_to_dict",
           "save_stack"]

_TOP_KEYS = ("description", "ambient", "layers", "substrate", "background", "kubelka_munk", "instrument")
#: keys of ``[instrument]`` that are not numbers: which layer a thickness spread applies to
_INSTRUMENT_STATIC = ("nonuniform_layer",)
_LAYER_KEYS = ("name", "n", "k", "thickness_nm", "coherent", "alpha_per_nm")
_SUBSTRATE_KEYS = ("n", "k")
_BACKGROUND_KEYS = ("n", "rho_g")
_AMBIENT_KEYS = ("n",)
_KUBELKA_MUNK_KEYS = ("n", "thickness_nm", "ground_reflectance", "K_per_nm", "S_per_nm", "pigments")
_PIGMENT_KEYS = ("name", "K_per_nm", "S_per_nm", "concentration")
#: Dispersion models read by name, their coefficients by field name, each a number, a list
#: (one per oscillator) or a free-parameter table: ``n = { tauc_lorentz = { Eg = 3.2, A = {
#: value = 150, free = true, min = 10, max = 500 }, E0 = 4.2, C = 1.5, eps_inf = 2.2 } }``.
_MODELS = {"lorentz": Lorentz, "drude": Drude, "tauc_lorentz": TaucLorentz, "cody_lorentz": CodyLorentz,
           "cauchy_urbach": CauchyUrbach}
#: Effective media read by name: ``n = { bruggeman = { materials = [<n>, <n>], fractions = 0.5 } }``,
#: each constituent written as ``n`` is (a number, a dispersion table, ``{ material = ... }``) or as
#: ``{ n = ..., k = ... }``; ``fractions`` as the class's (first m − 1 materials; the last fills the rest).
_MIXTURES = {"bruggeman": Bruggeman, "looyenga": Looyenga}
_DISPERSION_KEYS = ("cauchy", "sellmeier", "table", "material") + tuple(_MODELS) + tuple(_MIXTURES)


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
    spec = _annotated(where, key, spec, path + field, "other", annotations, spectral=False, value_range=value_range)
    return read_number(where, "n", spec, what=key)


def _model_material(where: FileLocation, kind: str, value, path: Optional[tuple], annotations: Optional[list],
                    prefix: str = "") -> Material:
    """``n = { <model> = { coefficient = ..., ... } }`` (:data:`_MODELS`)."""
    cls = _MODELS[kind]
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
    if kind in _MODELS or kind in _MIXTURES:
        if k_given:
            raise where.error(f"not allowed with n = {{ {kind} = ... }}: the model gives k itself", "k")
        if kind in _MIXTURES:
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
    """``n = { bruggeman = { materials = [<n>, <n>, ...], fractions = f } }`` (:data:`_MIXTURES`):
    each constituent as ``n`` is written (or ``{ n = ..., k = ... }``), its free coefficients
    named ``bruggeman.materials1.cauchy.A[layer]``; ``fractions`` the volume fraction(s) of the
    first m − 1 materials (a number for two, else a list; the last fills the rest), each in
    [0, 1] and free like any coefficient (default bounds [0, 1]) as ``bruggeman.fractions[layer]``
    or, in a list, ``bruggeman.fractions1[layer]`` …"""
    cls = _MIXTURES[kind]
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


def _spectrum(where: FileLocation, key: str, spec, base_dir: Path, column: str, label: str, *, lo, hi):
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


#: The words a stack file may write beside a value for a fit: ``thickness_nm = { value = 30000,
#: free = true, min = 0, max = 1e5 }``. The reader takes the value and hands the words on,
#: unread, as an :class:`Annotation`; what they mean (and which values they may take) belongs to
#: :mod:`fitting`, which reads them.
ANNOTATION_KEYS = ("free", "min", "max", "basis", "per_sample", "known", "smoothness")


class Annotation(NamedTuple):
    """A value of a stack file written with fitting words beside it (:data:`ANNOTATION_KEYS`),
    as found in the file: the reader has taken the value; the words are not interpreted here.

    Attributes:
        path: where the value lives in the stack, layers by name: ``("layers", "varnish",
            "thickness")``, ``("layers", "varnish", "alpha")``, ``("layers", name, "index", "n")``,
            ``("exit", "reflectance")``; a model coefficient ``("layers", name, "index", "A")``,
            one entry of a list ``("layers", name, "index", "B", 0)`` (0-based here, 1-based in
            the name), a constituent's ``("layers", name, "index", "materials", 0, "A")``; a
            field of the ``[instrument]`` table ``("datasets", "all", "angle_offset_deg")``.
        kind: what the value is: ``"thickness"`` (nm, also a pigment concentration: a number
            ≥ 0), ``"alpha"`` (1/nm), ``"rho_g"`` (fraction), ``"n"``, ``"coefficient"`` (the
            extinction coefficient k) or ``"other"`` (model coefficients, effective-medium
            fractions, instrument fields).
        name: a display name such as ``"thickness_nm[varnish]"``.
        key: the key the value is written under, for messages (``"thickness_nm"``, ``"B1"``).
        where: the table it is written in, for messages (``where.error(message, key)``).
        words: the fitting words as written (``{"free": True, "min": 0}``), unchecked.
        value: a number written as ``value = [a, b, ...]``, the list as written (the stack
            holds its first entry); None otherwise.
        spectral: the value is a spectrum (``alpha_per_nm``, ``rho_g``, ``ground_reflectance``).
        value_range: the value's physical range where the file's reader fixes one (an
            effective medium's volume fractions: ``(0.0, 1.0)``); None otherwise.
    """

    path: tuple
    kind: str
    name: str
    key: str
    where: FileLocation
    words: dict
    value: Optional[list] = None
    spectral: bool = False
    value_range: Optional[tuple] = None


def _annotated(where: FileLocation, key: str, spec, path: tuple, kind: str, annotations: Optional[list], *,
               spectral: bool, name: Optional[str] = None, value_range: Optional[tuple] = None):
    """The plain value spec of ``spec``: itself, or, when it is a table with fitting words
    (``{ value = ..., free = true, ... }``; for spectra the spectrum's own keys may stand for
    ``value``), its value — the words are recorded in ``annotations`` (when a list) as an
    :class:`Annotation`. A per-sample list ``value = [a, b, ...]`` gives its first entry."""
    if not isinstance(spec, dict) or not any(k in spec for k in ("value",) + ANNOTATION_KEYS):
        return spec
    words = {k: spec[k] for k in ANNOTATION_KEYS if k in spec}
    rest = {k: v for k, v in spec.items() if k not in ANNOTATION_KEYS and k != "value"}
    listed = None
    if "value" in spec:
        if rest:
            raise where.error(f"give either value = ... or {', '.join(rest)}, not both", key)
        plain = spec["value"]
        if isinstance(plain, list) and not spectral:
            if not plain or not all(is_number(v) for v in plain):
                raise where.error(f"value must be a number, or a list of numbers (one per sample), got {plain!r}", key)
            listed, plain = list(plain), plain[0]  # the stack itself holds one value: the first sample's
        elif not is_number(plain):
            raise where.error(f"value must be a number{'' if spectral else ', or a list of numbers (one per sample, with per_sample = true)'}, got {plain!r}", key)
    elif rest and spectral:
        plain = rest
    else:
        raise where.error("missing value = <number> next to free/min/max", key)
    if annotations is not None:
        display = name or (f"{key}[{path[1]}]" if path[0] == "layers" else key)
        annotations.append(Annotation(path=path, kind=kind, name=display, key=key, where=where, words=words,
                                      value=listed, spectral=spectral, value_range=value_range))
    return plain


def _layer(where: FileLocation, table: Mapping, base_dir: Path, name: str, index: int = 0, annotations: Optional[list] = None) -> Layer:
    reject_unknown_keys(where, table, _LAYER_KEYS)
    if "thickness_nm" not in table:
        raise where.error("missing (layer thickness in nm)", "thickness_nm")
    table = dict(table)
    spec = _annotated(where, "thickness_nm", table["thickness_nm"], ("layers", name, "thickness"), "thickness", annotations,
                       spectral=False)
    thickness = read_number(where, "thickness_nm", spec, minimum=0.0, what="nm")
    for key, field, kind in (("n", "n", "n"), ("k", "k", "coefficient")):
        if key in table and isinstance(table[key], dict) and any(k in table[key] for k in ("value",) + ANNOTATION_KEYS):
            table[key] = _annotated(where, key, table[key], ("layers", name, "index", field), kind, annotations, spectral=False)
    if "coherent" not in table:
        raise where.error(
            "missing: say coherent = true for a thin film (interference) or false for a thick layer "
            "(thicker than the coherence length, ~ a few µm)",
            "coherent",
        )
    coherent = table["coherent"]
    if not isinstance(coherent, bool):
        raise where.error(f"must be true or false, got {coherent!r}", "coherent")
    index = read_material(where, table, base_dir, allow_k=True, label=f"layer {name!r} n",
                          path=("layers", name, "index"), annotations=annotations)
    alpha = None
    if "alpha_per_nm" in table:
        if coherent:
            raise where.error(
                "is only for incoherent layers (coherent = false); give a coherent film an extinction coefficient k",
                "alpha_per_nm",
            )
        spec = _annotated(where, "alpha_per_nm", table["alpha_per_nm"], ("layers", name, "alpha"), "alpha", annotations,
                           spectral=True)
        alpha = _spectrum(where, "alpha_per_nm", spec, base_dir, "alpha_per_nm",
                          f"layer {name!r} alpha", lo=0.0, hi=None)
    return Layer(index, thickness, coherent=coherent, alpha=alpha, name=name)


def _kubelka_munk(source: str, km: Mapping, base_dir: Path, annotations: Optional[list]) -> KubelkaMunk:
    """The ``[kubelka_munk]`` table: a scattering body under the binder of index ``n`` —
    ``K_per_nm``, ``S_per_nm`` (numbers or spectra, 1/nm) or ``[[kubelka_munk.pigments]]`` (each
    with its K, S and a ``concentration``: Duncan's mixture), ``thickness_nm`` (absent: opaque),
    ``ground_reflectance`` (number or spectrum in [0, 1], default 0). ``thickness_nm``,
    ``ground_reflectance`` and each ``concentration`` may be free."""
    where = FileLocation(source, "[kubelka_munk]")
    reject_unknown_keys(where, km, _KUBELKA_MUNK_KEYS)
    index = read_material(where, km, base_dir, allow_k=False, label="kubelka_munk n")
    thickness = None
    if "thickness_nm" in km:
        spec = _annotated(where, "thickness_nm", km["thickness_nm"], ("exit", "thickness"), "thickness", annotations,
                           spectral=False)
        thickness = read_number(where, "thickness_nm", spec, minimum=0.0, what="nm")
    ground = 0.0
    if "ground_reflectance" in km:
        spec = _annotated(where, "ground_reflectance", km["ground_reflectance"], ("exit", "ground"), "rho_g", annotations,
                           spectral=True)
        ground = _spectrum(where, "ground_reflectance", spec, base_dir, "ground_reflectance",
                           "kubelka_munk ground reflectance", lo=0.0, hi=1.0)

    def constants(w: FileLocation, t: Mapping, label: str):
        for key in ("K_per_nm", "S_per_nm"):
            if key not in t:
                raise w.error(f"missing ({'absorption K' if key[0] == 'K' else 'scattering S'} in 1/nm)", key)
        return [_spectrum(w, key, t[key], base_dir, key, f"{label} {key[0]}", lo=0.0, hi=None)
                for key in ("K_per_nm", "S_per_nm")]

    if "pigments" in km:
        if "K_per_nm" in km or "S_per_nm" in km:
            raise where.error("give K_per_nm and S_per_nm, or [[kubelka_munk.pigments]], not both", "pigments")
        pigments, concentrations = [], []
        for i, (t, name, w) in enumerate(named_tables(source, km["pigments"], "kubelka_munk.pigments", "pigment")):
            reject_unknown_keys(w, t, _PIGMENT_KEYS)
            pigments.append(Paint(*constants(w, t, f"pigment {name!r}"), name=name))
            if "concentration" not in t:
                raise w.error("missing (the pigment's concentration in the mixture)", "concentration")
            spec = _annotated(w, "concentration", t["concentration"], ("exit", "paint", "concentrations", i),
                              "thickness", annotations, spectral=False,  # kind "thickness": a number >= 0
                              name=f"concentration[{name}]")
            concentrations.append(read_number(w, "concentration", spec, minimum=0.0))
        paint = Mixture(np.asarray(concentrations), pigments)
    else:
        paint = Paint(*constants(where, km, "kubelka_munk"))
    return KubelkaMunk(index, paint, thickness, ground)


# ------------------------------------------------------------------------------ stacks
def stack_from_dict(d: Mapping, base_dir=".", *, source: str = "<stack dict>", annotations: Optional[list] = None) -> Stack:
    """Build a :class:`Stack` from the parsed contents of a stack file (schema: module docstring).

    Args:
        d: the dict (as from ``tomllib``).
        base_dir: directory against which relative table file names are resolved.
        source: name used in error messages (the file name when called by :func:`load_stack`).
        annotations: if a list, each value written with fitting words (:data:`ANNOTATION_KEYS`)
            is appended to it as an :class:`Annotation` (layers named in their paths), its words
            unread; without a list the words are skipped.

    Units are those of the file: ``thickness_nm`` in nm, ``alpha_per_nm`` in 1/nm, ``rho_g`` a
    fraction in [0, 1]. Numbers stay scalars; tables become :class:`Tabulated` /
    :class:`TabulatedSpectrum` leaves of shape ``(table,)``, so the stack can be evaluated on
    any grid ``(wl,)`` inside the tables' range.
    """
    base_dir = Path(base_dir)
    top = FileLocation(source, "top level")
    if not isinstance(d, Mapping):
        raise top.error(f"expected a table of keys, got {type(d).__name__}")
    reject_unknown_keys(top, d, _TOP_KEYS)
    if "description" in d and not isinstance(d["description"], str):
        raise top.error("must be a string", "description")

    def _table(key):
        t = d[key]
        if not isinstance(t, Mapping):
            raise top.error(f"must be a table [{key}], got {t!r}", key)
        return t

    try:
        if "ambient" in d:
            where = FileLocation(source, "[ambient]")
            amb = _table("ambient")
            reject_unknown_keys(where, amb, _AMBIENT_KEYS + ("k",))
            ambient = read_material(where, amb, base_dir, allow_k=False, label="ambient n")
        else:
            ambient = Index(1.0)

        layers = [_layer(where, t, base_dir, name, i, annotations)
                  for i, (t, name, where) in enumerate(named_tables(source, d.get("layers", []), "layers", "layer"))]

        has_sub, has_bg, has_km = "substrate" in d, "background" in d, "kubelka_munk" in d
        if has_sub + has_bg + has_km > 1:
            raise top.error("give either [substrate] (specular), [background] (Lambertian) or [kubelka_munk] "
                            "(a scattering body), not both")
        if not (has_sub or has_bg or has_km):
            raise top.error("missing the exit medium: add a [substrate] (specular) or a [background] (Lambertian) "
                            "table, or a [kubelka_munk] scattering body")
        if has_km:
            exit_ = _kubelka_munk(source, _table("kubelka_munk"), base_dir, annotations)
        elif has_sub:
            where = FileLocation(source, "[substrate]")
            sub = _table("substrate")
            reject_unknown_keys(where, sub, _SUBSTRATE_KEYS)
            exit_ = Substrate(read_material(where, sub, base_dir, allow_k=True, label="substrate n"))
        else:
            where = FileLocation(source, "[background]")
            bg = _table("background")
            reject_unknown_keys(where, bg, _BACKGROUND_KEYS + ("k",))
            index = read_material(where, bg, base_dir, allow_k=False, label="background n")
            if "rho_g" not in bg:
                raise where.error("missing (intrinsic reflectance of the background, in [0, 1])", "rho_g")
            spec = _annotated(where, "rho_g", bg["rho_g"], ("exit", "reflectance"), "rho_g", annotations, spectral=True)
            rho = _spectrum(where, "rho_g", spec, base_dir, "rho_g", "background rho_g", lo=0.0, hi=1.0)
            exit_ = LambertianBackground(index, rho)
        if "instrument" in d:  # checked here (every loader refuses a bad table); applied by the caller
            _instrument_settings(source, _table("instrument"), annotations, [layer.name for layer in layers])
        return Stack(ambient=ambient, layers=layers, exit=exit_)
    except LayerstackError as e:
        msg = str(e)
        if msg.startswith(f"{source}:"):
            raise
        raise LayerstackError(f"{source}: {msg}") from None



# ------------------------------------------------------------------------------ the instrument
class InstrumentSettings(NamedTuple):
    """The ``[instrument]`` table of a stack file (schema: :mod:`layerstack_jax.io`, "The
    instrument"): fields of the measurement geometries of a fit or a prediction.

    Attributes:
        values: field name → number, in the geometry field's unit (``angle_offset_deg`` in
            degrees, ``bandwidth_nm`` in nm, ``thickness_spread`` dimensionless …).
        static: field name → value of the non-numeric fields (``nonuniform_layer``: a layer's
            name or 0-based position).
        where: ``"<file>: [instrument]"`` for messages.
    """

    values: dict
    static: dict
    where: str


def _instrument_settings(source: str, table: Mapping, annotations: Optional[list], layer_names: list) -> InstrumentSettings:
    """Read an ``[instrument]`` table: each key a number or a free-parameter table (declared as
    ``("datasets", "all", key)``: one value shared by every dataset whose geometry has the field)."""
    where = FileLocation(source, "[instrument]")
    values, static = {}, {}
    for key, spec in table.items():
        if key in _INSTRUMENT_STATIC:
            if not (isinstance(spec, str) or (isinstance(spec, int) and not isinstance(spec, bool))):
                raise where.error(f"must be a layer's name or 0-based position, got {spec!r}", key)
            if isinstance(spec, str) and spec not in layer_names:
                raise where.error(f"no layer named {spec!r} (layers: {layer_names})", key)
            if isinstance(spec, int) and not 0 <= spec < len(layer_names):
                raise where.error(f"the stack has {len(layer_names)} layer(s), no layer {spec}", key)
            static[key] = spec
            continue
        if isinstance(spec, dict) and not any(k in spec for k in ("value",) + ANNOTATION_KEYS):
            raise where.error(f"a number or {{ value = ..., free = true, min = ..., max = ... }}, got {spec!r}", key)
        plain = _annotated(where, key, spec, ("datasets", "all", key), "other", annotations, spectral=False)
        values[key] = read_number(where, key, plain)
    return InstrumentSettings(values, static, f"{source}: [instrument]")


def instrument_settings(d: Mapping, source: str) -> InstrumentSettings:
    """The ``[instrument]`` table of a parsed stack file ``d`` (from :func:`read_toml`; empty
    settings when it has none), checked like the rest of the file; ``source`` names the file in
    messages. Apply it to a geometry with :func:`instrument_geometry`."""
    table = d.get("instrument", {}) if isinstance(d, Mapping) else {}
    if not isinstance(table, Mapping):
        raise LayerstackError(f"{source}: instrument: must be a table [instrument], got {table!r}")
    names = [t.get("name") if isinstance(t, Mapping) else None for t in d.get("layers", [])]
    names = [n if isinstance(n, str) else f"layer {i + 1}" for i, n in enumerate(names)]
    return _instrument_settings(source, table, None, names)


def load_instrument(path) -> InstrumentSettings:
    """The ``[instrument]`` table of a stack file (:func:`instrument_settings` of the file read)."""
    path = Path(path)
    return instrument_settings(read_toml(path), str(path))


def instrument_geometry(geometry, settings: InstrumentSettings, *, partial: bool = False):
    """``geometry`` with the fields of ``settings`` set. Each key must be a field of it (a key
    that is not, e.g. ``bandwidth_nm`` for a sphere, is a :class:`LayerstackError` naming the
    key, the geometry and its fields) unless ``partial`` (several geometries share one table:
    each takes the keys it has; :func:`check_instrument_used` then checks that every key was
    taken by one). Returns the geometry unchanged when no key applies."""
    given = {**settings.values, **settings.static}
    fields = [f.name for f in dataclasses.fields(geometry)]
    if not partial:
        for key in given:
            if key not in fields:
                raise LayerstackError(f"{settings.where}: {key}: not a field of the geometry {geometry.label!r} "
                                      f"({type(geometry).__name__}; its fields: {', '.join(fields)})")
    given = {k: v for k, v in given.items() if k in fields}
    return dataclasses.replace(geometry, **given) if given else geometry


def check_instrument_used(settings: InstrumentSettings, geometries) -> None:
    """Raise naming the key when a key of ``settings`` is a field of none of ``geometries``."""
    fields = {f.name for g in geometries for f in dataclasses.fields(g)}
    for key in {**settings.values, **settings.static}:
        if key not in fields:
            labels = ", ".join(g.label for g in geometries) or "none"
            raise LayerstackError(f"{settings.where}: {key}: not a field of any geometry asked for ({labels})")


def load_stack(path) -> Stack:
    """Read a stack file (TOML, schema in the module docstring). Relative table file names are
    resolved against the file's directory. Raises :class:`LayerstackError` naming the file and
    the offending table/key for any problem. Units and shapes as in :func:`stack_from_dict`
    (thicknesses in nm, α in 1/nm; tables become leaves of shape ``(table,)``)."""
    path = Path(path)
    return stack_from_dict(read_toml(path), path.parent, source=str(path))


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
    elif type(m) in _MODEL_NAMES:  # a dispersion model or an effective medium: its fields by name
        out["n"] = {_MODEL_NAMES[type(m)]: _fields_to_dict(m, what)}
        k = 0.0
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


_MODEL_NAMES = {cls: name for name, cls in {**_MODELS, **_MIXTURES}.items()}


def _number_or_list(x, what: str):
    if is_concrete(x) and np.ndim(x) == 1:
        return np.asarray(x, float).tolist()
    return _scalar(x, what)


def _fields_to_dict(m: Material, what: str) -> dict:
    """The coefficients of a model (:data:`_MODELS`) or the materials and fractions of an effective
    medium (:data:`_MIXTURES`) as the stack file writes them."""
    if type(m) in _MIXTURES.values():
        materials = []
        for i, c in enumerate(m.materials):
            sub: dict = {}
            _material_to_dict(c, f"{what} material {i + 1}", sub)
            materials.append(sub if "k" in sub else sub["n"])
        return {"materials": materials, "fractions": _number_or_list(m.fractions, f"{what} fractions")}
    return {f.name: _number_or_list(getattr(m, f.name), f"{what} {f.name}") for f in dataclasses.fields(m) if f.init}


def _spectrum_to_dict(x, what: str):
    if isinstance(x, TabulatedSpectrum):
        return {"wavelength_nm": list(x.wavelength_nm), "values": np.asarray(x.values, float).tolist()}
    if callable(x) or np.ndim(x):
        raise LayerstackError(f"stack_to_dict: {what} must be a scalar or a TabulatedSpectrum")
    return _scalar(x, what)


def stack_to_dict(stack: Stack) -> dict:
    """The inverse of :func:`stack_from_dict`: a dict in the stack-file schema, tables inline.

    Works for stacks made of scalars, :class:`Index` (scalar), :class:`Cauchy`,
    :class:`Sellmeier`, :class:`Tabulated`, :class:`TabulatedSpectrum`, the dispersion models
    (:class:`TaucLorentz` …) and the effective media (:class:`Bruggeman`, :class:`Looyenga`) of
    these, over any exit (a :class:`KubelkaMunk` body's paint writes its own entries: K, S or one
    ``[[kubelka_munk.pigments]]`` table per pigment of a mixture); raises
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
    table = stack.exit.table  # the exit's own table; its numbers under the keys its fields declare
    d[table] = {}
    _material_to_dict(stack.exit.index, table, d[table])
    keys = {field: key for key, field in file_fields(stack.exit).items()}
    for f in dataclasses.fields(stack.exit):
        value = getattr(stack.exit, f.name)
        if f.name == "index" or f.metadata.get("static") or value is None:
            continue
        if f.name in keys:
            d[table][keys[f.name]] = _spectrum_to_dict(value, f"{table} {keys[f.name]}")
        elif callable(getattr(value, "file_table", None)):  # a part that writes its own entries (a paint)
            d[table].update(_entries_to_dict(value.file_table(), table))
        else:
            raise LayerstackError(f"stack_to_dict: the [{table}] field {f.name!r} has no stack-file form here; "
                                  "write this stack's file by hand")
    return d


def _entries_to_dict(entries: dict, where: str) -> dict:
    """A part's own stack-file entries (``file_table()``) with their values in file form: numbers
    and spectra as :func:`_spectrum_to_dict` writes them, lists of tables entry by entry."""
    out = {}
    for key, value in entries.items():
        if isinstance(value, str):
            out[key] = value
        elif isinstance(value, list):
            out[key] = [_entries_to_dict(v, f"{where}.{key}") for v in value]
        else:
            out[key] = _spectrum_to_dict(value, f"{where} {key}")
    return out


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


def _is_array_of_tables(x) -> bool:
    return isinstance(x, list) and bool(x) and all(isinstance(v, Mapping) for v in x)


def _toml_table(d: Mapping, what: str) -> list[str]:
    """The lines of table ``what``: its entries (inline values), then its arrays of tables
    (``[[what.key]]``, e.g. a Kubelka–Munk body's pigments)."""
    lines = [f"{_toml_key(k)} = {_toml_value(v, f'{what}.{k}')}" for k, v in d.items() if not _is_array_of_tables(v)]
    for k, v in d.items():
        if _is_array_of_tables(v):
            for item in v:
                lines += ["", f"[[{what}.{_toml_key(k)}]]", *_toml_table(item, f"{what}.{_toml_key(k)}")]
    return lines


def _dumps_stack(d: Mapping, header: str = "") -> str:
    """A stack dict (schema in the module docstring, e.g. from :func:`stack_to_dict`) as TOML
    text, ``header`` written first as ``#`` comment lines: top-level values, then every table
    (``[ambient]``, ``[[layers]]``, the exit's table …) in the dict's order."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    if lines:
        lines.append("")
    for key, value in d.items():
        if not isinstance(value, Mapping) and not _is_array_of_tables(value):
            lines.append(f"{_toml_key(key)} = {_toml_value(value, key)}")
    for key, value in d.items():
        if _is_array_of_tables(value):
            for item in value:
                lines += ["", f"[[{_toml_key(key)}]]", *_toml_table(item, _toml_key(key))]
        elif isinstance(value, Mapping):
            lines += ["", f"[{_toml_key(key)}]", *_toml_table(value, _toml_key(key))]
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


