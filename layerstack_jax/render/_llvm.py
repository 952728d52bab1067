"""Finding an LLVM that Dr.Jit's CPU backend can use, for Mitsuba's ``llvm_*`` variants.

Dr.Jit compiles the vectorized variants' kernels with the LLVM shared library it finds at run
time (``DRJIT_LIBLLVM_PATH``, else its own search). With LLVM 14 or 15, the versions Debian 12
installs by default, it aborts the whole process at the first kernel ("Cannot select …
fminimum"); LLVM ≥ 17 works (Debian 12's ``libllvm19`` package). So before an ``llvm_*``
variant is set this module

* leaves ``DRJIT_LIBLLVM_PATH`` alone when the user has set it;
* otherwise points it at the newest ``libLLVM`` ≥ 17 found in the usual places
  (:func:`configure`), which ``import layerstack_jax.render`` does once;
* and, on Linux where none is found, raises one sentence saying what to install
  (:func:`require_llvm`) rather than letting Dr.Jit abort. The scalar variants need no LLVM.
"""

from __future__ import annotations

import glob
import os
import re
import sys

from .._base.validate import LayerstackError

__all__ = ["MIN_LLVM", "find_llvm", "configure", "llvm_problem", "require_llvm", "best_variant"]

#: Oldest LLVM major version Dr.Jit's LLVM backend runs with here.
MIN_LLVM = 17

_DIRS = ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib", "/usr/local/lib",
         "/opt/homebrew/opt/llvm/lib", "/usr/local/opt/llvm/lib")
_INSTALL = ("install LLVM >= 17 (Debian/Ubuntu: `apt-get install libllvm19`; macOS: `brew install llvm`) or set "
            "DRJIT_LIBLLVM_PATH to its libLLVM shared library")


def _version(path: str) -> int | None:
    """LLVM major version in a library file name (libLLVM.so.19.1, libLLVM-19.so, llvm-19/lib/…)."""
    name = os.path.basename(path)
    for pattern in (r"libLLVM\.so\.(\d+)", r"libLLVM-(\d+)", r"libLLVM\.(\d+)\.dylib"):
        m = re.search(pattern, name)
        if m and int(m.group(1)) >= 4:  # not the soname's ABI number (llvm-19/lib/libLLVM.so.1)
            return int(m.group(1))
    m = re.search(r"llvm-?(\d+)", os.path.dirname(path))
    return int(m.group(1)) if m else None


def find_llvm(min_version: int = MIN_LLVM) -> str | None:
    """Path of the newest LLVM shared library of major version ≥ ``min_version`` in the usual
    system places, or None."""
    found = []
    for d in _DIRS:
        for pattern in ("libLLVM.so.*", "libLLVM-*.so*", "libLLVM.dylib", "libLLVM.*.dylib"):
            found += glob.glob(os.path.join(d, pattern))
    found += glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*")
    versions = [(v, p) for p in found if (v := _version(os.path.realpath(p)) or _version(p)) is not None and v >= min_version]
    return os.path.realpath(max(versions)[1]) if versions else None


def configure() -> str | None:
    """Set ``DRJIT_LIBLLVM_PATH`` to :func:`find_llvm`'s library when the variable is unset and one
    is found (before Dr.Jit first loads LLVM); returns the variable's value."""
    if not os.environ.get("DRJIT_LIBLLVM_PATH"):
        path = find_llvm()
        if path is not None:
            os.environ["DRJIT_LIBLLVM_PATH"] = path
    return os.environ.get("DRJIT_LIBLLVM_PATH")


def llvm_problem() -> str | None:
    """None when an ``llvm_*`` variant can be used here, else the sentence that says why not."""
    path = configure()
    if path:
        if not os.path.exists(path):
            return f"DRJIT_LIBLLVM_PATH={path!r} does not exist: {_INSTALL}"
        return None
    if not sys.platform.startswith("linux"):
        return None  # Dr.Jit's own search (no version trap known there)
    return (f"Mitsuba's llvm variants need LLVM >= {MIN_LLVM} (with older ones Dr.Jit aborts the process) and none was "
            f"found: {_INSTALL}; or use the slower variant 'scalar_spectral'")


def require_llvm() -> None:
    """Raise :class:`~layerstack_jax.LayerstackError` with :func:`llvm_problem`'s sentence."""
    problem = llvm_problem()
    if problem:
        raise LayerstackError(problem)


def best_variant(polarized: bool = False) -> str:
    """The fastest spectral Mitsuba variant usable here: ``cuda_ad_spectral`` with a CUDA GPU,
    else ``llvm_ad_spectral`` when an LLVM ≥ 17 is found, else ``scalar_spectral`` (each with
    ``_polarized`` if asked). Sets no variant."""
    suffix = "_polarized" if polarized else ""
    try:
        import drjit as dr

        if dr.has_backend(dr.JitBackend.CUDA):
            return "cuda_ad_spectral" + suffix
    except ImportError:  # pragma: no cover - Mitsuba missing: coated_bsdf says how to install it
        pass
    return ("scalar_spectral" if llvm_problem() else "llvm_ad_spectral") + suffix
