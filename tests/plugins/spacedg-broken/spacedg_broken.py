"""A spacedg plugin that cannot be imported: it depends on a module that does not exist.

The registry must record it as broken (``spacedg plugins`` lists it with its error) and keep
loading the other plugins.
"""

import spacedg_this_dependency_does_not_exist  # noqa: F401

from spacedg.plugins import hookimpl


@hookimpl
def spacedg_register_degradations(register):  # pragma: no cover - never reached
    raise AssertionError("unreachable")
