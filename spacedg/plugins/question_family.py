"""What a question-family plugin declares: :class:`QuestionFamily`, defined once.

A question family is described by its name (= ``question_type``), :class:`TaskGroup`,
:class:`AnswerType` (s), sub types, number of views, what it needs from the scene (visibility,
covisibility, …) and ``generate(scene, rng)``, which yields every valid
:class:`~spacedg.plugins.qa_record.QARecord` candidate in a seeded random order. The stored
generator checks each record against the declaration.

:class:`FamilyFactory` is how a family module declares its family once and still lets a caller
build it with other generator options (visibility thresholds, pair rules, …).
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from spacedg.errors import InvalidDataError, ParameterError, PluginError
from spacedg.plugins.candidates import PASSED_OVER, Candidate, gate_active
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.specs import SUB_TYPE_PATTERN, AnswerType, TaskGroup, _check_name, _enum

if TYPE_CHECKING:  # pragma: no cover - typing only
    from spacedg.plugins.origin import PluginOrigin
    from spacedg.scene.model import Scene

__all__ = ["SCENE_NEEDS", "FamilyFactory", "QuestionFamily", "QuestionGenerator"]

#: What a question family may need from the scene beyond its instances and views.
SCENE_NEEDS: frozenset[str] = frozenset({"visibility", "covisibility", "gaussians", "depth", "instance_ids"})


class QuestionGenerator(Protocol):
    """``generate(scene, rng) -> Iterator[QARecord]``: every valid candidate, in a seeded random order."""

    def __call__(self, scene: Scene, rng: np.random.Generator) -> Iterator[QARecord]: ...


# ---------------------------------------------------- question families
@dataclass(frozen=True, eq=False)
class QuestionFamily:
    """One ``question_type``: its declaration and its generator (see the module docstring).

    Attributes:
        name: the ``question_type`` (``^[a-z][a-z0-9_]*$``).
        task_group: one of :class:`TaskGroup`.
        answer_types: the answer types its records use.
        sub_question_types: every ``sub_question_type`` its records may carry.
        num_views: the numbers of views its records may use, e.g. ``(1,)`` or ``(1, 2)``.
        generate: ``generate(scene, rng) -> Iterator[QARecord]`` yielding **every** valid
            candidate in a seeded random order, lazily, so a caller takes as many as it wants.
            The stored callable is wrapped so that each record is checked against this
            declaration (the raw one is ``generate.__wrapped__``).
        needs: what it reads from the scene (subset of :data:`SCENE_NEEDS`), e.g.
            ``{"visibility"}``: per-view instance visibility must have been computed.
        description: what it asks, in a sentence.
        metric_only: a promise that every record (or light candidate) it yields carries a selection
            entry with a subject and without a cell (a metric answer, taken in generation order, one
            per subject): the question index (:mod:`spacedg.qa.build`), without a judge, then stops
            reading its candidates as soon as each sub type has the subjects its selection can take,
            and refuses a pooled record that breaks the promise. Default ``False``: every candidate is read.
        plain_rounds: a promise that every record (or light candidate) it yields carries a selection
            entry with a subject and a cell, that the records of one cell share one sub type, and that
            no entry has ``features`` or ``all_roles=False`` (balanced in whole rounds of its cell's
            roles, each filled by the first free candidate): the question index, without a judge
            and without partial rounds, then stops reading its candidates once the selection of what
            it has read is provably final (:func:`spacedg.qa.selection.prefix_settles`), and refuses
            a pooled record that breaks the promise. Not with ``metric_only``. Default ``False``.
        origin: set by the registry: which plugin registered the family.
    """

    name: str
    task_group: TaskGroup
    answer_types: frozenset[AnswerType]
    sub_question_types: tuple[str, ...]
    num_views: tuple[int, ...]
    generate: QuestionGenerator
    needs: frozenset[str] = frozenset()
    description: str = ""
    metric_only: bool = False
    plain_rounds: bool = False
    origin: PluginOrigin | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        _check_name(self.name, "question family name")
        where = f"question family {self.name!r}"
        object.__setattr__(self, "task_group", _enum(TaskGroup, self.task_group, f"{where}: task_group"))
        answer_types = self.answer_types
        if isinstance(answer_types, (str, AnswerType)):
            answer_types = (answer_types,)
        answer_types = frozenset(_enum(AnswerType, a, f"{where}: answer type") for a in answer_types)
        if not answer_types:
            raise PluginError(f"{where}: declare at least one answer type ({', '.join(a.value for a in AnswerType)})")
        object.__setattr__(self, "answer_types", answer_types)
        subs = (self.sub_question_types,) if isinstance(self.sub_question_types, str) else tuple(self.sub_question_types)
        if not subs:
            raise PluginError(f"{where}: declare at least one sub_question_type")
        for s in subs:
            if not isinstance(s, str) or not SUB_TYPE_PATTERN.match(s):
                raise PluginError(
                    f"{where}: sub_question_type {s!r} is not valid: start with a lower-case letter, then use "
                    "letters, digits, '_' and '+' (e.g. 'relpos_A_facing_B', 'yaw+pitch_dual')"
                )
        object.__setattr__(self, "sub_question_types", subs)
        views = (self.num_views,) if isinstance(self.num_views, int) else tuple(self.num_views)
        if not views or any(isinstance(v, bool) or not isinstance(v, int) or v < 1 for v in views):
            raise PluginError(f"{where}: num_views must be positive integers such as (1,) or (1, 2), got {self.num_views!r}")
        object.__setattr__(self, "num_views", tuple(sorted(set(views))))
        needs = frozenset(self.needs)
        unknown = sorted(needs - SCENE_NEEDS)
        if unknown:
            raise PluginError(f"{where}: needs {unknown} unknown; choose from {sorted(SCENE_NEEDS)}")
        object.__setattr__(self, "needs", needs)
        if not isinstance(self.description, str):
            raise PluginError(f"{where}: description must be a string")
        for promise in ("metric_only", "plain_rounds"):
            if not isinstance(getattr(self, promise), bool):
                raise PluginError(f"{where}: {promise} must be True or False, got {getattr(self, promise)!r}")
        if self.metric_only and self.plain_rounds:
            raise PluginError(f"{where}: metric_only and plain_rounds exclude each other (records without a cell, or all with one); declare one")
        if not callable(self.generate):
            raise PluginError(f"{where}: generate must be callable as generate(scene, rng), got {type(self.generate).__name__}")
        if not isinstance(self.generate, _CheckedGenerator):
            object.__setattr__(self, "generate", _CheckedGenerator(self.generate, self))

    def check_record(self, record: QARecord, scene_id: str | None = None) -> None:
        """Raise :class:`PluginError` if ``record`` contradicts this declaration."""
        where = f"question family {self.name!r}: record {record.id!r}"
        problems = []
        if record.question_type != self.name:
            problems.append(f"question_type is {record.question_type!r}, expected {self.name!r}")
        if record.task_group is not self.task_group:
            problems.append(f"task_group is {record.task_group.value!r}, expected {self.task_group.value!r}")
        if record.answer_type not in self.answer_types:
            problems.append(f"answer_type {record.answer_type.value!r} is not declared ({sorted(a.value for a in self.answer_types)})")
        if record.sub_question_type not in self.sub_question_types:
            problems.append(f"sub_question_type {record.sub_question_type!r} is not declared {list(self.sub_question_types)}")
        if len(record.views) not in self.num_views:
            problems.append(f"uses {len(record.views)} view(s), declared {list(self.num_views)}")
        if scene_id is not None and record.scene_id != scene_id:
            problems.append(f"scene_id is {record.scene_id!r}, expected {scene_id!r}")
        if problems:
            raise PluginError(f"{where}: " + "; ".join(problems))

    def describe(self) -> dict[str, Any]:
        """A JSON-serialisable description (what ``spacedg plugins --json`` prints)."""
        return {
            "name": self.name,
            "task_group": self.task_group.value,
            "answer_types": sorted(a.value for a in self.answer_types),
            "sub_question_types": list(self.sub_question_types),
            "num_views": list(self.num_views),
            "needs": sorted(self.needs),
            "description": self.description,
            "metric_only": self.metric_only,
            "plain_rounds": self.plain_rounds,
        }


@dataclass(frozen=True, eq=False)
class FamilyFactory:
    """A question family's declaration; calling it with the generator's options makes the :class:`QuestionFamily`.

    ``generate(scene, rng, …)`` takes the family's options after ``scene`` and ``rng``
    (visibility thresholds, pair rules, …), each with a default. A family module writes::

        make_family = FamilyFactory(generate, name=NAME, task_group=..., answer_types=..., ...)
        FAMILY = make_family()  # the registered family: the generator's defaults

    and ``make_family(thresholds)`` or ``make_family(pair_rules=rules)`` is the same family
    with other options, bound as in a call of ``generate`` (an unknown option raises
    ``TypeError``). The family stores ``functools.partial(generate, **options)``, so it pickles
    when ``generate`` does.

    Attributes:
        generate: the raw generator, options not bound.
        name, task_group, answer_types, sub_question_types, num_views, needs, description, metric_only, plain_rounds:
            as :class:`QuestionFamily` (any iterable of answer types and of needs).
    """

    generate: Callable[..., Iterator[QARecord]]
    name: str
    task_group: TaskGroup
    answer_types: Iterable[AnswerType]
    sub_question_types: tuple[str, ...]
    num_views: tuple[int, ...]
    needs: Iterable[str] = frozenset()
    description: str = ""
    metric_only: bool = False
    plain_rounds: bool = False

    def __call__(self, *args: Any, **kwargs: Any) -> QuestionFamily:
        """The family whose ``generate(scene, rng)`` is ``self.generate(scene, rng, *args, **kwargs)``."""
        bound = inspect.signature(self.generate).bind_partial(None, None, *args, **kwargs).arguments
        options = dict(list(bound.items())[2:])  # past scene and rng
        return QuestionFamily(
            name=self.name,
            task_group=self.task_group,
            answer_types=frozenset(self.answer_types),
            sub_question_types=self.sub_question_types,
            num_views=self.num_views,
            generate=functools.partial(self.generate, **options),
            needs=frozenset(self.needs),
            description=self.description,
            metric_only=self.metric_only,
            plain_rounds=self.plain_rounds,
        )


class _CheckedGenerator:
    """``generate(scene, rng)`` of a :class:`QuestionFamily`, checking every record it yields.

    A class rather than a closure so that families pickle (DataLoader workers). The raw
    generator is :attr:`__wrapped__`.
    """

    __spacedg_checked__ = True

    def __init__(self, raw: QuestionGenerator, family: QuestionFamily) -> None:
        self.__wrapped__ = raw
        self.family = family
        self.__name__ = getattr(raw, "__name__", "generate")
        self.__doc__ = getattr(raw, "__doc__", None)

    def __repr__(self) -> str:
        return f"<generate of question family {self.family.name!r}: {self.__wrapped__!r}>"

    def __call__(self, scene: Scene, rng: np.random.Generator) -> Iterator[QARecord]:
        family = self.family
        if not isinstance(rng, np.random.Generator):
            raise ParameterError(
                f"question family {family.name!r}: rng must be a numpy.random.Generator, got {type(rng).__name__}; "
                "use np.random.default_rng(seed)"
            )
        if "visibility" in family.needs and scene.instances and not any(inst.visibility for inst in scene.instances):
            raise InvalidDataError(
                f"question family {family.name!r} needs per-view instance visibility, but no instance of scene "
                f"{scene.id!r} has any; compute it first (spacedg.scene.visibility)"
            )
        if "covisibility" in family.needs and getattr(scene, "covisibility", None) is None:
            raise InvalidDataError(
                f"question family {family.name!r} needs view covisibility, but scene {scene.id!r} has none; "
                "attach it first (spacedg.scene.covisibility.with_covisibility)"
            )
        return self._records(scene, rng)

    def _records(self, scene: Scene, rng: np.random.Generator) -> Iterator[QARecord]:
        family = self.family
        gated = False  # whether a gated caller listens: asked at the first pass-over, as admission() is (a no raises below)
        for record in self.__wrapped__(scene, rng):
            if type(record) is Candidate:  # checked once built (spacedg.qa.build)
                yield record
                continue
            if record is PASSED_OVER and (gated or (gated := gate_active())):
                yield record
                continue
            if not isinstance(record, QARecord):
                raise PluginError(f"question family {family.name!r} yielded a {type(record).__name__}, not a QARecord")
            family.check_record(record, scene.id)
            yield record
