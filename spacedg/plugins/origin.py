"""Where a plugin came from: :class:`PluginOrigin`, a plain value type.

It lives apart from the loader (:mod:`spacedg.plugins.registry`) so that the contracts which
carry it (:class:`~spacedg.plugins.specs.DegradationSpec`,
:class:`~spacedg.plugins.question_family.QuestionFamily`) need not import the loader, and no
import cycle runs through the plugin contracts.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Literal

__all__ = ["PLUGINS_ENV", "PluginOrigin", "Source"]

#: Environment variable naming extra plugin modules (``pkg.mod,other.mod:obj``).
PLUGINS_ENV = "SPACEDG_PLUGINS"

Source = Literal["entry_point", "env", "programmatic"]


@dataclass(frozen=True)
class PluginOrigin:
    """Where a plugin came from.

    Attributes:
        name: entry-point name; the ``SPACEDG_PLUGINS`` item; or the name given to
            :meth:`~spacedg.plugins.registry.Registry.register_plugin`.
        value: what was loaded: ``"module"`` or ``"module:attribute"`` (``repr`` for objects
            registered in-process).
        distribution: the installed distribution providing it (``None`` if unknown).
        version: that distribution's version (``None`` if unknown).
        builtin: provided by the ``spacedg`` distribution itself.
        source: ``"entry_point"``, ``"env"`` (``SPACEDG_PLUGINS``) or ``"programmatic"``.
    """

    name: str
    value: str
    distribution: str | None
    version: str | None
    builtin: bool
    source: Source

    @property
    def kind(self) -> str:
        return "built-in" if self.builtin else "third-party"

    def describe(self) -> str:
        """``"entry point 'x' (module) of distribution d 1.0"``-style text for messages."""
        what = {
            "entry_point": f"entry point {self.name!r} ({self.value})",
            "env": f"module {self.value!r} from {PLUGINS_ENV}",
            "programmatic": f"plugin {self.name!r} registered in-process",
        }[self.source]
        if self.distribution:
            what += f" of distribution {self.distribution} {self.version or '(unknown version)'}"
        return what

    def to_dict(self) -> dict[str, Any]:
        """Every field, in declaration order (plain JSON types)."""
        return asdict(self)
