"""Argument checks shared by the subcommands, run before any work: one-line
:class:`~spacedg.errors.ParameterError` s that name the flag, the value and what is accepted.

- numbers: :func:`at_least`, :func:`in_range`, :func:`seed`, :func:`fraction`, :func:`positive_number`;
- subcommands: :func:`add_command` registers one (its parser, its handler, its description:
  the handler's docstring);
- the renderer: :func:`add_backend_arguments` declares ``--backend`` / ``--device`` once for every
  command that renders;
- outputs: :func:`output_folder` / :func:`output_file`: the path (or its nearest existing
  ancestor, since commands create missing folders) must be a folder this process can write in
  (checked by creating and removing a temporary file there: permission bits alone say nothing
  for root, a read-only mount or ``/proc``), and must not be a file where a folder is expected
  or the reverse.
"""

from __future__ import annotations

import argparse
import inspect
import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

from spacedg.errors import ParameterError
from spacedg.render.renderer import BACKENDS

__all__ = ["add_backend_arguments", "add_command", "at_least", "fraction", "in_range", "output_file", "output_folder", "positive_number", "seed"]


def add_command(
    subparsers: argparse._SubParsersAction,
    name: str,
    handler: Callable[[argparse.Namespace], int],
    *,
    help: str,
    description: str | None = None,
) -> argparse.ArgumentParser:
    """Register subcommand ``name``: its parser, with ``help`` (the one-line summary in the parent's
    list) and ``description`` (its own ``--help``; default: ``handler``'s docstring, else ``help``), and
    ``handler``, called with the parsed namespace and returning the exit code (``args.func``)."""
    text = description or inspect.getdoc(handler) or help
    parser = subparsers.add_parser(name, help=help, description=text)
    parser.set_defaults(func=handler)
    return parser


def add_backend_arguments(parser: argparse.ArgumentParser, what: str = "renderer", device: bool = True) -> None:
    """``--backend`` (one of :data:`spacedg.render.renderer.BACKENDS`, default ``auto``) and, with
    ``device``, ``--device`` (a torch device for the torch and gsplat backends); ``what`` names what renders."""
    parser.add_argument("--backend", choices=BACKENDS, default="auto",
                        help=f"{what}: auto (default: the compiled CPU path; on --device cuda gsplat's CUDA compositor "
                             "when it loads, else torch), cpu, torch or gsplat")
    if device:
        parser.add_argument("--device", default=None,
                            help="torch device for the torch and gsplat backends, e.g. cuda or cuda:1 (default: CPU); "
                                 "with a non-CPU device the degradations run there too")

#: Largest seed accepted (numpy's SeedSequence takes any non-negative integer; 2**63 keeps it an int64).
MAX_SEED = 2**63 - 1


def at_least(flag: str, value: int | None, low: int) -> None:
    """``value`` (when given) must be an integer >= ``low``."""
    if value is not None and value < low:
        raise ParameterError(f"{flag} must be at least {low}, got {value}")


def in_range(flag: str, value: int | None, low: int, high: int, unit: str = "") -> None:
    """``value`` (when given) must be an integer in ``[low, high]``."""
    if value is not None and not low <= value <= high:
        raise ParameterError(f"{flag} must be from {low} to {high}{' ' + unit if unit else ''}, got {value}")


def seed(flag: str, value: int | None) -> None:
    """A seed: a non-negative integer."""
    if value is not None and not 0 <= value <= MAX_SEED:
        raise ParameterError(f"{flag} must be a non-negative integer (at most 2**63 - 1), got {value}")


def positive_number(flag: str, value: float | None) -> None:
    """``value`` (when given) must be a finite number > 0."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ParameterError(f"{flag} must be a finite number > 0, got {value}")


def fraction(flag: str, value: float | None) -> None:
    """``value`` (when given) must be a finite number in [0, 1]."""
    if value is not None and not (math.isfinite(value) and 0.0 <= value <= 1.0):
        raise ParameterError(f"{flag} must be a number from 0 to 1, got {value}")


def _writable_ancestor(flag: str, path: Path) -> Path:
    """The nearest existing ancestor of ``path`` (``path`` itself if it exists), checked to be a
    folder this process can create files in."""
    probe = path
    while not probe.exists() and probe != probe.parent:
        if probe.is_symlink():  # a dangling link: following it would write elsewhere
            raise ParameterError(f"{flag} {path}: {probe} is a broken symbolic link; remove it or choose another path")
        probe = probe.parent
    if not probe.is_dir():
        raise ParameterError(f"{flag} {path}: {probe} is a file, not a folder; choose another path")
    try:
        fd, name = tempfile.mkstemp(prefix=".spacedg-write-check-", dir=probe)
    except OSError as err:
        raise ParameterError(f"{flag} {path}: cannot write in {probe} ({err.strerror}); choose a folder you can write to") from None
    os.close(fd)
    os.unlink(name)
    return probe


def output_folder(flag: str, path: Path) -> None:
    """``path`` is (or can be created as) a folder this process can write in."""
    if path.exists() and not path.is_dir():
        raise ParameterError(f"{flag} {path} is a file; pass a folder (it is created when missing)")
    _writable_ancestor(flag, path)


def output_file(flag: str, path: Path, suffixes: tuple[str, ...] = ()) -> None:
    """``path`` is a file this process can write (its folder is created when missing); with
    ``suffixes``, its name must end with one of them."""
    if suffixes and path.suffix.lower() not in suffixes:
        raise ParameterError(f"{flag} {path}: write a {' or '.join(suffixes)} file")
    if path.is_dir():
        raise ParameterError(f"{flag} {path} is a folder; pass a file path")
    _writable_ancestor(flag, path.parent if str(path.parent) else Path("."))
