"""The ``layerstack`` parser and :func:`main`."""

from __future__ import annotations

import argparse
import sys
import warnings

from layerstack_jax import LayerstackError, LayerstackWarning, use_compilation_cache

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


def main(argv=None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); returns the exit status
    (0 success, 2 usage or input error) instead of exiting, so it can be called in-process."""
    parser = _build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse usage errors (status 2), --help / --version (0)
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    use_compilation_cache()  # a later run loads the programs this one compiles (LAYERSTACK_CACHE_DIR)
    formatwarning = warnings.formatwarning
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("once", LayerstackWarning)  # a warning once, not once per dataset or angle
            warnings.formatwarning = _format_warning
            return args.func(args)
    except LayerstackError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
    except OSError as e:
        print(f"{PROG}: error: {_os_error_message(e)}", file=sys.stderr)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130  # 128 + SIGINT, as shells report it
    finally:
        warnings.formatwarning = formatwarning
    return 2


def _format_warning(message, category, filename, lineno, line=None) -> str:
    """The library's warnings as one line, like the command line's own messages."""
    if issubclass(category, LayerstackWarning):
        return f"{PROG}: warning: {message}\n"
    return f"{PROG}: warning: {category.__name__}: {message}\n"


