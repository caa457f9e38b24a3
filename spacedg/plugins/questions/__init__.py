"""Built-in question families, one module per ``question_type``, plus shared helpers:
:mod:`~spacedg.plugins.questions.geometry` (poses, direction words, sectors, options, the
ground-plane compass frame, the box-intersection tolerance),
:mod:`~spacedg.plugins.questions.records` (what every family's records are built from: seeded
orders, the "referable object" rule, geometry-block entries),
:mod:`~spacedg.plugins.questions.language` (wording) and
:mod:`~spacedg.plugins.questions.pairs` (the pair-family factory: a two-view object family
from its per-pair record stream). A family imports shared code only from these and
:mod:`spacedg.plugins.questions.view_sampling`, never from another family module.

Each family module defines ``make_family`` (a
:class:`~spacedg.plugins.question_family.FamilyFactory`: the family's declaration, called with
other generator options for a custom family), ``FAMILY = make_family()`` and the hook
``spacedg_register_question_families`` (:func:`~spacedg.plugins.hookspecs.registering`); it
is announced as an entry point of the ``spacedg`` distribution in ``pyproject.toml``. Modules
are imported by the registry, not here.
"""
