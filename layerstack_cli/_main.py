"""The ``layerstack`` parser and :func:`main`."""

from __future__ import annotations

import argparse
import os
import sys

from layerstack_jax import LayerstackError

from ._common import PROG
from ._cube import _add_fit_cube_parser
from ._design import _add_design_parser
from ._fit import _add_fit_parser
from ._predict import _add_predict_parser

_SUBCOMMANDS = (_add_predict_parser, _add_fit_parser, _add_fit_cube_parser, _add_design_parser)


def _build_parser() -> argparse.ArgumentParser:
    from layerstack_jax import __version__

    parser = argparse.ArgumentParser(prog=PROG, description="Light in layered coatings (layerstack_jax).")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    return parser


def _os_error_message(e: OSError) -> str:
    if e.filename is not None and e.strerror:
        return f"{e.filename}: {e.strerror}"
    return str(e)


#: Size limit of the compiled programs the command line keeps on disk (least recently used go first).
CACHE_MAX_BYTES = 2 ** 30


def compilation_cache_dir() -> str:
    """Where the command line keeps compiled programs: ``$LAYERSTACK_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/layerstack/xla`` (``~/.cache/layerstack/xla``); empty when
    ``LAYERSTACK_CACHE_DIR`` is set to the empty string (no cache)."""
    path = os.environ.get("LAYERSTACK_CACHE_DIR")
    if path is not None:
        return path
    return os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"),
                        "layerstack", "xla")


def _use_compilation_cache() -> None:
    """Turn on JAX's persistent compilation cache (:func:`compilation_cache_dir`) for this process,
    unless one is configured already (``jax_compilation_cache_dir``) or it is turned off.

    The command line runs in a fresh process each time, so without it every ``layerstack fit``
    of the same model structure compiles the same programs again (~3 s for a 3-angle
    ellipsometric fit, most of the first fit); with it, a later run loads them from disk. JAX
    stores only programs that took ≥ ``jax_persistent_cache_min_compile_time_secs`` (1 s by
    default) to compile, keyed by the program, the JAX version and the options, so a stale entry
    is never used. Once JAX has opened a cache, it keeps it for the rest of the process."""
    import jax

    path = compilation_cache_dir()
    if not path or jax.config.jax_compilation_cache_dir is not None:
        return
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_compilation_cache_max_size", CACHE_MAX_BYTES)


def main(argv=None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); returns the exit status
    (0 success, 2 usage or input error) instead of exiting, so it can be called in-process."""
    parser = _build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse usage errors (status 2), --help / --version (0)
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    _use_compilation_cache()
    try:
        return args.func(args)
    except LayerstackError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
    except OSError as e:
        print(f"{PROG}: error: {_os_error_message(e)}", file=sys.stderr)
    return 2


