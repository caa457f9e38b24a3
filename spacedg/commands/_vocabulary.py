"""One option name per concept on the command line, and the old spellings kept for one release.

The vocabulary (held by ``tests/commands/test_vocabulary.py``, which walks every parser):

- ``--families a,b``: question families (old: ``qa preview --types``, ``export --question-types``);
- ``--image-size WxH``: image sizes in pixels (old: ``--width`` / ``--height`` of ``render`` and
  ``scenes synth``; ``--thumb-width`` is the width of a contact sheet's thumbnails, another concept);
- ``--device``: a torch device only (``cpu``, ``cuda``, ``cuda:N``, ``mps``; checked by
  :func:`spacedg.devices.resolve_device`); ``scenes import --scannetpp-camera dslr|iphone`` picks a ScanNet++
  camera (old: ``scenes import --device``);
- ``--num-gaussians N`` (``scenes synth``) is a count, ``--gaussians-file PATH`` (``scenes import``)
  a file (old: ``--gaussians`` for both);
- ``--shard-size``: items per resumable chunk of ``export`` (old: ``--chunk-size``).

:data:`DEPRECATED` is the one table of old spellings. Each still parses, prints one line
``spacedg <command>: warning: <old> is deprecated …; use <new>`` on stderr, raises a
:class:`DeprecationWarning`, and lands where its new option does (``--width`` / ``--height``
land in ``width`` / ``height``, which :func:`spacedg.commands._args.image_size_of` maps onto
``--image-size``).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from dataclasses import dataclass
from typing import Any

__all__ = ["DEPRECATED", "Alias", "add_deprecated", "deprecated_for"]


@dataclass(frozen=True)
class Alias:
    """An old spelling of one command's option, kept for one release.

    ``command`` is the command path (``"scenes synth"``), ``old`` the old option, ``new`` the
    option it maps to, ``usage`` how to write the new one (for the warning).
    """

    command: str
    old: str
    new: str
    usage: str


#: Every deprecated option of every command (removed in the release after next).
DEPRECATED: tuple[Alias, ...] = (
    Alias("qa preview", "--types", "--families", "--families a,b"),
    Alias("export", "--question-types", "--families", "--families a,b"),
    Alias("export", "--chunk-size", "--shard-size", "--shard-size N"),
    Alias("scenes synth", "--gaussians", "--num-gaussians", "--num-gaussians N"),
    Alias("scenes synth", "--width", "--image-size", "--image-size WxH"),
    Alias("scenes synth", "--height", "--image-size", "--image-size WxH"),
    Alias("scenes import", "--gaussians", "--gaussians-file", "--gaussians-file PATH"),
    Alias("scenes import", "--device", "--scannetpp-camera", "--scannetpp-camera dslr|iphone"),
    Alias("render", "--width", "--image-size", "--image-size WxH"),
    Alias("render", "--height", "--image-size", "--image-size WxH"),
)


def deprecated_for(command: str) -> list[Alias]:
    """The rows of :data:`DEPRECATED` for ``command`` (e.g. ``"render"``)."""
    return [alias for alias in DEPRECATED if alias.command == command]


class DeprecatedOption(argparse.Action):
    """Store like the option it stands for, after one warning line on stderr and a DeprecationWarning."""

    def __init__(self, option_strings: list[str], dest: str, *, alias: Alias, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, **kwargs)
        self.alias = alias

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        alias = self.alias
        message = (f"{option_string or alias.old} is deprecated and goes in the next release; "
                   f"use {alias.usage}")
        print(f"{parser.prog}: warning: {message}", file=sys.stderr, flush=True)
        warnings.warn(f"spacedg {alias.command}: {message}", DeprecationWarning, stacklevel=2)
        setattr(namespace, self.dest, values)


def add_deprecated(parser: argparse.ArgumentParser, command: str, **overrides: Any) -> None:
    """Register every old spelling of :data:`DEPRECATED` for ``command`` on ``parser`` (hidden from
    ``--help``). Each takes the new option's ``dest``, ``type``, ``choices`` and ``metavar``, unless
    ``overrides[old]`` (a dict of ``add_argument`` keywords) says otherwise; register the new
    options first."""
    for alias in deprecated_for(command):
        settings = dict(overrides.get(alias.old, {}))
        if "dest" not in settings:
            new = parser._option_string_actions[alias.new]
            settings.update(dest=new.dest, type=new.type, choices=new.choices, metavar=new.metavar)
        parser.add_argument(alias.old, action=DeprecatedOption, alias=alias, default=argparse.SUPPRESS,
                            help=argparse.SUPPRESS, **settings)
