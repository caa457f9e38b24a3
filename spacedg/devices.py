"""Torch devices asked for by name: one check for every command and function that takes one.

:func:`resolve_device` turns ``"cpu"``, ``"cuda"``, ``"cuda:1"``, ``"mps"`` (or a
:class:`torch.device`) into a :class:`torch.device` that exists on this machine, or raises one
:class:`~spacedg.errors.ParameterError` that names the argument, what it got and what it accepts:
a malformed name, an unknown device type, CUDA asked of a torch built without it (or with no GPU
visible), a CUDA index at or above ``torch.cuda.device_count()``. Without the check, such a
device fails far from its cause (``AssertionError: Torch not compiled with CUDA enabled`` inside
the renderer) or is silently ignored.

torch is imported inside the function, so importing this module stays light.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any

from spacedg.errors import ParameterError

if TYPE_CHECKING:  # pragma: no cover
    import torch

__all__ = ["ACCEPTED", "resolve_device"]

#: What a device name may be, for error messages.
ACCEPTED = "cpu, cuda, cuda:N (N a visible GPU's index) or mps"
_NAME = re.compile(r"(?P<kind>[a-z][a-z0-9_]*)(?::(?P<index>\d{1,6}))?")
_SHOWN = 60  # characters of a bad value repeated in a message


def resolve_device(value: str | torch.device | None, argument: str = "device") -> torch.device | None:
    """The torch device named by ``value`` (``None`` stays ``None``: the caller's default).

    Args:
        value: a device name (``cpu``, ``cuda``, ``cuda:N``, ``mps``; case and surrounding spaces
            ignored) or a :class:`torch.device`.
        argument: how the caller names the value in messages, e.g. ``"--device"`` or ``"device"``
            (``""``: the message starts with the value, for argparse, which names the option itself).

    Raises:
        ParameterError: ``value`` is not a device name, names an unknown device type, or a device
            this machine does not have.
    """
    if value is None:
        return None
    import torch

    prefix = f"{argument} " if argument else ""
    if isinstance(value, torch.device):
        text = str(value)
    elif isinstance(value, str):
        text = value.strip().lower()
    else:
        raise ParameterError(f"{prefix}must be a device name ({ACCEPTED}) or a torch.device, got {type(value).__name__} "
                             f"{_shown(value)}")
    match = _NAME.fullmatch(text)
    if match is None:
        raise ParameterError(f"{prefix}{_shown(value)} is not a device name; pass {ACCEPTED}")
    kind, index = match["kind"], match["index"]
    problem = _problem(torch, kind, None if index is None else int(index))
    if problem is not None:
        raise ParameterError(f"{prefix}{_shown(value)}: {problem}")
    return torch.device(text)


def _problem(torch: Any, kind: str, index: int | None) -> str | None:
    """Why device ``kind[:index]`` cannot be used here, or ``None`` when it can."""
    if kind == "cpu":
        return None if index in (None, 0) else "there is one CPU device: pass cpu"
    if kind == "cuda":
        return _cuda_problem(torch, index)
    if kind == "mps":
        mps = getattr(torch.backends, "mps", None)
        available = mps is not None and mps.is_available()
        if not available:
            return "Apple's MPS is not available on this machine; pass cpu"
        return None if index in (None, 0) else "there is one MPS device: pass mps"
    return f"unknown device type {kind!r}; pass {ACCEPTED}"


def _cuda_problem(torch: Any, index: int | None) -> str | None:
    if torch.version.cuda is None and getattr(torch.version, "hip", None) is None:
        return (f"this torch ({torch.__version__}) was built without CUDA; install a CUDA build of torch "
                "or pass cpu")
    if not torch.cuda.is_available():
        return ("no CUDA device is visible (no GPU, no driver, or CUDA_VISIBLE_DEVICES hides them: "
                "torch.cuda.is_available() is False); pass cpu")
    count = torch.cuda.device_count()
    if index is not None and index >= count:
        visible = "cuda:0" if count == 1 else f"cuda:0 … cuda:{count - 1}"
        return f"there {'is' if count == 1 else 'are'} {count} visible CUDA device{'s' if count != 1 else ''} ({visible})"
    return None


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= _SHOWN else f"{text[:_SHOWN]}… ({len(text):,} characters)"
