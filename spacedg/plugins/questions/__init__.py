"""Built-in question families, one module per ``question_type``, plus shared helpers
(:mod:`~spacedg.plugins.questions.language` for wording).

Each family module defines ``FAMILY`` (a :class:`~spacedg.plugins.specs.QuestionFamily`) and
the hook ``spacedg_register_question_families``; it is announced as an entry point of the
``spacedg`` distribution in ``pyproject.toml``. Modules are imported by the registry, not here.
"""
