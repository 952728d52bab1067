"""The fitting words of a stack file: ``thickness_nm = { value = 30000, free = true, min = 0 }``.

The stack file's readers take the value of such a table and record the words beside it, unread,
as an :class:`Annotation` (:func:`annotated`); their meaning belongs to :mod:`fitting`.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

from .file_grammar import FileLocation, is_number

__all__ = ["ANNOTATION_KEYS", "Annotation", "annotated"]

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


def annotated(where: FileLocation, key: str, spec, path: tuple, kind: str, annotations: Optional[list], *,
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
            if words.get("per_sample") is not True:  # else a prediction would silently take the first
                raise where.error(f"value = [...] gives one value per sample: add per_sample = true (got {plain!r})",
                                  key)
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
