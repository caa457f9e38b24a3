"""``spacedg`` command line: parse, call a module, print. Each subcommand lives in
``spacedg/commands/<name>.py`` and exposes ``add_parser(subparsers)``, which registers its
parser with :func:`spacedg.commands._args.add_command`: the handler (``args.func``, called with the
parsed namespace, returns an exit code) and, as the ``--help`` description, the handler's docstring."""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from typing import Any, TextIO

from spacedg.errors import SpaceDGError, SpaceDGWarning


def build_parser() -> argparse.ArgumentParser:
    """The ``spacedg`` parser and every sub-command's (a :class:`~spacedg.commands._args.CommandParser`:
    usage errors are one line naming the command, exit status 2)."""
    from spacedg.commands import evaluate, export, gallery, kernels, plugins, predict, qa, render, review, scenes
    from spacedg.commands._args import CommandParser

    parser = CommandParser(
        prog="spacedg",
        description="Degradation-aware spatial QA data from 3D Gaussian Splatting scenes.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    scenes.add_parser(sub)
    render.add_parser(sub)
    gallery.add_parser(sub)
    qa.add_parser(sub)
    export.add_parser(sub)
    predict.add_parser(sub)
    evaluate.add_parser(sub)
    review.add_parser(sub)
    plugins.add_parser(sub)
    kernels.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``spacedg`` console script; returns the process exit code.

    Exit status 2 with one line for bad input: ``spacedg <command>: error: … (see `spacedg <command>
    --help`)`` for a usage error (unknown option, bad choice, missing or malformed value: raised as
    ``SystemExit(2)`` by the parser), ``spacedg: error: …`` for any
    :class:`~spacedg.errors.SpaceDGError` of the handler; 130 with one line for Ctrl+C (naming the plugin
    being imported when that is where it landed); warnings of spacedg
    (:class:`~spacedg.errors.SpaceDGWarning`: plugin clashes, slow plugin imports, ...) print as
    one line ``spacedg: warning: …`` on stderr.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("default", SpaceDGWarning)
        warnings.showwarning = _one_line_warnings(warnings.showwarning)
        parser = build_parser()
        args = parser.parse_args(argv)
        try:
            return int(args.func(args) or 0)
        except BrokenPipeError:  # output piped into `head` and closed: not an error
            sys.stderr.close()
            return 0
        except SpaceDGError as err:
            # Bad input: one clear line, no traceback.
            print(f"spacedg: error: {err}", file=sys.stderr)
            return 2
        except OSError as err:
            # The file system refused (no such folder, permission, a name too long, disk full): one line too.
            name = str(err.filename) if err.filename is not None else ""
            where = f"{name[:200]}…" if len(name) > 200 else name
            print(f"spacedg: error: {err.strerror or err}{': ' + where if where else ''}", file=sys.stderr)
            return 2
        except KeyboardInterrupt as err:
            text = str(err).strip()
            print(f"spacedg: {text}" if text else "spacedg: interrupted", file=sys.stderr)
            return 130


def _one_line_warnings(fallback: Any) -> Any:
    """A ``warnings.showwarning`` that prints spacedg's warnings as ``spacedg: warning: …``."""

    def show(message: Warning | str, category: type[Warning], filename: str, lineno: int,
             file: TextIO | None = None, line: str | None = None) -> None:
        if issubclass(category, SpaceDGWarning):
            print(f"spacedg: warning: {message}", file=file or sys.stderr, flush=True)
        else:
            fallback(message, category, filename, lineno, file, line)

    return show


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
