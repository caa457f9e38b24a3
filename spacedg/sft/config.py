"""Config groups → objects: ``hydra.utils.instantiate`` with spacedg's errors.

A group of ``conf/`` that builds something (``model/``, ``data/``, ``data.val``) names its class
in ``_target_`` and its other keys are exactly that class's arguments. The class declares no
defaults of its own, so every default lives once, in the YAML. :func:`build` checks the keys
against the class before instantiating, so a typo is one :class:`~spacedg.errors.ParameterError`
naming the key and the known keys (not an omegaconf or Hydra traceback), and a spacedg error
raised while building (an unknown degradation name, an impossible setting) comes out as itself,
not wrapped in Hydra's ``InstantiationException``.
"""

from __future__ import annotations

import inspect
from typing import Any

from hydra.errors import InstantiationException
from hydra.utils import get_object, instantiate
from omegaconf import DictConfig, OmegaConf

from spacedg.errors import ParameterError, SpaceDGError

__all__ = ["build"]


def _check_keys(node: DictConfig, where: str) -> None:
    """Raise :class:`ParameterError` unless the keys of ``node`` are exactly the arguments of its
    ``_target_`` (and, recursively, of every nested node with a ``_target_``); ``where`` is the
    node's dotted name in the config (``"model"``, ``"data.val"``), used in the messages."""
    if "_target_" not in node:
        raise ParameterError(f"{where}: no _target_; a {where} config names the class it builds "
                             f"(see the packaged conf/ files)")
    try:
        target = get_object(str(node["_target_"]))
    except ImportError as err:
        raise ParameterError(f"{where}._target_={node['_target_']!r} cannot be imported: {str(err).splitlines()[0]}") from None
    arguments = {p.name: p for p in inspect.signature(target).parameters.values()
                 if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
    known = ", ".join(arguments)
    keys = [str(k) for k in node if not str(k).startswith("_")]
    for key in keys:
        if key not in arguments:
            raise ParameterError(f"{where}: unknown key {key!r}; the known keys are {known}")
        if OmegaConf.is_missing(node, key):
            raise ParameterError(f"{where}.{key} is not set (???); set it, e.g. {where}.{key}=VALUE")
    absent = [name for name, p in arguments.items() if p.default is p.empty and name not in keys]
    if absent:
        raise ParameterError(f"{where}: key {absent[0]!r} is missing; a {where} config sets every one of {known}")
    for key in keys:
        value = node[key]
        if isinstance(value, DictConfig) and "_target_" in value:
            _check_keys(value, f"{where}.{key}")


def build(node: DictConfig, where: str) -> Any:
    """``hydra.utils.instantiate(node)`` (containers passed as plain lists and dicts) after checking
    its keys (see the module doc); a :class:`~spacedg.errors.SpaceDGError` raised by the target is
    re-raised as is."""
    _check_keys(node, where)
    try:
        return instantiate(node, _convert_="all")
    except InstantiationException as err:
        cause: BaseException | None = err
        while cause is not None and not isinstance(cause, SpaceDGError):
            cause = cause.__cause__
        if cause is None:
            raise
        raise cause.with_traceback(cause.__traceback__) from None
