"""Running plugin code: an exception raised inside a plugin's ``apply`` / ``generate`` becomes a
:class:`~spacedg.errors.PluginRuntimeError` that names the plugin and its distribution.

The data layer calls every plugin through :func:`plugin_call`::

    with plugin_call("degradation", step.spec, "apply"):
        out = step.spec.apply(rgb, aux, params, rng)

- a :class:`~spacedg.errors.SpaceDGError` raised inside passes through unchanged (it is already
  a message meant for the user: a bad parameter, a scene without visibility, ...);
- any other :class:`Exception` is re-raised as :class:`~spacedg.errors.PluginRuntimeError`
  chained to the original (``__cause__``), with ``plugin`` and ``distribution`` set and a
  message naming the plugin, where it came from, the error, the innermost source line and the fix;
- ``KeyboardInterrupt`` / ``SystemExit`` pass through (stopping is not a plugin bug).
"""

from __future__ import annotations

import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from spacedg.errors import PluginRuntimeError, SpaceDGError

__all__ = ["plugin_call", "plugin_runtime_error"]


def _where(err: BaseException) -> str:
    """``" at file.py:12"`` for the innermost frame of ``err``'s traceback (``""`` without one)."""
    frames = traceback.extract_tb(err.__traceback__) if err.__traceback__ is not None else []
    if not frames:
        return ""
    last = frames[-1]
    return f" at {Path(last.filename).name}:{last.lineno}"


def plugin_runtime_error(kind: str, spec: Any, action: str, err: BaseException) -> PluginRuntimeError:
    """The :class:`PluginRuntimeError` for ``err`` raised by ``spec.<action>`` (``kind``:
    ``"degradation"`` or ``"question family"``); the caller chains it (``raise … from err``)."""
    name = str(getattr(spec, "name", "?"))
    origin = getattr(spec, "origin", None)
    distribution = getattr(origin, "distribution", None)
    source = origin.describe() if origin is not None else "not registered through a plugin"
    detail = str(err).strip().splitlines()[0] if str(err).strip() else "(no message)"
    if origin is not None and getattr(origin, "builtin", False):
        fix = f"this is a bug in spacedg's built-in {kind} {name!r}; please report it with the command you ran"
    elif distribution:
        fix = (f"this is a bug in that plugin, not in your data: report it to the authors of {distribution}, "
               f"or leave {name!r} out (uninstall it with `pip uninstall {distribution}`)")
    else:
        fix = f"this is a bug in that plugin's code, not in your data: fix it, or leave {name!r} out"
    message = (f"{kind} {name!r} ({source}) raised {type(err).__name__} in {action}{_where(err)}: {detail}; {fix}")
    return PluginRuntimeError(message, plugin=name, distribution=distribution)


@contextmanager
def plugin_call(kind: str, spec: Any, action: str) -> Iterator[None]:
    """Run plugin code; a non-spacedg exception inside becomes a :class:`PluginRuntimeError`."""
    try:
        yield
    except SpaceDGError:
        raise
    except Exception as err:  # noqa: BLE001 - any failure of third-party code is named, then chained
        raise plugin_runtime_error(kind, spec, action, err) from err
