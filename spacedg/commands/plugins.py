"""``spacedg plugins [--json]``: list plugins, what they provide, the broken ones and name clashes.

This is the diagnosis tool, so it works whatever is installed: exit status 0 even when some
plugins are broken (listed with their error) or two plugins register one name (the clash is
listed with both sources and the fix; other commands warn about it and fail only when they use
that name). An import slower than the registry's threshold is listed with its duration.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from spacedg.commands import _args
from spacedg.plugins.origin import PLUGINS_ENV
from spacedg.plugins.registry import AUTOLOAD_ENV, SLOW_IMPORT_SECONDS, Registry, get_registry


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``plugins`` subcommand on ``subparsers``."""
    parser = _args.add_command(
        subparsers, "plugins", run, help="list installed plugins (degradations, question families) and broken ones",
        description=f"List every plugin found through the 'spacedg' entry-point group, with its distribution, version "
                    f"and what it provides, and the plugins that failed to load. Environment: {AUTOLOAD_ENV}=1 loads only "
                    f"the built-ins; {PLUGINS_ENV}=pkg.mod,... loads extra modules.",
    )
    parser.add_argument("--json", action="store_true", help="print a machine-readable JSON document instead of text")
    return parser


def run(args: argparse.Namespace) -> int:
    registry = get_registry()
    if args.json:
        json.dump(registry.describe(), sys.stdout, indent=2, sort_keys=False)
        sys.stdout.write("\n")
    else:
        sys.stdout.write(format_text(registry))
    return 0


def format_text(registry: Registry) -> str:
    """The human-readable listing."""
    doc = registry.describe()
    lines: list[str] = []
    n_ok, n_broken, n_clash = len(doc["plugins"]), len(doc["broken"]), len(doc["clashes"])
    state = "on" if doc["autoload"] else f"off ({AUTOLOAD_ENV}=1: built-ins only)"
    clashes = f", {n_clash} name clash{'es' if n_clash != 1 else ''}" if n_clash else ""
    lines.append(f"spacedg plugins: {n_ok} loaded, {n_broken} broken{clashes}; autoload {state}")
    if doc["explicit_modules"]:
        lines.append(f"  {PLUGINS_ENV}: {', '.join(doc['explicit_modules'])}")
    for plugin in doc["plugins"]:
        lines.append("")
        lines.append(f"{plugin['name']}  [{_dist(plugin)}, {'built-in' if plugin['builtin'] else 'third-party'}]  "
                     f"{plugin['value']}{_slow(plugin)}")
        for deg in plugin["degradations"]:
            params = ", ".join(
                f"{p['name']} ({p['unit']}) {_limits(p)}" for p in deg["params"]
            ) or "no parameters"
            lines.append(f"  degradation      {deg['name']:<22} stage={deg['stage']:<8} category={deg['category']:<16} {params}")
        for fam in plugin["question_families"]:
            views = "/".join(str(v) for v in fam["num_views"])
            lines.append(
                f"  question family  {fam['name']:<22} task_group={fam['task_group']:<15} "
                f"answers={','.join(fam['answer_types'])} views={views}"
            )
        if not plugin["degradations"] and not plugin["question_families"]:
            lines.append("  (registers nothing)")
    if doc["broken"]:
        lines.append("")
        lines.append("Broken plugins (not loaded):")
        for b in doc["broken"]:
            lines.append(f"  {b['name']}  [{_dist(b)}, {b['value']}] failed at {b['phase']}: {b['error_type']}: "
                         f"{b['message']}{_slow(b)}")
    if doc["clashes"]:
        lines.append("")
        lines.append("Name clashes (the name is withheld: commands that use it fail until one plugin is uninstalled):")
        for c in doc["clashes"]:
            sources = ", ".join(f"{s['name']} [{_dist(s)}, {'built-in' if s['builtin'] else 'third-party'}]" for s in c["sources"])
            lines.append(f"  {c['kind']} {c['name']!r}: {sources}")
            lines.append(f"    {c['message']}")
    if doc["skipped"]:
        lines.append("")
        lines.append(f"Skipped (autoload disabled; add to {PLUGINS_ENV} to load):")
        for s in doc["skipped"]:
            lines.append(f"  {s['name']}  [{_dist(s)}]  {s['value']}")
    return "\n".join(lines) + "\n"


def _slow(entry: dict[str, Any]) -> str:
    seconds = entry.get("import_seconds")
    return f"  (slow import: {seconds:.1f} s)" if seconds is not None and seconds >= SLOW_IMPORT_SECONDS else ""


def _dist(entry: dict[str, Any]) -> str:
    if not entry.get("distribution"):
        return "no distribution"
    return f"{entry['distribution']} {entry.get('version') or '?'}"


def _limits(param: dict[str, Any]) -> str:
    lo = "-inf" if param["low"] is None else f"{param['low']:g}"
    hi = "inf" if param["high"] is None else f"{param['high']:g}"
    return f"[{lo}, {hi}]"
