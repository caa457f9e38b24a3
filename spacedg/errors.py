"""Exception types shared by every part of spacedg.

Every error raised on bad input is one of these, and its message names what is wrong
(file, field, count, first offending index) and how to fix it.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager


class SpaceDGError(Exception):
    """Base class of all errors raised by spacedg on bad input or configuration."""


class InvalidDataError(SpaceDGError, ValueError):
    """Values that break a documented convention (NaN positions, negative scales, ...)."""


class FileFormatError(SpaceDGError, ValueError):
    """A file that is malformed, truncated, hostile or of an unsupported variant."""


class FileValueError(FileFormatError, InvalidDataError):
    """A file whose structure parses but whose values break a convention (NaN, zero quaternions)."""


class ParameterError(SpaceDGError, ValueError):
    """An unknown parameter name or a value outside its hard limits."""


class PluginError(SpaceDGError):
    """A plugin that cannot be loaded, is unknown, or clashes with another."""


class UnknownPluginError(PluginError, LookupError):
    """A degradation or question family name that no loaded plugin provides."""


class DuplicatePluginError(PluginError):
    """Two plugins registered the same name."""


@contextmanager
def error_context(prefix: str) -> Iterator[None]:
    """Prefix the message of any :class:`SpaceDGError` raised inside the block.

    Readers use it so that an error raised deep in validation names the file and record,
    e.g. ``"scene.json: view 'frame_0003': fx must be > 0 (got -1.0)"``.
    """
    try:
        yield
    except SpaceDGError as err:
        raise type(err)(f"{prefix}: {err}") from err
