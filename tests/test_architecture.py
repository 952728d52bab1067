"""The house stays one-way (issue 17, docs/architecture.md): read from the source, not run.

* nothing under ``layerstack_jax/`` imports ``fitting`` or ``layerstack_cli``; nothing under
  ``fitting/`` imports ``layerstack_cli``;
* ``fitting`` and ``layerstack_cli`` use ``layerstack_jax`` through its public names only (no
  ``layerstack_jax._module``, no ``_name``);
* no import cycle among the imports of ``layerstack_jax``, ``fitting``, ``layerstack_cli`` and
  ``benchmarks`` — module-level, inside functions and under ``TYPE_CHECKING`` alike (an import
  deferred into a function still ties two concepts together);
* no ``isinstance`` on a concrete geometry class outside the module that defines it;
* no access to private attributes of optimistix, equinox or jaxopt;
* comments and docstrings explain the code as it is: no dates, no before → after timings
  (history lives in commit messages and ``benchmarks/results/``).
"""

from __future__ import annotations

import ast
import inspect
import textwrap
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("layerstack_jax", "fitting", "layerstack_cli", "benchmarks")
GEOMETRY_CLASSES = {"Sphere": "sphere.py", "Directional": "directional.py", "BRDF": "directional.py",
                    "Specular": "specular.py", "Ellipsometric": "ellipsometer.py"}


def _modules(package: str) -> dict[str, Path]:
    return {".".join(p.relative_to(ROOT).with_suffix("").parts): p for p in (ROOT / package).rglob("*.py")}


def _imports(path: Path, module: str, *, top_level_only: bool, source: str | None = None) -> set[str]:
    """Absolute names of the modules ``path`` (or ``source``, written there) imports (relative
    imports resolved)."""
    tree = ast.parse(path.read_text(encoding="utf-8") if source is None else source)
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package
                for _ in range(node.level - 1):
                    base = base.rpartition(".")[0]
                name = f"{base}.{node.module}" if node.module else base
            else:
                name = node.module or ""
            out.add(name)
            out |= {f"{name}.{a.name}" for a in node.names}
    return out


@pytest.mark.parametrize("package, forbidden", [("layerstack_jax", ("fitting", "layerstack_cli")),
                                                ("fitting", ("layerstack_cli",))])
def test_dependencies_point_one_way(package, forbidden):
    bad = []
    for module, path in _modules(package).items():
        for name in _imports(path, module, top_level_only=False):
            if name.split(".")[0] in forbidden:
                bad.append(f"{path.relative_to(ROOT)} imports {name}")
    assert not bad, "\n".join(bad)


def _private_uses_of_layerstack_jax(source: str, where: str) -> list[str]:
    """Where the module ``source`` (named ``where`` in the findings) reaches into
    ``layerstack_jax``'s private modules or names: imports of ``layerstack_jax._…`` (or of a
    ``_name`` from it) and attributes ``ls._…`` of the package."""
    tree = ast.parse(source)
    aliases, bad = set(), []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "layerstack_jax":
                    aliases.add(a.asname or a.name)
                    if any(part.startswith("_") for part in a.name.split(".")[1:]):
                        bad.append(f"{where}:{node.lineno} import {a.name}")
        elif isinstance(node, ast.ImportFrom) and not node.level and (node.module or "").split(".")[0] == "layerstack_jax":
            parts = node.module.split(".")[1:]
            names = [a.name for a in node.names if a.name.startswith("_") and not a.name.startswith("__")]
            if any(part.startswith("_") for part in parts) or names:
                bad.append(f"{where}:{node.lineno} from {node.module} import "
                           + ", ".join(a.name for a in node.names))
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases
                and node.attr.startswith("_") and not node.attr.startswith("__")):
            bad.append(f"{where}:{node.lineno} {node.value.id}.{node.attr}")
    return bad


@pytest.mark.parametrize("package", ["fitting", "layerstack_cli"])
def test_fitting_and_cli_use_public_physics_only(package):
    """The fitting layer and the command line are clients of the physics like any user's code:
    every name they take from ``layerstack_jax`` is public (``__all__`` of the package or of a
    public submodule such as ``layerstack_jax.io``)."""
    import importlib

    bad = [b for path in _modules(package).values()
           for b in _private_uses_of_layerstack_jax(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT)))]
    assert not bad, "\n".join(bad)
    for path in _modules(package).values():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and not node.level and (node.module or "").startswith("layerstack_jax"):
                public = set(getattr(importlib.import_module(node.module), "__all__", ()))
                for a in node.names:
                    if a.name != "__version__" and public and a.name not in public:
                        bad.append(f"{path.relative_to(ROOT)}:{node.lineno} {a.name} is not in {node.module}.__all__")
    assert not bad, "\n".join(bad)


def test_the_private_use_check_can_fail():
    """The check above finds each form of reaching into the physics' internals."""
    source = ("import layerstack_jax as ls\nfrom layerstack_jax._stacks.stack import resolve\n"
              "from layerstack_jax._instruments import batched as _batched, Stack\nimport layerstack_jax._base.progress\nls._validate.warn_if\n"
              "from layerstack_jax import Stack\nfrom layerstack_jax.io import load_stack\nls.Stack\n")
    found = _private_uses_of_layerstack_jax(source, "probe")
    assert [f.split(":")[1].split()[0] for f in found] == ["2", "3", "4", "5"], found


# The floors of layerstack_jax, bottom up, and what each may import (its __init__ docstring says
# the same): a floor imports only floors below it; the top (the package's __init__, io, cli,
# render) may import any.
FLOORS = {
    "_base": set(),
    "_kernels": {"_base"},
    "_media": {"_base"},
    "_stacks": {"_base", "_kernels", "_media"},
    "_instruments": {"_base", "_kernels", "_media", "_stacks"},
    "_appearance": {"_base", "_kernels", "_media", "_stacks"},
    "_files": {"_base", "_media", "_stacks"},
}


def _floor_violations(modules: dict, source: str | None = None) -> list[str]:
    bad = []
    for module, path in modules.items():
        parts = module.split(".")
        if len(parts) < 3 or parts[1] not in FLOORS:
            continue
        for name in _imports(path, module, top_level_only=False, source=source):
            target = name.split(".")
            if target[0] != "layerstack_jax" or len(target) < 2 or target[1] == parts[1]:
                continue
            if target[1] not in FLOORS[parts[1]]:
                bad.append(f"{path.relative_to(ROOT)} imports {name} (floor {target[1]} is not below {parts[1]})")
    return bad


def test_every_floor_imports_only_floors_below_it():
    modules = _modules("layerstack_jax")
    floors = {p.name for p in (ROOT / "layerstack_jax").iterdir() if (p / "__init__.py").exists()} - {"render"}
    assert floors == set(FLOORS), "a new subpackage of layerstack_jax needs its place in FLOORS"
    flat = {p.name for p in (ROOT / "layerstack_jax").glob("*.py")}
    assert flat == {"__init__.py", "io.py", "cli.py"}, f"modules outside the floors: {sorted(flat)}"
    assert not _floor_violations(modules), "\n".join(_floor_violations(modules))
    # the check can fail: a kernel importing a stack is found
    probe = {"layerstack_jax._kernels.fresnel": ROOT / "layerstack_jax" / "_kernels" / "fresnel.py"}
    assert _floor_violations(probe, source="def f():\n    from .._stacks.stack import Stack\n")


def test_no_import_cycles():
    modules = {}
    for package in PACKAGES:
        modules |= _modules(package)
    graph = {m: {n for n in _imports(p, m, top_level_only=False) if n in modules and n != m}
             for m, p in modules.items()}
    # a module importing its own package's __init__ re-exports is not a cycle of concepts
    for m in graph:
        graph[m] = {n for n in graph[m] if not m.startswith(n + ".")}
    state: dict[str, int] = {}
    cycles = []

    def visit(m, trail):
        state[m] = 1
        for n in graph[m]:
            if state.get(n) == 1:
                cycles.append(" -> ".join(trail[trail.index(n):] + [n]) if n in trail else f"{m} -> {n}")
            elif n not in state:
                visit(n, trail + [n])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not cycles, "\n".join(cycles)


def test_no_isinstance_on_geometry_classes_outside_their_module():
    bad = []
    for package in PACKAGES:
        for module, path in _modules(package).items():
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "isinstance" and len(node.args) == 2:
                    names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                    names |= {n.attr for n in ast.walk(node.args[1]) if isinstance(n, ast.Attribute)}
                    for cls in names & set(GEOMETRY_CLASSES):
                        if path.name != GEOMETRY_CLASSES[cls] or package != "layerstack_jax":
                            bad.append(f"{path.relative_to(ROOT)}:{node.lineno} isinstance(..., {cls})")
    assert not bad, "\n".join(bad)


_PRIVATE = re.compile(r"\b(optx|optimistix|eqx|equinox|jaxopt|lx|lineax)\.(?:[A-Za-z]\w*\.)*_[A-Za-z]\w*|RESULTS\._")


def test_no_private_attributes_of_optimistix_equinox_jaxopt():
    bad = []
    for package in PACKAGES:
        for module, path in _modules(package).items():
            for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                code = line.split("#", 1)[0]
                if _PRIVATE.search(code):
                    bad.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not bad, "\n".join(bad)


def _exit_classes() -> dict:
    """Every exit medium the library defines (subclasses of ``ExitMedium``) -> its module's file name."""
    import layerstack_jax as ls

    found, todo = {}, [ls.ExitMedium]
    while todo:
        cls = todo.pop()
        todo += cls.__subclasses__()
        found[cls.__name__] = Path(__import__("sys").modules[cls.__module__].__file__).name
    return found


def test_no_code_asks_which_class_an_exit_is():
    """The exit-medium seam (issue 28): code outside an exit's own module never asks for its class
    (``isinstance(x, Substrate)``, ``isinstance(stack.exit, …)``, ``type(stack.exit)``); it asks the
    interface (``diffuse``, ``lower``, ``table``, ``label``) or the resolved stack (``rho_g``).
    Only the interface itself may be named (``isinstance(exit, ExitMedium)``: is this an exit?)."""
    classes = _exit_classes()
    interface = "ExitMedium"
    assert {"Substrate", "LambertianBackground"} <= set(classes)
    bad = []
    for package in PACKAGES:
        for module, path in _modules(package).items():
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if not isinstance(node, ast.Call):
                    continue
                fn = getattr(node.func, "id", None)
                if fn == "isinstance" and len(node.args) == 2:
                    names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                    names |= {n.attr for n in ast.walk(node.args[1]) if isinstance(n, ast.Attribute)}
                    subject = ast.unparse(node.args[0])
                    for cls in names & (set(classes) - {interface}):
                        if package != "layerstack_jax" or path.name != classes[cls]:
                            bad.append(f"{path.relative_to(ROOT)}:{node.lineno} isinstance(..., {cls})")
                    if "exit" in subject and names - {interface}:
                        bad.append(f"{path.relative_to(ROOT)}:{node.lineno} isinstance({subject}, ...)")
                if fn == "type" and node.args and "exit" in ast.unparse(node.args[0]):
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno} type({ast.unparse(node.args[0])})")
    assert not bad, "\n".join(bad)


_ROLE_TABLE = re.compile(r"""\(\s*["'](Layer|Index|Cauchy|Sellmeier|LambertianBackground|Substrate|Tabulated)["']\s*,\s*["']\w+["']\s*\)""")


def test_leaf_roles_come_from_field_declarations_only():
    """Leaf roles (batch axes, fixed optics, per-wavelength fit, stack-file key) are declared on the
    fields (``layerstack_jax._base.leaves.leaf``), not kept in tables elsewhere: no ``("Layer",
    "thickness")``-style (class name, field) pairs and no path tests on ``"reflectance"`` /
    ``"alpha"`` fields outside the modules that define them."""
    bad = []
    for package in PACKAGES:
        for module, path in _modules(package).items():
            text = path.read_text(encoding="utf-8")
            for i, line in enumerate(text.splitlines(), 1):
                code = line.split("#", 1)[0]
                if _ROLE_TABLE.search(code):
                    bad.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
                if re.search(r"""\[\s*["']exit["']\s*,\s*["']reflectance["']\s*\]|==\s*\(\s*["']exit["']\s*,\s*["']reflectance["']\s*\)""", code):
                    bad.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not bad, "\n".join(bad)


#: a date (not a version string such as ``v2026-05-24``), or a timing that narrates a change ("30 → 9 ms")
_HISTORY = re.compile(r"(?<![v\w])20\d\d-\d\d-\d\d\b|\d(?:\.\d+)?\s*(?:ms|s|µs)?\s*(?:→|->)\s*[\d.]+(?:[–-][\d.]+)?\s*(?:ms|s|µs)\b")


def _comments_and_docstrings(source: str):
    """``(line, text)`` of every comment and docstring of a module's ``source``."""
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            yield tok.start[0], tok.string
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                yield node.body[0].lineno, doc


def _history_in(source: str, where: str) -> list[str]:
    return [f"{where}:{line}: {m.group(0)!r}" for line, text in _comments_and_docstrings(source)
            for m in _HISTORY.finditer(text)]


def test_comments_carry_no_dates_or_before_after_timings():
    bad = [b for package in PACKAGES for path in _modules(package).values()
           for b in _history_in(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT)))]
    assert not bad, "history belongs in commit messages and benchmarks/results/:\n" + "\n".join(bad)


def test_the_history_check_can_fail():
    source = ('"""Module (measured 2026-11-27)."""\n# forward 100 → 91 ms\nx = 1  # 30 -> 9 ms\n'
              'def f():\n    """Release ``v2026-05-24``; 10 nm → 12 nm is a unit, not a timing."""\n')
    assert [b.split(":")[1] for b in _history_in(source, "probe")] == ["2", "3", "1"], _history_in(source, "probe")


def _own_members(cls) -> set[str]:
    return {k for k in vars(cls) if not k.startswith("__") and not k.startswith("_abc")}


def _concrete_subclasses(cls) -> list:
    out, todo = [], [cls]
    while todo:
        c = todo.pop()
        todo += c.__subclasses__()
        if not getattr(c, "__abstractmethods__", None):
            out.append(c)
    return out


def test_geometry_is_narrow_and_every_instrument_honours_it():
    """``Geometry`` holds what every instrument needs to be read (≤ 10 members); what only the
    spectrophotometers have lives in ``OpticalGeometry``; clients' extras (command-line columns,
    ellipsometer batching) live with their clients. Every concrete geometry implements every
    abstract member, and none of its members is a stub that raises NotImplementedError."""
    import layerstack_jax as ls

    members = _own_members(ls.Geometry)
    assert len(members) <= 10, sorted(members)
    assert not members & {"optics", "read", "prediction_columns", "polarized_columns", "supports_polarization",
                          "ellipsometry_angle", "from_ellipsometry", "reading_group", "background_factor"}
    concrete = _concrete_subclasses(ls.Geometry)
    assert {c.__name__ for c in concrete} >= {"Sphere", "Directional", "BRDF", "Specular", "Ellipsometric"}
    interface = set().union(*(getattr(c, "__abstractmethods__", set()) for c in (ls.Geometry, ls.OpticalGeometry)))
    assert interface >= {"measure", "label", "quantity_label", "parse", "optics", "read"}
    bad = []
    for cls in concrete:
        for base in (ls.Geometry, ls.OpticalGeometry):
            if issubclass(cls, base):
                for name in base.__abstractmethods__:
                    if getattr(getattr(cls, name), "__isabstractmethod__", False):
                        bad.append(f"{cls.__name__}.{name} is not implemented")
        for name in _own_members(cls) | members:
            member = getattr(cls, name, None)
            fn = getattr(member, "fget", member)
            try:
                source = ast.parse(textwrap.dedent(inspect.getsource(fn)))
            except (TypeError, OSError):
                continue
            for node in ast.walk(source):
                if isinstance(node, ast.Raise) and "NotImplementedError" in ast.unparse(node):
                    bad.append(f"{cls.__name__}.{name} raises NotImplementedError")
    assert not bad, "\n".join(bad)


def _escaped_docstrings(source: str, where: str) -> list[str]:
    """Docstrings holding a control character: a backslash sequence of LaTeX (``\\theta``,
    ``\\tfrac``, ``\\rho``, ``\\bar``, ``\\frac``) written in a string that is not raw, which
    Python reads as a tab, a carriage return, a backspace or a form feed."""
    bad = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc and any(c in doc for c in "\t\b\f\r\a\v"):
                bad.append(f"{where}:{getattr(node, 'lineno', 1)}")
    return bad


def test_docstrings_hold_no_escaped_latex():
    bad = [hit for package in PACKAGES for name, path in _modules(package).items()
           for hit in _escaped_docstrings(path.read_text(encoding="utf-8"), name)]
    assert not bad, "write these docstrings raw (r\"\"\"): " + ", ".join(bad)
    # the check can fail: a non-raw docstring with \theta is found, its raw form is not
    assert _escaped_docstrings('def f():\n    """At :math:`\\theta`."""\n', "probe") == ["probe:1"]
    assert _escaped_docstrings('def f():\n    r"""At :math:`\\theta`."""\n', "probe") == []
