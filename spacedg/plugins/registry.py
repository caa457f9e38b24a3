"""The plugin registry: loads entry points, records broken plugins, rejects duplicate names.

Loading (what :func:`get_registry` does on first use, once per process):

1. Every entry point of the group ``spacedg`` is loaded (one entry point = one module or
   object implementing the hooks of :mod:`spacedg.plugins.hookspecs`). The built-ins are
   entry points of the ``spacedg`` distribution itself, so they travel the same path as
   third-party plugins.
2. Each plugin's hook implementations are called one plugin at a time with a ``register``
   callback of its own, so every registered spec records its :class:`PluginOrigin`. A plugin
   whose import raises (any exception), whose hooks do not match the hook specs, or whose hook
   raises is recorded as a :class:`BrokenPlugin` (entry point, distribution and version, error
   type and message, a short traceback) and contributes nothing; the others load normally.
3. Two plugins registering one name (degradation names and question-family names are separate
   namespaces) raise :class:`~spacedg.errors.DuplicatePluginError` naming both.

Environment:

``SPACEDG_DISABLE_PLUGIN_AUTOLOAD=1``
    Load only the entry points of the ``spacedg`` distribution (hermetic runs); installed
    third-party plugins are skipped (and named in "unknown name" errors).
``SPACEDG_PLUGINS=pkg.mod,other.mod:obj``
    Additionally import these modules (or ``module:attribute`` objects) and register them,
    whether or not autoload is disabled. A module that is already registered is skipped.

In-process use: :meth:`Registry.register_plugin` registers an object or module directly
(errors raise instead of being recorded).
"""

from __future__ import annotations

import copy
import importlib
import importlib.metadata as metadata
import os
import re
import threading
import traceback
import types
from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass
from typing import Any, Literal

import pluggy

from spacedg.errors import DuplicatePluginError, PluginError, UnknownPluginError
from spacedg.plugins import hookspecs
from spacedg.plugins.question_family import QuestionFamily
from spacedg.plugins.specs import DegradationSpec, suggest

__all__ = [
    "AUTOLOAD_ENV",
    "PLUGINS_ENV",
    "BUILTIN_DISTRIBUTION",
    "PluginOrigin",
    "BrokenPlugin",
    "PluginRecord",
    "Registry",
    "get_registry",
    "reset_registry",
    "list_degradations",
    "get_degradation",
    "list_question_families",
    "get_question_family",
]

AUTOLOAD_ENV = "SPACEDG_DISABLE_PLUGIN_AUTOLOAD"
PLUGINS_ENV = "SPACEDG_PLUGINS"
BUILTIN_DISTRIBUTION = "spacedg"

Source = Literal["entry_point", "env", "programmatic"]
_HOOKS = ("spacedg_register_degradations", "spacedg_register_question_families")
_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"", "0", "false", "no", "off"}


def _canonical(dist_name: str) -> str:
    """PEP 503 normalised distribution name."""
    return re.sub(r"[-_.]+", "-", dist_name).lower()


@dataclass(frozen=True)
class PluginOrigin:
    """Where a plugin came from.

    Attributes:
        name: entry-point name; the ``SPACEDG_PLUGINS`` item; or the name given to
            :meth:`Registry.register_plugin`.
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


@dataclass(frozen=True)
class BrokenPlugin:
    """A plugin that failed to load; it contributes nothing.

    Attributes:
        origin: where it came from.
        phase: ``"import"`` (loading the entry point raised), ``"register"`` (its hook
            implementations do not match the hook specs, or it implements none) or ``"hook"``
            (a hook raised, or passed ``register`` something that is not a spec).
        error_type: the exception's class name.
        message: the exception's message.
        traceback: the last frames of the traceback, formatted.
    """

    origin: PluginOrigin
    phase: Literal["import", "register", "hook"]
    error_type: str
    message: str
    traceback: str

    @classmethod
    def from_exception(cls, origin: PluginOrigin, phase: Literal["import", "register", "hook"], err: BaseException) -> BrokenPlugin:
        tb = "".join(traceback.format_exception(type(err), err, err.__traceback__, limit=-4)).rstrip()
        return cls(origin, phase, type(err).__name__, str(err), tb)

    @property
    def error(self) -> str:
        return f"{self.error_type}: {self.message}"

    def to_dict(self) -> dict[str, Any]:
        return {**self.origin.to_dict(), "phase": self.phase, "error_type": self.error_type, "message": self.message, "traceback": self.traceback}


@dataclass(frozen=True)
class PluginRecord:
    """A loaded plugin and the names it registered."""

    origin: PluginOrigin
    degradations: tuple[str, ...] = ()
    question_families: tuple[str, ...] = ()


class _PluginFailure(Exception):
    """Internal: a plugin failed in ``phase``; ``__cause__`` holds the original error."""

    def __init__(self, phase: Literal["register", "hook"], err: BaseException) -> None:
        super().__init__(f"{type(err).__name__}: {err}")
        self.phase = phase
        self.err = err


def _env_flag(environ: Mapping[str, str], name: str) -> bool:
    raw = environ.get(name, "")
    value = raw.strip().lower()
    if value in _TRUE:
        return True
    if value in _FALSE:
        return False
    raise PluginError(f"environment variable {name}={raw!r} is not a boolean; set it to 1 (on) or 0 (off)")


def _parse_modules(raw: str) -> list[str]:
    items = [item.strip() for item in raw.split(",")]
    bad = [item for item in items if item and not re.match(r"^[A-Za-z_][\w.]*(:[A-Za-z_][\w.]*)?$", item)]
    if bad:
        raise PluginError(
            f"environment variable {PLUGINS_ENV}: {bad} are not module paths; write comma-separated "
            "importable names such as 'my_pkg.plugin' or 'my_pkg.plugin:obj'"
        )
    return list(dict.fromkeys(item for item in items if item))


def _distribution_of_module(module_name: str) -> tuple[str | None, str | None]:
    top = module_name.split(".", 1)[0]
    try:
        dists = metadata.packages_distributions().get(top, [])
    except Exception:  # noqa: BLE001 - metadata of unrelated packages must not break loading
        dists = []
    if not dists:
        return None, None
    name = dists[0]
    try:
        return name, metadata.version(name)
    except metadata.PackageNotFoundError:
        return name, None


class Registry:
    """Degradations and question families by name, with the plugins that provided them.

    Build one with :meth:`from_environment` (what :func:`get_registry` does) or empty with
    ``Registry()`` and fill it with :meth:`load_entry_points`, :meth:`load_module` and
    :meth:`register_plugin`. Lookups are thread-safe; loading holds a lock.
    """

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._pm = pluggy.PluginManager(hookspecs.PROJECT_NAME)
        self._pm.add_hookspecs(hookspecs)
        self._degradations: dict[str, DegradationSpec] = {}
        self._families: dict[str, QuestionFamily] = {}
        self._plugins: list[PluginRecord] = []
        self._broken: list[BrokenPlugin] = []
        self._skipped: list[PluginOrigin] = []
        self.autoload: bool = True
        self.explicit_modules: tuple[str, ...] = ()

    # ------------------------------------------------------------ loading
    @classmethod
    def from_environment(cls, environ: Mapping[str, str] | None = None) -> Registry:
        """Load entry points (all, or only built-ins when ``SPACEDG_DISABLE_PLUGIN_AUTOLOAD``
        is set), then the modules named in ``SPACEDG_PLUGINS``."""
        env = os.environ if environ is None else environ
        autoload = not _env_flag(env, AUTOLOAD_ENV)
        modules = _parse_modules(env.get(PLUGINS_ENV, ""))
        registry = cls()
        registry.autoload = autoload
        registry.explicit_modules = tuple(modules)
        registry.load_entry_points(builtin_only=not autoload)
        for module in modules:
            registry.load_module(module)
        return registry

    def load_entry_points(self, *, builtin_only: bool = False) -> None:
        """Load every entry point of the group ``spacedg`` (built-ins first, then by
        distribution and name). With ``builtin_only`` the others are skipped and remembered."""
        eps = list(metadata.entry_points(group=hookspecs.ENTRY_POINT_GROUP))
        origins = []
        for ep in eps:
            dist = getattr(ep, "dist", None)
            dist_name = dist.name if dist is not None else None
            version = dist.version if dist is not None else None
            builtin = dist_name is not None and _canonical(dist_name) == BUILTIN_DISTRIBUTION
            origins.append((PluginOrigin(ep.name, ep.value, dist_name, version, builtin, "entry_point"), ep))
        origins.sort(key=lambda item: (not item[0].builtin, _canonical(item[0].distribution or ""), item[0].name))
        with self._lock:
            for origin, ep in origins:
                if builtin_only and not origin.builtin:
                    self._skipped.append(origin)
                    continue
                try:
                    obj = ep.load()
                except (Exception, SystemExit) as err:  # noqa: BLE001 - any import failure marks the plugin broken
                    self._broken.append(BrokenPlugin.from_exception(origin, "import", err))
                    continue
                self._add_recording(obj, origin)

    def load_module(self, target: str) -> None:
        """Import ``"pkg.mod"`` (or ``"pkg.mod:attr"``) and register it; failures are recorded as broken."""
        module_name, _, attr = target.partition(":")
        dist, version = _distribution_of_module(module_name)
        builtin = dist is not None and _canonical(dist) == BUILTIN_DISTRIBUTION
        origin = PluginOrigin(target, target, dist, version, builtin, "env")
        with self._lock:
            try:
                obj: Any = importlib.import_module(module_name)
                for part in filter(None, attr.split(".")):
                    obj = getattr(obj, part)
            except (Exception, SystemExit) as err:  # noqa: BLE001
                self._broken.append(BrokenPlugin.from_exception(origin, "import", err))
                return
            self._add_recording(obj, origin)

    def register_plugin(
        self,
        obj: object,
        name: str,
        *,
        distribution: str | None = None,
        version: str | None = None,
        builtin: bool = False,
    ) -> PluginRecord:
        """Register a module or object implementing the hooks, in-process.

        Unlike entry points, failures raise :class:`PluginError` (with the original error as
        ``__cause__``) instead of being recorded; duplicates raise :class:`DuplicatePluginError`.
        """
        if not isinstance(name, str) or not name:
            raise PluginError(f"register_plugin: name must be a non-empty string, got {name!r}")
        value = str(obj.__name__) if isinstance(obj, types.ModuleType) else f"{type(obj).__module__}.{type(obj).__qualname__} instance"
        origin = PluginOrigin(name, value, distribution, version, builtin, "programmatic")
        with self._lock:
            try:
                return self._add(obj, origin)
            except _PluginFailure as failure:
                raise PluginError(f"{origin.describe()} failed while {'registering' if failure.phase == 'register' else 'running its hooks'}: {failure}") from failure.err

    def _add_recording(self, obj: object, origin: PluginOrigin) -> None:
        try:
            self._add(obj, origin)
        except _PluginFailure as failure:
            self._broken.append(BrokenPlugin.from_exception(origin, failure.phase, failure.err))

    def _add(self, obj: object, origin: PluginOrigin) -> PluginRecord:
        if self._pm.is_registered(obj):
            # e.g. a module named in SPACEDG_PLUGINS that an entry point already loaded
            for record in self._plugins:
                if self._pm.get_plugin(self._plugin_key(record.origin)) is obj:
                    return record
            return PluginRecord(origin)
        key = self._plugin_key(origin)
        try:
            self._pm.register(obj, name=key)
            self._pm.check_pending()
        except Exception as err:  # noqa: BLE001 - pluggy validation errors
            if self._pm.is_registered(obj):
                self._pm.unregister(obj)
            raise _PluginFailure("register", err) from err
        try:
            impls = [
                (hook, impl)
                for hook in _HOOKS
                for impl in getattr(self._pm.hook, hook).get_hookimpls()
                if impl.plugin is obj and not (impl.hookwrapper or impl.wrapper)
            ]
            if not impls:
                raise _PluginFailure(
                    "register",
                    PluginError(
                        f"{origin.describe()} implements no spacedg hook; decorate "
                        f"{' or '.join(_HOOKS)} with spacedg.plugins.hookimpl"
                    ),
                )
            degradations: list[DegradationSpec] = []
            families: list[QuestionFamily] = []
            registers: dict[str, Callable[[Any], None]] = {
                "spacedg_register_degradations": self._stager(degradations, DegradationSpec, origin),
                "spacedg_register_question_families": self._stager(families, QuestionFamily, origin),
            }
            for hook, impl in impls:
                kwargs = {"register": registers[hook]}
                try:
                    impl.function(*[kwargs[arg] for arg in impl.argnames])
                except Exception as err:  # noqa: BLE001 - a raising hook marks the plugin broken
                    raise _PluginFailure("hook", err) from err
            record = self._commit(origin, degradations, families)
        except BaseException:
            self._pm.unregister(obj)
            raise
        return record

    def _plugin_key(self, origin: PluginOrigin) -> str:
        return f"{origin.source}:{origin.distribution or '-'}:{origin.name}"

    @staticmethod
    def _stager(bucket: list[Any], kind: type, origin: PluginOrigin) -> Callable[[Any], None]:
        def register(spec: Any) -> None:
            if not isinstance(spec, kind):
                raise PluginError(f"register() expects a {kind.__name__}, got {type(spec).__name__}")
            bucket.append(spec)

        register.__doc__ = f"Register one {kind.__name__} (from {origin.describe()})."
        return register

    def _commit(self, origin: PluginOrigin, degradations: list[DegradationSpec], families: list[QuestionFamily]) -> PluginRecord:
        for kind, specs, table in (("degradation", degradations, self._degradations), ("question family", families, self._families)):
            seen: dict[str, Any] = {}
            for spec in specs:
                other = table.get(spec.name)
                if other is not None or spec.name in seen:
                    first = other.origin if other is not None else origin
                    raise DuplicatePluginError(self._duplicate_message(kind, spec.name, first, origin))
                seen[spec.name] = spec
        stamped_d = [_with_origin(spec, origin) for spec in degradations]
        stamped_f = [_with_origin(spec, origin) for spec in families]
        for spec in stamped_d:
            self._degradations[spec.name] = spec
        for fam in stamped_f:
            self._families[fam.name] = fam
        record = PluginRecord(origin, tuple(s.name for s in stamped_d), tuple(f.name for f in stamped_f))
        self._plugins.append(record)
        return record

    @staticmethod
    def _duplicate_message(kind: str, name: str, first: PluginOrigin | None, second: PluginOrigin) -> str:
        first_text = first.describe() if first is not None else "an unknown plugin"
        if first == second:
            return f"{kind} {name!r} is registered twice by {second.describe()}; register each name once"
        fix_dist = second.distribution if not second.builtin else (first.distribution if first is not None else None)
        uninstall = f"pip uninstall {fix_dist}" if fix_dist else "uninstall one of them"
        return (
            f"{kind} {name!r} is registered by two plugins: {first_text}, and {second.describe()}. "
            f"Names must be unique. Fix: uninstall one of them (e.g. `{uninstall}`), or set "
            f"{AUTOLOAD_ENV}=1 and name the plugin module you want in {PLUGINS_ENV}."
        )

    # ------------------------------------------------------------ queries
    @property
    def plugins(self) -> list[PluginRecord]:
        """Loaded plugins, in load order."""
        return list(self._plugins)

    @property
    def broken(self) -> list[BrokenPlugin]:
        """Plugins that failed to load, in load order."""
        return list(self._broken)

    @property
    def skipped(self) -> list[PluginOrigin]:
        """Installed third-party entry points not loaded because autoload is disabled."""
        return list(self._skipped)

    def list_degradations(self) -> list[DegradationSpec]:
        """Every registered degradation, sorted by name."""
        return [self._degradations[k] for k in sorted(self._degradations)]

    def list_question_families(self) -> list[QuestionFamily]:
        """Every registered question family, sorted by name."""
        return [self._families[k] for k in sorted(self._families)]

    def get_degradation(self, name: str) -> DegradationSpec:
        """The degradation called ``name``; :class:`UnknownPluginError` with suggestions otherwise."""
        spec = self._degradations.get(name) if isinstance(name, str) else None
        if spec is None:
            raise UnknownPluginError(self._unknown_message("degradation", name, self._degradations))
        return spec

    def get_question_family(self, name: str) -> QuestionFamily:
        """The question family called ``name``; :class:`UnknownPluginError` with suggestions otherwise."""
        fam = self._families.get(name) if isinstance(name, str) else None
        if fam is None:
            raise UnknownPluginError(self._unknown_message("question family", name, self._families))
        return fam

    def _unknown_message(self, kind: str, name: object, available: Iterable[str]) -> str:
        names = sorted(available)
        plural = "question families" if kind == "question family" else f"{kind}s"
        parts = [f"unknown {kind} {name!r}."]
        close = suggest(str(name), names)
        if close:
            parts.append(f"Did you mean {', '.join(repr(c) for c in close)}?")
        parts.append(f"Available {plural}: {', '.join(names) if names else 'none'}.")
        key = str(name)
        suspects = [b for b in self._broken if b.origin.name == key or key in suggest(b.origin.name, [key])]
        for b in suspects:
            parts.append(f"The plugin {b.origin.describe()} may provide it but failed to load ({b.error}).")
        others = [b for b in self._broken if b not in suspects]
        if others:
            listing = ", ".join(repr(b.origin.name) for b in others)
            other = " other" if suspects else ""
            parts.append(f"{len(others)}{other} plugin(s) failed to load ({listing}); run `spacedg plugins` to see their errors.")
        if not self.autoload:
            parts.append(
                f"Plugin autoloading is disabled ({AUTOLOAD_ENV}=1): only built-in plugins and modules named in "
                f"{PLUGINS_ENV} are loaded."
            )
            for origin in self._skipped:
                if origin.name == key or key in suggest(origin.name, [key]):
                    parts.append(f"The installed {origin.describe()} was skipped; unset {AUTOLOAD_ENV} or set {PLUGINS_ENV}={origin.value}.")
        return " ".join(parts)

    def describe(self) -> dict[str, Any]:
        """A JSON-serialisable document of everything loaded (``spacedg plugins --json``)."""
        return {
            "autoload": self.autoload,
            "explicit_modules": list(self.explicit_modules),
            "plugins": [
                {
                    **record.origin.to_dict(),
                    "degradations": [self._degradations[n].describe() for n in record.degradations],
                    "question_families": [self._families[n].describe() for n in record.question_families],
                }
                for record in self._plugins
            ],
            "broken": [b.to_dict() for b in self._broken],
            "skipped": [o.to_dict() for o in self._skipped],
        }


def _with_origin(spec: Any, origin: PluginOrigin) -> Any:
    """A copy of ``spec`` that records ``origin`` (specs are frozen; validation already ran)."""
    stamped = copy.copy(spec)
    object.__setattr__(stamped, "origin", origin)
    return stamped


# ----------------------------------------------------------- process-wide
_REGISTRY: Registry | None = None
_REGISTRY_LOCK = threading.Lock()


def get_registry() -> Registry:
    """The process-wide registry, built from the environment on first use (thread-safe)."""
    global _REGISTRY
    registry = _REGISTRY
    if registry is None:
        with _REGISTRY_LOCK:
            if _REGISTRY is None:
                _REGISTRY = Registry.from_environment()
            registry = _REGISTRY
    return registry


def reset_registry() -> None:
    """Forget the process-wide registry; the next :func:`get_registry` reloads (for tests)."""
    global _REGISTRY
    with _REGISTRY_LOCK:
        _REGISTRY = None


def list_degradations() -> list[DegradationSpec]:
    """Every registered degradation, sorted by name."""
    return get_registry().list_degradations()


def get_degradation(name: str) -> DegradationSpec:
    """The degradation called ``name`` (raises :class:`UnknownPluginError` with suggestions)."""
    return get_registry().get_degradation(name)


def list_question_families() -> list[QuestionFamily]:
    """Every registered question family, sorted by name."""
    return get_registry().list_question_families()


def get_question_family(name: str) -> QuestionFamily:
    """The question family called ``name`` (raises :class:`UnknownPluginError` with suggestions)."""
    return get_registry().get_question_family(name)
