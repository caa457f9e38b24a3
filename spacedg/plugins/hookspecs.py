"""The two spacedg hooks (pluggy project name ``"spacedg"``).

A plugin is a module (or object) exposing one or both hook implementations, and is
announced by an entry point in the group ``spacedg`` of its distribution::

    # pyproject.toml of a third-party package
    [project.entry-points.spacedg]
    vignetting = "spacedg_vignetting"

    # spacedg_vignetting.py
    from spacedg.plugins import hookimpl, DegradationSpec

    @hookimpl
    def spacedg_register_degradations(register):
        register(DegradationSpec(...))

Each hook receives a ``register`` callable; call it once per spec. The registry gives every
plugin its own ``register`` so each spec records where it came from. A plugin whose import or
hook raises is recorded as broken (``spacedg plugins`` lists it) and contributes nothing.

A module that declares its specs as constants may write the hook as :func:`registering`
(the built-ins do)::

    spacedg_register_degradations = registering(SPEC)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import pluggy

if TYPE_CHECKING:  # pragma: no cover - typing only
    from spacedg.plugins.question_family import QuestionFamily
    from spacedg.plugins.specs import DegradationSpec

PROJECT_NAME = "spacedg"
#: The entry-point group the registry loads plugins from.
ENTRY_POINT_GROUP = "spacedg"

hookspec = pluggy.HookspecMarker(PROJECT_NAME)
#: Decorator for plugin authors: ``@hookimpl def spacedg_register_degradations(register): ...``.
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)


@hookspec
def spacedg_register_degradations(register: Callable[[DegradationSpec], None]) -> None:
    """Register degradations: call ``register(spec)`` once per :class:`DegradationSpec`."""


@hookspec
def spacedg_register_question_families(register: Callable[[QuestionFamily], None]) -> None:
    """Register question families: call ``register(family)`` once per :class:`QuestionFamily`."""


def registering(*items: DegradationSpec | QuestionFamily) -> Callable[[Callable[[Any], None]], None]:
    """A hook implementation calling ``register(item)`` for each of ``items``, in order.

    Assign it to the hook's name in the plugin module (pluggy finds hook implementations by
    name): ``spacedg_register_degradations = registering(SPEC)`` or
    ``spacedg_register_question_families = registering(FAMILY)``. The same as writing the
    decorated function out (module docstring).
    """

    @hookimpl
    def register_items(register: Callable[[Any], None]) -> None:
        for item in items:
            register(item)

    return register_items
