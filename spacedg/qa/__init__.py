"""Questions offline: a scene's question index, built once and audited (the ``qa`` layer).

The layer sits between :mod:`spacedg.plugins` (question families make candidate records) and
:mod:`spacedg.data` (the online side reads the indexes); it never imports ``data``.

- :mod:`spacedg.qa.index`: index files (full and selection indexes), cache keys, read/write.
- :mod:`spacedg.qa.build`: the build: visibility, pooling, selection, dealing, writing.
- :mod:`spacedg.qa.selection`: the debiased selection (subjects once, whole rounds per cell).
- :mod:`spacedg.qa.deal`: distractors and correct letters dealt evenly.
- :mod:`spacedg.qa.audit` (with ``audit_text``, ``audit_priors``, ``audit_model``): the blind stress test.
- :mod:`spacedg.qa.stats`: counts, answer balance, repeats, ambiguities.
- :mod:`spacedg.qa.judge`: the optional description judge; :mod:`spacedg.qa.views`: clean views.
- :mod:`spacedg.qa.preview`: a PNG contact sheet of records.

The public surface below is imported lazily (``import spacedg.qa`` loads nothing heavy)::

    from spacedg.qa import QABuildConfig, build_scene_index, read_index, blind_audit
"""

from __future__ import annotations

import importlib
from typing import Any

#: Public name → the module that defines it.
_PUBLIC = {
    "QABuildConfig": "spacedg.qa.index",
    "SceneQA": "spacedg.qa.index",
    "index_paths": "spacedg.qa.index",
    "index_is_current": "spacedg.qa.index",
    "read_index": "spacedg.qa.index",
    "prepare_scene": "spacedg.qa.build",
    "generate_records": "spacedg.qa.build",
    "build_scene_index": "spacedg.qa.build",
    "ensure_indexes": "spacedg.qa.build",
    "select_records": "spacedg.qa.selection",
    "blind_audit": "spacedg.qa.audit",
    "null_audit": "spacedg.qa.audit",
    "format_audit": "spacedg.qa.audit",
    "DescriptionJudge": "spacedg.qa.judge",
    "qa_sheet": "spacedg.qa.preview",
}

__all__ = sorted(_PUBLIC)


def __getattr__(name: str) -> Any:
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'spacedg.qa' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *_PUBLIC])
