r"""Stack files read: the TOML schema of a :class:`~layerstack_jax.Stack` (documented in
:mod:`layerstack_jax.io`) becomes a stack — :func:`stack_from_dict`, :func:`load_stack`. The
tables this module reads itself are the stack's: ``[ambient]``, ``[[layers]]`` and the exits
(``[substrate]``, ``[background]``, ``[kubelka_munk]``); a material is read by
:mod:`.material_file`, the ``[instrument]`` table by :mod:`.instrument_file`, the fitting words
beside a value by :mod:`.annotations`; :mod:`.stack_writer` writes the schema back.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Optional

import numpy as np

from .._base.validate import LayerstackError
from .._media.materials import Index
from .._stacks.kubelka_munk import KubelkaMunk, Mixture, Paint
from .._stacks.stack import LambertianBackground, Layer, Stack, Substrate
from .annotations import ANNOTATION_KEYS, annotated
from .file_grammar import (
    FileLocation,
    named_tables,
    read_number,
    read_toml,
    reject_unknown_keys,
)
from .instrument_file import read_instrument_table
from .material_file import read_material, read_spectrum

__all__ = ["stack_from_dict", "load_stack"]

_TOP_KEYS = ("description", "ambient", "layers", "substrate", "background", "kubelka_munk", "instrument")
_LAYER_KEYS = ("name", "n", "k", "thickness_nm", "coherent", "alpha_per_nm")
_SUBSTRATE_KEYS = ("n", "k")
_BACKGROUND_KEYS = ("n", "rho_g")
_AMBIENT_KEYS = ("n",)
_KUBELKA_MUNK_KEYS = ("n", "thickness_nm", "ground_reflectance", "K_per_nm", "S_per_nm", "pigments")
_PIGMENT_KEYS = ("name", "K_per_nm", "S_per_nm", "concentration")


def _layer(where: FileLocation, table: Mapping, base_dir: Path, name: str, index: int = 0, annotations: Optional[list] = None) -> Layer:
    reject_unknown_keys(where, table, _LAYER_KEYS)
    if "thickness_nm" not in table:
        raise where.error("missing (layer thickness in nm)", "thickness_nm")
    table = dict(table)
    spec = annotated(where, "thickness_nm", table["thickness_nm"], ("layers", name, "thickness"), "thickness", annotations,
                       spectral=False)
    thickness = read_number(where, "thickness_nm", spec, minimum=0.0, what="nm")
    for key, field, kind in (("n", "n", "n"), ("k", "k", "coefficient")):
        if key in table and isinstance(table[key], dict) and any(k in table[key] for k in ("value",) + ANNOTATION_KEYS):
            table[key] = annotated(where, key, table[key], ("layers", name, "index", field), kind, annotations, spectral=False)
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
        spec = annotated(where, "alpha_per_nm", table["alpha_per_nm"], ("layers", name, "alpha"), "alpha", annotations,
                           spectral=True)
        alpha = read_spectrum(where, "alpha_per_nm", spec, base_dir, "alpha_per_nm",
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
        spec = annotated(where, "thickness_nm", km["thickness_nm"], ("exit", "thickness"), "thickness", annotations,
                           spectral=False)
        thickness = read_number(where, "thickness_nm", spec, minimum=0.0, what="nm")
    ground = 0.0
    if "ground_reflectance" in km:
        spec = annotated(where, "ground_reflectance", km["ground_reflectance"], ("exit", "ground"), "rho_g", annotations,
                           spectral=True)
        ground = read_spectrum(where, "ground_reflectance", spec, base_dir, "ground_reflectance",
                           "kubelka_munk ground reflectance", lo=0.0, hi=1.0)

    def constants(w: FileLocation, t: Mapping, label: str):
        for key in ("K_per_nm", "S_per_nm"):
            if key not in t:
                raise w.error(f"missing ({'absorption K' if key[0] == 'K' else 'scattering S'} in 1/nm)", key)
        return [read_spectrum(w, key, t[key], base_dir, key, f"{label} {key[0]}", lo=0.0, hi=None)
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
            spec = annotated(w, "concentration", t["concentration"], ("exit", "paint", "concentrations", i),
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
            spec = annotated(where, "rho_g", bg["rho_g"], ("exit", "reflectance"), "rho_g", annotations, spectral=True)
            rho = read_spectrum(where, "rho_g", spec, base_dir, "rho_g", "background rho_g", lo=0.0, hi=1.0)
            exit_ = LambertianBackground(index, rho)
        if "instrument" in d:  # checked here (every loader refuses a bad table); applied by the caller
            read_instrument_table(source, _table("instrument"), annotations, [layer.name for layer in layers])
        return Stack(ambient=ambient, layers=layers, exit=exit_)
    except LayerstackError as e:
        msg = str(e)
        if msg.startswith(f"{source}:"):
            raise
        raise LayerstackError(f"{source}: {msg}") from None



def load_stack(path) -> Stack:
    """Read a stack file (TOML, schema in the module docstring). Relative table file names are
    resolved against the file's directory. Raises :class:`LayerstackError` naming the file and
    the offending table/key for any problem. Units and shapes as in :func:`stack_from_dict`
    (thicknesses in nm, α in 1/nm; tables become leaves of shape ``(table,)``)."""
    path = Path(path)
    return stack_from_dict(read_toml(path), path.parent, source=str(path))
