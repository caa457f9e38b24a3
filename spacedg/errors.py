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


class PluginRuntimeError(PluginError):
    """A plugin's own code raised while spacedg ran it (a degradation's ``apply``, a question
    family's ``generate``).

    The message names the plugin and the distribution that installed it; the original
    exception is chained as ``__cause__``.

    Attributes:
        plugin: the degradation or question-family name.
        distribution: the installed distribution providing it (``None`` if unknown).
    """

    def __init__(self, message: str, *, plugin: str | None = None, distribution: str | None = None) -> None:
        super().__init__(message)
        self.plugin = plugin
        self.distribution = distribution


class PluginImportInterrupted(KeyboardInterrupt):
    """Ctrl+C (SIGINT) arrived while a plugin was being imported; the message names the plugin.

    A :class:`KeyboardInterrupt`, so everything that stops on Ctrl+C still stops; the command
    line prints its message on one line and exits with status 130.
    """


class SpaceDGWarning(UserWarning):
    """Something the user should know that does not stop the work (the command line prints
    ``spacedg: warning: <message>`` on one line)."""


class PluginWarning(SpaceDGWarning):
    """A plugin problem that does not stop the command: a name clash, a slow import."""


class ErasedViewWarning(SpaceDGWarning):
    """A degradation's parameters turned a view with content into one flat colour (pure airlight,
    white, black): the image is delivered as asked, but shows nothing of the scene
    (:mod:`spacedg.data.erased_views`)."""


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
