"""spacedg plugins: degradations and question families, registered through pluggy hooks.

Public API::

    from spacedg.plugins import (
        hookimpl, registering,                        # for plugin authors: the hook decorator, or a hook from constants
        DegradationSpec, ParamSpec, ParamRange, Category, Stage,
        QuestionFamily, FamilyFactory, AnswerType, TaskGroup,
        get_registry, reset_registry,
        list_degradations, get_degradation,
        list_question_families, get_question_family,
        degradation_names, question_family_names,     # names only (never raise for a clash)
    )

See :mod:`spacedg.plugins.specs` for the stage contracts, :mod:`spacedg.plugins.registry`
for loading rules and environment variables, and ``spacedg plugins`` for what is installed.
Question-family authors import their helpers (records, wording, visibility, view pairs,
options, answers) from :mod:`spacedg.plugins.authoring`, a module of its own (not re-exported
here: it reaches into the question helpers, which this package's contracts do not need).
"""

from spacedg.plugins.hookspecs import ENTRY_POINT_GROUP, hookimpl, registering
from spacedg.plugins.registry import (
    AUTOLOAD_ENV,
    BrokenPlugin,
    PluginClash,
    PluginRecord,
    Registry,
    degradation_names,
    get_degradation,
    get_question_family,
    get_registry,
    list_degradations,
    list_question_families,
    question_family_names,
    reset_registry,
)
from spacedg.plugins.origin import PLUGINS_ENV, PluginOrigin
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.question_family import FamilyFactory, QuestionFamily
from spacedg.plugins.specs import (
    REQUIRED_PRESETS,
    SEVERITY_PRESETS,
    AnswerType,
    Category,
    DegradationSpec,
    DisplayApply,
    LinearApply,
    ParamRange,
    ParamSpec,
    RasterApply,
    Stage,
    TaskGroup,
)

__all__ = [
    "ENTRY_POINT_GROUP",
    "AUTOLOAD_ENV",
    "PLUGINS_ENV",
    "REQUIRED_PRESETS",
    "SEVERITY_PRESETS",
    "hookimpl",
    "registering",
    "AnswerType",
    "BrokenPlugin",
    "PluginClash",
    "Category",
    "DegradationSpec",
    "FamilyFactory",
    "DisplayApply",
    "LinearApply",
    "ParamRange",
    "ParamSpec",
    "QARecord",
    "PluginOrigin",
    "PluginRecord",
    "QuestionFamily",
    "RasterApply",
    "Registry",
    "Stage",
    "TaskGroup",
    "degradation_names",
    "get_degradation",
    "get_question_family",
    "get_registry",
    "list_degradations",
    "list_question_families",
    "question_family_names",
    "reset_registry",
]
