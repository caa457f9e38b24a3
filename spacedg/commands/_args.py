"""Argument checks shared by the subcommands, run before any work: one-line errors that name the
flag, the value and what is accepted.

- the parser: :class:`CommandParser` prints every usage error (unknown option, bad choice, missing
  or malformed value) as one line ``spacedg <command>: error: … (see `spacedg <command> --help`)``
  and exits 2, instead of argparse's usage block;
- numbers as argparse types (checked at parse time, so ``--null -1`` is refused at the call):
  :func:`whole` (an integer in a range), :func:`real` (a finite number in a range), :data:`SEED`;
  and, inside handlers, :func:`in_range` and :func:`seed` for values computed from several flags;
- devices: :func:`device_option`, the argparse type of every ``--device`` (a torch device that
  exists here: :func:`spacedg.devices.resolve_device`);
- sizes: :func:`image_size_of` maps the deprecated ``--width`` / ``--height`` onto ``--image-size``;
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
import re
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from spacedg.errors import ParameterError
from spacedg.limits import MAX_IMAGE_SIDE, check_image_size
from spacedg.render.renderer import BACKENDS

__all__ = [
    "SEED", "CommandParser", "Ranged", "add_backend_arguments", "add_command", "add_device_argument", "device_option",
    "image_size_of", "in_range", "output_file", "output_folder", "real", "seed", "usage_error", "whole",
]

#: Namespace attribute holding the ``prog`` of the deepest parser that ran (``"spacedg qa audit"``).
PROG_KEY = "_spacedg_prog"


def usage_error(prog: str, message: str) -> NoReturn:
    """Print ``<prog>: error: <message> (see `<prog> --help`)`` as one line on stderr and exit 2."""
    text = " ".join(str(message).split())
    sys.stderr.write(f"{prog}: error: {text} (see `{prog} --help`)\n")
    sys.stderr.flush()
    raise SystemExit(2)


class CommandParser(argparse.ArgumentParser):
    """An :class:`argparse.ArgumentParser` whose usage errors are one line naming the command
    (:func:`usage_error`); its sub-parsers are of this class too."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.set_defaults(**{PROG_KEY: self.prog})

    def parse_args(self, args: Sequence[str] | None = None, namespace: Any = None) -> Any:  # type: ignore[override]
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:  # argparse reports a sub-command's unknown options from the top parser: name the sub-command
            shown = " ".join(extras)
            shown = shown if len(shown) <= 200 else f"{shown[:200]}…"
            usage_error(getattr(parsed, PROG_KEY, self.prog), f"unrecognized arguments: {shown}")
        return parsed

    def error(self, message: str) -> NoReturn:
        usage_error(self.prog, message)


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
        add_device_argument(parser, "torch device for the torch and gsplat backends: cpu, cuda or cuda:N (default: CPU); "
                                    "with a non-CPU device the degradations run there too")


def add_device_argument(parser: argparse.ArgumentParser, help: str) -> None:
    """``--device``: a torch device that exists on this machine (:func:`device_option`), default ``None``."""
    parser.add_argument("--device", type=device_option, default=None, metavar="DEVICE", help=help)


def device_option(text: str) -> str:
    """argparse type of ``--device``: the name of a torch device this machine has (``cpu``, ``cuda``,
    ``cuda:N``, ``mps``), normalised (``"CUDA:0 "`` → ``"cuda:0"``); torch is imported only when
    the option is given."""
    from spacedg.devices import resolve_device

    try:
        return str(resolve_device(text, argument=""))
    except ParameterError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


#: Largest seed accepted (numpy's SeedSequence takes any non-negative integer; 2**63 keeps it an int64).
MAX_SEED = 2**63 - 1
_INTEGER = re.compile(r"[+-]?\d{1,19}")
_SHOWN = 40


def _shown(text: str) -> str:
    cleaned = text.strip()
    return repr(cleaned) if len(cleaned) <= _SHOWN else f"{cleaned[:_SHOWN]!r}… ({len(cleaned):,} characters)"


class Ranged:
    """An argparse type: a number in ``[low, high]`` (``high`` ``None``: no upper bound), else an
    :class:`argparse.ArgumentTypeError` saying what is accepted. ``low`` / ``high`` / ``accepts``
    are public so tests can read the range of every numeric option."""

    def __init__(self, low: float, high: float | None, accepts: str, parse: Callable[[str], float]) -> None:
        self.low, self.high, self.accepts, self._parse = low, high, accepts, parse
        self.__name__ = accepts  # argparse names a type by its __name__

    def __call__(self, text: str) -> Any:
        try:
            value = self._parse(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {self.accepts}, got {_shown(text)}") from None
        if not (self.low <= value and (self.high is None or value <= self.high)):
            raise argparse.ArgumentTypeError(f"must be {self.accepts}, got {text.strip()}")
        return value

    def __repr__(self) -> str:
        return f"<{self.accepts}>"


def _parse_int(text: str) -> int:
    if not _INTEGER.fullmatch(text.strip()):
        raise ValueError(text)
    return int(text)


def _parse_finite(text: str) -> float:
    if len(text) > 64:
        raise ValueError(text)
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(text)
    return value


def whole(low: int, high: int | None = None, unit: str = "") -> Ranged:
    """argparse type: an integer in ``[low, high]`` (no upper bound when ``high`` is ``None``)."""
    suffix = f" {unit}" if unit else ""
    accepts = f"a whole number >= {low}{suffix}" if high is None else f"a whole number from {low} to {high}{suffix}"
    return Ranged(low, high, accepts, _parse_int)


def real(low: float, high: float | None = None, *, above: bool = False, unit: str = "") -> Ranged:
    """argparse type: a finite number in ``[low, high]`` (``above``: ``> low``, for a positive size)."""
    suffix = f" {unit}" if unit else ""
    if above:
        accepts = f"a finite number > {low:g}{suffix}"
        ranged = Ranged(low, high, accepts, _parse_finite)
        ranged.low = math.nextafter(low, math.inf)
        return ranged
    accepts = (f"a finite number >= {low:g}{suffix}" if high is None else f"a number from {low:g} to {high:g}{suffix}")
    return Ranged(low, high, accepts, _parse_finite)


#: argparse type of every ``--seed``: a non-negative integer (at most 2**63 - 1).
SEED = Ranged(0, MAX_SEED, "a non-negative integer (at most 2**63 - 1)", _parse_int)


def image_size_of(args: argparse.Namespace, default: tuple[int, int] | None = None, min_side: int = 8) -> tuple[int, int] | None:
    """``--image-size`` as ``(width, height)`` pixels, or the deprecated ``--width`` / ``--height``
    mapped onto it (a side left out is ``default``'s); ``default`` when neither is given. With no
    ``default``, a lone ``--width`` or ``--height`` gives ``None`` (the caller keeps an aspect ratio).

    Raises:
        ParameterError: both spellings given, a side under ``min_side`` pixels, or over the size policy.
    """
    width, height = getattr(args, "width", None), getattr(args, "height", None)
    given = getattr(args, "image_size", None)
    if width is None and height is None:
        return given if given is not None else default
    if given is not None:
        raise ParameterError("--image-size and the deprecated --width/--height are alternatives; pass --image-size WxH")
    if width is None or height is None:
        if default is None:
            return None
        width = default[0] if width is None else width
        height = default[1] if height is None else height
    in_range("--width", width, min_side, MAX_IMAGE_SIDE, "pixels")
    in_range("--height", height, min_side, MAX_IMAGE_SIDE, "pixels")
    check_image_size(int(width), int(height), "--width/--height", "render smaller", ParameterError)
    return int(width), int(height)



def in_range(flag: str, value: int | None, low: int, high: int, unit: str = "") -> None:
    """``value`` (when given) must be an integer in ``[low, high]``."""
    if value is not None and not low <= value <= high:
        raise ParameterError(f"{flag} must be from {low} to {high}{' ' + unit if unit else ''}, got {value}")


def seed(flag: str, value: int | None) -> None:
    """A seed: a non-negative integer."""
    if value is not None and not 0 <= value <= MAX_SEED:
        raise ParameterError(f"{flag} must be a non-negative integer (at most 2**63 - 1), got {value}")




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
