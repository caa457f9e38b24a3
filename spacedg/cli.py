"""``spacedg`` command line: parse, call a module, print. Each subcommand lives in
``spacedg/commands/<name>.py`` and exposes ``add_parser(subparsers)``, which registers its
parser and sets ``func`` (called with the parsed namespace, returns an exit code)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from spacedg.errors import SpaceDGError


def build_parser() -> argparse.ArgumentParser:
    from spacedg.commands import evaluate, export, gallery, plugins, predict, qa, render, review, scenes

    parser = argparse.ArgumentParser(
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
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``spacedg`` console script; returns the process exit code."""
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


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
