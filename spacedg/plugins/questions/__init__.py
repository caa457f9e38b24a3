"""Built-in question families, one module per ``question_type``, plus shared helpers:
:mod:`~spacedg.plugins.questions.geometry` (poses, direction words, sectors, options, the
ground-plane compass frame, the box-intersection tolerance),
:mod:`~spacedg.plugins.questions.records` (what every family's records are built from: seeded
orders, the "referable object" rule, geometry-block entries) and
:mod:`~spacedg.plugins.questions.language` (wording). A family imports shared code only from
these and :mod:`spacedg.plugins.questions.view_sampling`, never from another family module.

Each family module defines ``FAMILY`` (a :class:`~spacedg.plugins.specs.QuestionFamily`) and
the hook ``spacedg_register_question_families``; it is announced as an entry point of the
``spacedg`` distribution in ``pyproject.toml``. Modules are imported by the registry, not here.
"""
