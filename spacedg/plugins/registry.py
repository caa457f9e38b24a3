"""The plugin registry: loads entry points, records broken plugins, withholds clashing names.

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
   namespaces) is a **clash**. Loading goes on: the clash is recorded (:attr:`Registry.clashes`,
   listed by ``spacedg plugins``) and announced once as a :class:`~spacedg.errors.PluginWarning`
   (the command line prints ``spacedg: warning: …`` on stderr). The clashing name is withheld:
   :func:`get_degradation` / :func:`get_question_family` of that name, and
   :func:`list_degradations` / :func:`list_question_families` (whose callers use every name)
   raise :class:`~spacedg.errors.DuplicatePluginError` naming both sources and the fix. Every
   other name, including the other names of both plugins, works as usual, so commands that do
   not use the clashing name run on. :func:`degradation_names` / :func:`question_family_names`
   list names only (clashing ones included) and never raise.

Interrupts and slow imports (the import is the only plugin code that runs on every command):

- Ctrl+C (SIGINT) while a plugin is being imported raises
  :class:`~spacedg.errors.PluginImportInterrupted` (a ``KeyboardInterrupt``) whose message names
  that plugin; the command line prints it on one line and exits with status 130. A plugin that
  raises ``KeyboardInterrupt`` (or ``SystemExit``) itself, with no SIGINT delivered, is recorded as
  broken like any other import failure. (SIGINT is told apart by a handler installed for the
  duration of each import, in the main thread when Python's default handler is in place. Under
  another SIGINT handler a ``KeyboardInterrupt`` during an import is taken as the user's; in other
  threads, where SIGINT never lands, as the plugin's.)
- An import still running after :data:`SLOW_IMPORT_SECONDS` (2 s) triggers one
  :class:`~spacedg.errors.PluginWarning` at that moment, naming the plugin and
  ``SPACEDG_DISABLE_PLUGIN_AUTOLOAD=1``; every import's duration is kept
  (:meth:`Registry.import_seconds`, shown by ``spacedg plugins`` when slow). The built-ins
  import in about 0.3 s together, 0.1 s at most each.

Environment:

``SPACEDG_DISABLE_PLUGIN_AUTOLOAD=1``
    Load only the entry points of the ``spacedg`` distribution (hermetic runs); installed
    third-party plugins are skipped (and named in "unknown name" errors).
``SPACEDG_PLUGINS=pkg.mod,other.mod:obj``
    Additionally import these modules (or ``module:attribute`` objects) and register them,
    whether or not autoload is disabled. A module that is already registered is skipped.

In-process use: :meth:`Registry.register_plugin` registers an object or module directly
(errors, clashes included, raise instead of being recorded).
"""

from __future__ import annotations

import copy
import importlib
import importlib.metadata as metadata
import os
import re
import signal
import threading
import time
import traceback
import types
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Literal

import pluggy

from spacedg.errors import (
    DuplicatePluginError,
    PluginError,
    PluginImportInterrupted,
    PluginWarning,
    UnknownPluginError,
)
from spacedg.plugins import hookspecs
from spacedg.plugins.origin import PLUGINS_ENV, PluginOrigin
from spacedg.plugins.question_family import QuestionFamily
from spacedg.plugins.specs import DegradationSpec, suggest

__all__ = [
    "AUTOLOAD_ENV",
    "BUILTIN_DISTRIBUTION",
    "BrokenPlugin",
    "PluginRecord",
    "PluginClash",
    "Registry",
    "SLOW_IMPORT_SECONDS",
    "get_registry",
    "reset_registry",
    "list_degradations",
    "get_degradation",
    "list_question_families",
    "get_question_family",
    "degradation_names",
    "question_family_names",
]

AUTOLOAD_ENV = "SPACEDG_DISABLE_PLUGIN_AUTOLOAD"
BUILTIN_DISTRIBUTION = "spacedg"

_HOOKS = ("spacedg_register_degradations", "spacedg_register_question_families")
_TRUE = {"1", "true", "yes", "on"}
#: A plugin import still running after this many seconds is announced (a PluginWarning naming it).
SLOW_IMPORT_SECONDS = 2.0
_FALSE = {"", "0", "false", "no", "off"}


def _canonical(dist_name: str) -> str:
    """PEP 503 normalised distribution name."""
    return re.sub(r"[-_.]+", "-", dist_name).lower()


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


@dataclass(frozen=True)
class PluginClash:
    """One name registered by more than one plugin (withheld: using it is an error).

    Attributes:
        kind: ``"degradation"`` or ``"question family"``.
        name: the clashing name.
        sources: every plugin that registered it, in load order (built-ins first).
    """

    kind: str
    name: str
    sources: tuple[PluginOrigin, ...]

    def message(self) -> str:
        """The error text: both sources and the fix."""
        return Registry._duplicate_message(self.kind, self.name, self.sources[0], self.sources[-1], self.sources[1:-1])

    def warning(self) -> str:
        """The one-line warning printed when the registry loads."""
        dists = ", ".join(_short(o) for o in self.sources)
        return (
            f"{self.kind} {self.name!r} is registered by {len(self.sources)} plugins ({dists}); the name is withheld: "
            f"using it is an error until one is uninstalled, other names work. `spacedg plugins` lists the clash"
        )

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "name": self.name, "sources": [o.to_dict() for o in self.sources], "message": self.message()}


def _short(origin: PluginOrigin) -> str:
    if origin.distribution:
        return f"{origin.distribution} {origin.version or '?'}"
    return origin.value


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
        self._clashes: dict[tuple[str, str], PluginClash] = {}
        self._import_seconds: dict[PluginOrigin, float] = {}
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
        for clash in registry.clashes:
            warnings.warn(PluginWarning(clash.warning()), stacklevel=2)
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
                self._load_guarded(origin, ep.load)

    def load_module(self, target: str) -> None:
        """Import ``"pkg.mod"`` (or ``"pkg.mod:attr"``) and register it; failures are recorded as broken."""
        module_name, _, attr = target.partition(":")
        dist, version = _distribution_of_module(module_name)
        builtin = dist is not None and _canonical(dist) == BUILTIN_DISTRIBUTION
        origin = PluginOrigin(target, target, dist, version, builtin, "env")
        def load() -> Any:
            obj: Any = importlib.import_module(module_name)
            for part in filter(None, attr.split(".")):
                obj = getattr(obj, part)
            return obj

        with self._lock:
            self._load_guarded(origin, load)

    def _load_guarded(self, origin: PluginOrigin, load: Callable[[], Any]) -> None:
        """Import one plugin with ``load()`` and register what it provides; any failure but a real
        Ctrl+C (:class:`PluginImportInterrupted`) marks it broken."""
        try:
            with self._importing(origin):
                obj = load()
        except PluginImportInterrupted:
            raise
        except BaseException as err:  # noqa: BLE001 - any import failure marks the plugin broken
            self._broken.append(BrokenPlugin.from_exception(origin, "import", err))
            return
        self._add_recording(obj, origin)

    @contextmanager
    def _importing(self, origin: PluginOrigin) -> Iterator[None]:
        """Import one plugin: time it (a warning once it passes :data:`SLOW_IMPORT_SECONDS`), and
        turn a Ctrl+C into :class:`PluginImportInterrupted` naming it (see the module docstring).
        A ``KeyboardInterrupt`` the plugin raised itself propagates as is (recorded as broken)."""
        started = time.perf_counter()
        _IMPORT_CLOCK.begin(origin)
        try:
            interrupted = PluginImportInterrupted(f"interrupted while importing plugin {origin.describe()}")
            with _sigint_watch() as state:
                try:
                    yield
                except KeyboardInterrupt as err:
                    if isinstance(err, PluginImportInterrupted):
                        raise
                    if state["sigint"] or (not state["watched"] and state["main"]):
                        raise interrupted from None
                    raise
            if state["sigint"]:  # the plugin swallowed the KeyboardInterrupt; the user still asked to stop
                raise interrupted
        finally:
            _IMPORT_CLOCK.end()
            self._import_seconds[origin] = time.perf_counter() - started

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
            self._add(obj, origin, record_clashes=True)
        except _PluginFailure as failure:
            self._broken.append(BrokenPlugin.from_exception(origin, failure.phase, failure.err))

    def _add(self, obj: object, origin: PluginOrigin, *, record_clashes: bool = False) -> PluginRecord:
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
            record = self._commit(origin, degradations, families, record_clashes=record_clashes)
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

    def _commit(self, origin: PluginOrigin, degradations: list[DegradationSpec], families: list[QuestionFamily],
                *, record_clashes: bool = False) -> PluginRecord:
        """Add one plugin's specs. A name it registers twice fails the plugin; a name another
        plugin holds raises :class:`DuplicatePluginError` (``record_clashes=False``) or is kept
        out and recorded as a :class:`PluginClash` (loading from the environment)."""
        clashing: list[tuple[str, str, PluginOrigin | None]] = []
        for kind, specs, table in (("degradation", degradations, self._degradations), ("question family", families, self._families)):
            seen: set[str] = set()
            for spec in specs:
                if spec.name in seen:
                    err = DuplicatePluginError(self._duplicate_message(kind, spec.name, origin, origin))
                    if record_clashes:
                        raise _PluginFailure("hook", err)
                    raise err
                seen.add(spec.name)
                other = table.get(spec.name)
                if other is not None or (kind, spec.name) in self._clashes:
                    first = other.origin if other is not None else self._clashes[(kind, spec.name)].sources[0]
                    if not record_clashes:
                        raise DuplicatePluginError(self._duplicate_message(kind, spec.name, first, origin))
                    clashing.append((kind, spec.name, first))
        for kind, name, first in clashing:
            known = self._clashes.get((kind, name))
            sources = (*known.sources, origin) if known is not None else (first, origin)
            self._clashes[(kind, name)] = PluginClash(kind, name, tuple(s for s in sources if s is not None))
        withheld = {(kind, name) for kind, name, _ in clashing}
        degradations = [s for s in degradations if ("degradation", s.name) not in withheld]
        families = [f for f in families if ("question family", f.name) not in withheld]
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
    def _duplicate_message(kind: str, name: str, first: PluginOrigin | None, second: PluginOrigin,
                           others: Iterable[PluginOrigin] = ()) -> str:
        first_text = first.describe() if first is not None else "an unknown plugin"
        if first == second:
            return f"{kind} {name!r} is registered twice by {second.describe()}; register each name once"
        others = list(others)
        fix_dist = second.distribution if not second.builtin else (first.distribution if first is not None else None)
        uninstall = f"pip uninstall {fix_dist}" if fix_dist else "uninstall one of them"
        count = "two" if not others else str(2 + len(others))
        middle = "".join(f", {o.describe()}" for o in others)
        if first is not None and first.builtin:
            fix = (f"Fix: uninstall the third-party one (e.g. `{uninstall}`): a built-in cannot be replaced, "
                   f"so a plugin must choose another name; or set {AUTOLOAD_ENV}=1 to load only the built-ins.")
        else:
            fix = (f"Fix: uninstall one of them (e.g. `{uninstall}`), or set {AUTOLOAD_ENV}=1 and name the plugin "
                   f"module you want in {PLUGINS_ENV}.")
        return f"{kind} {name!r} is registered by {count} plugins: {first_text}{middle}, and {second.describe()}. Names must be unique. {fix}"

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

    @property
    def clashes(self) -> list[PluginClash]:
        """Names registered by more than one plugin (withheld), in the order found."""
        return list(self._clashes.values())

    def import_seconds(self, origin: PluginOrigin) -> float | None:
        """How long importing the plugin of ``origin`` took (``None``: not imported by this registry)."""
        return self._import_seconds.get(origin)

    def _check_clashes(self, kind: str, name: str | None = None) -> None:
        found = [c for (k, n), c in self._clashes.items() if k == kind and (name is None or n == name)]
        if found:
            raise DuplicatePluginError(" ".join(c.message() for c in found))

    def list_degradations(self) -> list[DegradationSpec]:
        """Every registered degradation, sorted by name (:class:`DuplicatePluginError` while a
        degradation name clashes: the caller would use it; :meth:`degradation_names` does not raise)."""
        self._check_clashes("degradation")
        return [self._degradations[k] for k in sorted(self._degradations)]

    def list_question_families(self) -> list[QuestionFamily]:
        """Every registered question family, sorted by name (:class:`DuplicatePluginError` while
        a family name clashes; :meth:`question_family_names` does not raise)."""
        self._check_clashes("question family")
        return [self._families[k] for k in sorted(self._families)]

    def degradation_names(self) -> list[str]:
        """Every degradation name, clashing ones included, sorted (names only: never raises)."""
        return sorted(set(self._degradations) | {n for k, n in self._clashes if k == "degradation"})

    def question_family_names(self) -> list[str]:
        """Every question-family name, clashing ones included, sorted (names only: never raises)."""
        return sorted(set(self._families) | {n for k, n in self._clashes if k == "question family"})

    def get_degradation(self, name: str) -> DegradationSpec:
        """The degradation called ``name``; :class:`UnknownPluginError` with suggestions, or
        :class:`DuplicatePluginError` naming both sources when two plugins registered it."""
        return self._lookup("degradation", name, self._degradations)

    def get_question_family(self, name: str) -> QuestionFamily:
        """The question family called ``name``; :class:`UnknownPluginError` with suggestions, or
        :class:`DuplicatePluginError` naming both sources when two plugins registered it."""
        return self._lookup("question family", name, self._families)

    def _lookup(self, kind: str, name: object, table: Mapping[str, Any]) -> Any:
        if isinstance(name, str):
            self._check_clashes(kind, name)
        found = table.get(name) if isinstance(name, str) else None
        if found is None:
            raise UnknownPluginError(self._unknown_message(kind, name, table))
        return found

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
                    "import_seconds": _rounded(self._import_seconds.get(record.origin)),
                    "degradations": [self._degradations[n].describe() for n in record.degradations],
                    "question_families": [self._families[n].describe() for n in record.question_families],
                }
                for record in self._plugins
            ],
            "broken": [{**b.to_dict(), "import_seconds": _rounded(self._import_seconds.get(b.origin))} for b in self._broken],
            "skipped": [o.to_dict() for o in self._skipped],
            "clashes": [c.to_dict() for c in self._clashes.values()],
        }


def _rounded(seconds: float | None) -> float | None:
    return None if seconds is None else round(seconds, 3)


class _ImportClock:
    """One watcher thread (started on first use, then idle) that announces an import still
    running after :data:`SLOW_IMPORT_SECONDS`: cheaper than a timer thread per import."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._current: list[Any] | None = None  # [origin, started, announced]
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None

    def begin(self, origin: PluginOrigin) -> None:
        with self._lock:
            self._current = [origin, time.monotonic(), False]
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._watch, name="spacedg-plugin-import-clock", daemon=True)
                self._thread.start()
        self._wake.set()

    def end(self) -> None:
        with self._lock:
            self._current = None

    def _watch(self) -> None:
        while True:
            self._wake.wait()
            with self._lock:
                current = self._current
                if current is None:
                    self._wake.clear()
                    continue
                origin, started, announced = current
                limit = SLOW_IMPORT_SECONDS
                due = not announced and time.monotonic() - started >= limit
                if due:
                    current[2] = True
            if due:
                _warn_slow(origin, limit)
            time.sleep(0.05)


_IMPORT_CLOCK = _ImportClock()


def _new_clock_after_fork() -> None:  # a forked child has no watcher thread, and maybe a held lock
    global _IMPORT_CLOCK
    _IMPORT_CLOCK = _ImportClock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_new_clock_after_fork)


def _warn_slow(origin: PluginOrigin, seconds: float) -> None:
    """The note of an import still running after ``seconds`` (runs on the watcher thread)."""
    if origin.builtin:
        fix = "spacedg's own plugins import in well under a second: check the machine's load and the Python environment"
    else:
        what = f"uninstall {origin.distribution} (`pip uninstall {origin.distribution}`)" if origin.distribution else "remove it"
        fix = (f"every spacedg command imports the installed plugins: set {AUTOLOAD_ENV}=1 to skip third-party plugins, "
               f"or {what}")
    warnings.warn(PluginWarning(f"importing plugin {origin.describe()} has taken over {seconds:g} s and is still running; {fix}"),
                  stacklevel=1)


@contextmanager
def _sigint_watch() -> Iterator[dict[str, bool]]:
    """Tell a Ctrl+C apart from a ``KeyboardInterrupt`` raised by plugin code: ``state["sigint"]``
    becomes true when SIGINT arrives. Only in the main thread with Python's default handler
    (``state["watched"]``); otherwise the handlers are left alone (``state["main"]``: in the
    main thread with SIGINT not ignored, where an unwatched ``KeyboardInterrupt`` may be the
    user's; elsewhere it cannot)."""
    main = threading.current_thread() is threading.main_thread()
    # SIGINT ignored (a process started in the background by a non-interactive shell): no Ctrl+C
    # can arrive, so a KeyboardInterrupt is the plugin's own
    user_can_interrupt = main and signal.getsignal(signal.SIGINT) is not signal.SIG_IGN
    state = {"sigint": False, "watched": False, "main": user_can_interrupt}
    if not main or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield state
        return

    def handler(signum: int, frame: Any) -> None:
        state["sigint"] = True
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, handler)
    state["watched"] = True
    try:
        yield state
    finally:
        signal.signal(signal.SIGINT, previous)


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


def degradation_names() -> list[str]:
    """Every degradation name (clashing ones included), sorted; never raises for a clash."""
    return get_registry().degradation_names()


def question_family_names() -> list[str]:
    """Every question-family name (clashing ones included), sorted; never raises for a clash."""
    return get_registry().question_family_names()
