"""Generate docs/api.md from the docstrings of the public names of ``layerstack_jax`` and ``fitting``.

    python docs/make_api.py            # writes docs/api.md, lists docstring gaps on stderr
    python docs/make_api.py --check    # exit 1 if docs/api.md is out of date

The public names are those re-exported in ``layerstack_jax/__init__.py`` and ``fitting/__init__.py``
(``from ._x import Name as Name``), in that file's order. For each: its kind, signature, defining module and docstring;
for classes also their public methods and properties. A docstring that names no unit or no shape
is reported on stderr (a heuristic: it looks for unit and shape words), for authors to fix.
"""

from __future__ import annotations

import ast
import inspect
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import fitting  # noqa: E402
import layerstack_jax  # noqa: E402

TARGET = ROOT / "docs" / "api.md"
UNIT_WORDS = re.compile(r"\bnm\b|1/nm|1/sr|degree|radian|\brad\b|dimensionless|unitless|µm|\bin \[0, 1\]")
SHAPE_WORDS = re.compile(r"shape|\(wl|wl\)|\(\*|scalar|1-D")

GROUPS = [
    ("Stacks and materials", ("Stack", "Layer", "Substrate", "LambertianBackground", "TabulatedSpectrum",
                              "Material", "Index", "Cauchy", "Sellmeier", "Tabulated")),
    ("Computing", ("specular", "diffuse", "reflectance", "invert_background", "Response", "Diffuse")),
    ("Geometries", ("Geometry", "Sphere", "Directional", "BRDF", "Specular", "parse_geometry")),
    ("Building blocks", ("fresnel_amplitudes", "normal_wavevector", "hemispherical_rule", "DEFAULT_NODES")),
    ("Files", ("load_stack", "stack_from_dict", "stack_to_dict", "read_csv_columns", "save_spectra_csv",
               "parse_wavelengths")),
    ("Errors", ("LayerstackError",)),
]

FITTING_GROUPS = [
    ("Fitting: parameters", ("Parameter", "thickness", "alpha", "rho_g", "index_n", "dispersion", "bspline_basis")),
    ("Fitting: data, objective, solvers", ("Dataset", "Objective", "resample", "fit", "METHODS", "HOST_METHODS", "FitResult",
                                            "fit_batch", "BatchResult", "calibration_series", "background_rho_g")),
    ("Design", ("SpectralTarget", "ColourTarget", "merit", "optimize_thicknesses", "DesignResult",
                "with_thicknesses", "needle_function", "NeedleScan", "insert_needle", "needle_design",
                "RobustSpec", "thickness_yield", "YieldResult")),
]


SECTION = re.compile(r"^(Args|Arguments|Attributes|Returns|Raises|Parameters|Shapes?):\s*$")
ITEM = re.compile(r"^ {4}(\*{0,2}[\w, .*]+?):\s+(.*)$")


def rst_inline(text: str) -> str:
    """``x`` -> `x`, :math:`x` -> $x$, :func:`x` / :class:`~a.x` -> `x`."""
    text = re.sub(r":math:`([^`]+)`", r"$\1$", text)
    text = re.sub(r":\w+:`~?([^`]+)`", lambda m: f"`{m.group(1).split('.')[-1]}`", text)
    return re.sub(r"``([^`]+)``", r"`\1`", text)


def doc_to_markdown(doc: str) -> str:
    """Google-style docstring to Markdown: sections as bold labels with bullet items, doctest
    lines and ``.. math::`` blocks fenced, RST inline markup translated."""
    out: list[str] = []
    lines = doc.splitlines()
    i = 0
    in_section = False
    while i < len(lines):
        line = lines[i]
        if line.startswith(">>>"):
            block = []
            while i < len(lines) and (lines[i].startswith(">>>") or lines[i].startswith("...")):
                block.append(lines[i])
                i += 1
            out += ["```python", *block, "```"]
            continue
        if line.strip().startswith(".. math::"):
            indent = len(line) - len(line.lstrip())
            i += 1
            block = []
            while i < len(lines) and (not lines[i].strip() or len(lines[i]) - len(lines[i].lstrip()) > indent):
                block.append(lines[i].strip())
                i += 1
            out += ["$$", " ".join(b for b in block if b), "$$", ""]
            continue
        m = SECTION.match(line)
        if m:
            out += ["", f"**{m.group(1)}**", ""]
            in_section = True
            i += 1
            continue
        if in_section and line.startswith("    "):
            item = ITEM.match(line)
            if item and not line.startswith("     "):
                out.append(f"- `{item.group(1)}`: {rst_inline(item.group(2))}")
            elif out and out[-1].startswith("- "):
                out[-1] += " " + rst_inline(line.strip())
            else:
                out.append("- " + rst_inline(line.strip()))
            i += 1
            continue
        if not line.strip():
            in_section = False
        out.append(rst_inline(line.lstrip() if in_section else line))
        i += 1
    return "\n".join(out).strip("\n")


def public_names(package=layerstack_jax) -> list[str]:
    """Names re-exported in the package __init__, in order."""
    tree = ast.parse((ROOT / package.__name__ / "__init__.py").read_text(encoding="utf-8"))
    names = []
    for node in tree.body:
        if isinstance(node, ast.ImportFrom):
            names += [a.asname or a.name for a in node.names]
    return names


def signature(obj) -> str:
    """``inspect.signature`` with string annotations unquoted (``'Stack'`` -> ``Stack``)."""
    try:
        text = str(inspect.signature(obj))
    except (TypeError, ValueError):
        return "(...)"
    text = re.sub(r"ForwardRef\('([^']+)'\)", r"\1", text)
    return re.sub(r"(: |-> )'([^']+)'", r"\1\2", text)


def kind(obj) -> str:
    if inspect.isclass(obj):
        if issubclass(obj, BaseException):
            return "exception"
        if issubclass(obj, tuple) and hasattr(obj, "_fields"):
            return "named tuple"
        return "class"
    if callable(obj):
        return "function"
    return "constant"


def members(cls) -> list[tuple[str, object]]:
    """Public methods and properties defined on the class itself."""
    out = []
    for name, value in vars(cls).items():
        if name.startswith("_") or name in getattr(cls, "_fields", ()):
            continue
        if isinstance(value, property) or inspect.isfunction(value):
            out.append((name, value))
    return out


def entry(name: str, gaps: list[str], package=layerstack_jax) -> list[str]:
    obj = getattr(package, name)
    k = kind(obj)
    module = getattr(obj, "__module__", None) or package.__name__
    lines = [f"### `{name}`", ""]
    if k == "constant":
        module = ".".join(_constant_source(name, package).relative_to(ROOT).with_suffix("").parts)
        lines += [f"*constant* `{name} = {obj!r}` — defined in `{module}`", ""]
        doc = _constant_doc(name, package)
    else:
        lines += [f"*{k}*, defined in `{module}`", "", "```python", f"{name}{signature(obj)}", "```", ""]
        doc = inspect.getdoc(obj) or ""
    if doc:
        lines += [doc_to_markdown(doc), ""]
    else:
        lines += ["*(no docstring)*", ""]
    if k in ("class", "named tuple"):
        for mname, value in members(obj):
            mdoc = inspect.getdoc(value) or "*(no docstring)*"
            mdoc = rst_inline(" ".join(mdoc.split()))
            if isinstance(value, property):
                lines += [f"- property `{mname}` — {mdoc}"]
            else:
                lines += [f"- method `{mname}{signature(value)}` — {mdoc}"]
        if members(obj):
            lines += [""]
    if k in ("function", "class", "named tuple", "constant") and name not in _NO_UNITS_EXPECTED:
        sig = "" if k == "constant" else signature(obj)
        has_units = UNIT_WORDS.search(doc) or re.search(r"_(nm|deg|rad|per_nm)\b", sig)
        missing = [w for w, ok in (("units", has_units), ("shapes", SHAPE_WORDS.search(doc))) if not ok]
        if missing:
            gaps.append(f"{name}: docstring names no {' and no '.join(missing)}")
    return lines


# Names for which units/shapes make no sense (errors, abstract bases, parsers of text, name
# tables and database look-ups that return only strings).
_NO_UNITS_EXPECTED = {"LayerstackError", "Geometry", "Material", "parse_geometry", "read_csv_columns",
                      "stack_to_dict", "DEFAULT_NODES", "Stack", "OBSERVERS", "database_version",
                      "material_sources", "METHODS", "HOST_METHODS"}


def _constant_source(name: str, package=layerstack_jax) -> Path:
    """The private module that defines the constant ``name`` (``NAME = …`` at top level)."""
    for path in sorted((ROOT / package.__name__).glob("*.py")):
        if any(line.startswith(f"{name} =") or line.startswith(f"{name}:") for line in path.read_text(encoding="utf-8").splitlines()):
            return path
    raise LookupError(f"no module of {package.__name__} defines {name}")


def _constant_doc(name: str, package=layerstack_jax) -> str:
    """The ``#:`` comment block above a module-level constant."""
    lines = _constant_source(name, package).read_text(encoding="utf-8").splitlines()
    for i, line in enumerate(lines):
        if line.startswith(f"{name} =") or line.startswith(f"{name}:"):
            doc = []
            j = i - 1
            while j >= 0 and lines[j].startswith("#:"):
                doc.insert(0, lines[j][2:].strip())
                j -= 1
            return " ".join(doc)
    return ""


def _package_groups(package, groups) -> list:
    names = public_names(package)
    grouped = [n for _, g in groups for n in g]
    missing = [n for n in names if n not in grouped]
    return [(t, tuple(n for n in g if n in names)) for t, g in groups] + (
        [(f"Other ({package.__name__})", tuple(missing))] if missing else [])


def build() -> tuple[str, list[str]]:
    sections = [(layerstack_jax, _package_groups(layerstack_jax, GROUPS)),
                (fitting, _package_groups(fitting, FITTING_GROUPS))]
    gaps: list[str] = []
    out = [
        "<!-- Generated by docs/make_api.py from the docstrings: edit those, then run it. -->",
        "",
        "# API reference",
        "",
        f"`layerstack_jax` {layerstack_jax.__version__} (the physics) and `fitting` (inverse problems and "
        "design). Every public name, as re-exported in `layerstack_jax/__init__.py` and "
        "`fitting/__init__.py`. Units: wavelengths and thicknesses in nm, α in 1/nm, angles in "
        "radians in functions and degrees in geometry objects; spectra are shaped `(..., wl)` with the "
        "wavelength last and polarization `(s, p)` on axis −2 of `specular` outputs. See "
        "[physics.md](physics.md) for the formulas.",
        "",
    ]
    anchors: dict[tuple, str] = {}
    seen: dict[str, int] = {}
    for package, groups in sections:
        for title, group in groups:
            for n in group:
                base = n.lower()
                anchors[(package.__name__, n)] = base if base not in seen else f"{base}-{seen[base]}"
                seen[base] = seen.get(base, 0) + 1
    for package, groups in sections:
        for title, group in groups:
            out += [f"- **{title}**: " + ", ".join(f"[`{n}`](#{anchors[(package.__name__, n)]})" for n in group)]
    out += [""]
    for package, groups in sections:
        for title, group in groups:
            out += [f"## {title}", ""]
            for name in group:
                out += entry(name, gaps, package)
    return "\n".join(out).rstrip("\n") + "\n", gaps


def main(argv: list[str]) -> int:
    text, gaps = build()
    if "--check" in argv:
        current = TARGET.read_text(encoding="utf-8") if TARGET.exists() else ""
        if current != text:
            print("docs/api.md is out of date: run python docs/make_api.py", file=sys.stderr)
            return 1
        return 0
    TARGET.write_text(text, encoding="utf-8")
    n = len(public_names(layerstack_jax)) + len(public_names(fitting))
    print(f"wrote {TARGET.relative_to(ROOT)} ({n} public names)", file=sys.stderr)
    for gap in gaps:
        print(f"  docstring gap: {gap}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
