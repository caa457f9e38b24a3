"""Torch devices from user input: one check for every ``device=`` argument and ``--device`` option.

:func:`resolve_device` turns ``None``, ``"cpu"``, ``"cuda"``, ``"cuda:1"``, … (or a
``torch.device``) into a ``torch.device`` and refuses, with a :class:`~spacedg.errors.ParameterError`
naming the argument, a malformed string, CUDA asked of a torch without CUDA, and a CUDA index
this machine does not have. torch is imported inside the function only (``import spacedg`` stays light).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from spacedg.errors import ParameterError

if TYPE_CHECKING:
    import torch

__all__ = ["resolve_device"]


def resolve_device(value: Any, argument: str = "device") -> torch.device | None:
    """``value`` as a ``torch.device`` (``None`` stays ``None``: the caller's default).

    Raises:
        ParameterError: ``value`` is not a device (``"cpu"``, ``"cuda"``, ``"cuda:N"``, …), names
            CUDA while ``torch.cuda.is_available()`` is false, or a CUDA index >= ``torch.cuda.device_count()``.
    """
    if value is None:
        return None
    import torch

    if not isinstance(value, (str, torch.device)):
        raise ParameterError(f"{argument} must be a torch device such as 'cpu', 'cuda' or 'cuda:0', got {value!r}")
    try:
        device = torch.device(value.strip() if isinstance(value, str) else value)
    except (RuntimeError, TypeError, ValueError) as err:
        raise ParameterError(f"{argument} must be a torch device such as 'cpu', 'cuda' or 'cuda:0', got {value!r} ({err})") from None
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise ParameterError(
                f"{argument} {value!r} asks for CUDA, but this torch has no usable CUDA device "
                "(a CPU-only build, or no GPU/driver); use 'cpu' or leave it out"
            )
        count = torch.cuda.device_count()
        if device.index is not None and device.index >= count:
            raise ParameterError(f"{argument} {value!r}: this machine has {count} CUDA device(s), 'cuda:0' … 'cuda:{count - 1}'")
    return device
