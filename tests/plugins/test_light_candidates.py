"""Light candidates (:mod:`spacedg.plugins.candidates`) are the records the families yield
otherwise: same records, same order, same draws; a candidate's fields are its record's."""

from __future__ import annotations

import itertools
import zlib

import numpy as np
import pytest

from spacedg.plugins.candidates import Candidate, light_candidates
from spacedg.qa.index import selected_families
from spacedg.qa.twins import named_ids

#: Candidates compared per family (the first ones of its stream).
FIRST = 150


@pytest.fixture(scope="module")
def room_scene(qa_room_dirs):
    from spacedg.scene.io import load_scene
    from tests.room_qa import prepare_room

    folder = qa_room_dirs[0]
    return prepare_room(load_scene(folder), folder / "cache")


@pytest.mark.parametrize("family", selected_families(None), ids=lambda f: f.name)
def test_light_candidates_build_the_plain_records(room_scene, family) -> None:
    plain = list(itertools.islice(family.generate(room_scene, np.random.default_rng(3)), FIRST))
    with light_candidates():
        light = list(itertools.islice(family.generate(room_scene, np.random.default_rng(3)), FIRST))
    assert len(light) == len(plain) > 0
    built = []
    for item in light:
        if type(item) is not Candidate:
            built.append(item)
            continue
        record = item.build()
        assert item.sub_question_type == record.sub_question_type and item.views == record.views
        assert item.subject == record.geometry["selection"]["subject"]
        assert item.selection() == record.geometry["selection"]
        assert list(item.named) == named_ids(record)
        built.append(record)
    assert [r.to_dict() for r in built] == [r.to_dict() for r in plain]


def test_offer_builds_outside_the_block() -> None:
    from spacedg.plugins.candidates import offer
    from tests.qa_records import qa_record

    record = qa_record()
    assert offer("s", ("v",), "object:1", (1,), dict, lambda: record) is record
    with light_candidates():
        item = offer("s", ("v",), "object:1", (1,), dict, lambda: record)
    assert isinstance(item, Candidate) and item.build() is record and item.named == (1,)


def test_pooled_refuses_a_record_whose_selection_differs_from_its_offer() -> None:
    from spacedg.errors import PluginError
    from spacedg.qa.pooled import Pooled
    from tests.qa_records import qa_record

    class Declared:
        name = "demo_family"

        def check_record(self, record, scene_id=None) -> None:
            pass

    record = qa_record(geometry={"selection": {"subject": "object:1"}})
    good = Pooled(Candidate("s", ("v",), "object:1", (1,), lambda: {"subject": "object:1"}, lambda: record), Declared(), "scene")
    assert good.geometry == {"selection": {"subject": "object:1"}} and good.materialised() == record and good.id == record.id
    bad = Pooled(Candidate("s", ("v",), "object:2", (2,), lambda: {"subject": "object:2"}, lambda: record), Declared(), "scene")
    with pytest.raises(PluginError, match="selection entry"):
        bad.materialised()


@pytest.mark.parametrize("family", selected_families(None), ids=lambda f: f.name)
def test_a_gate_is_asked_with_what_is_then_offered(room_scene, family) -> None:
    """Every candidate a family yields was admitted just before with its own sub type, views,
    subject and named ids (so the pool's rules read the same fields either way), and a gate that
    admits everything changes no draw: the same candidates, building the same records."""
    from spacedg.plugins.candidates import gated

    asked: list[tuple] = []

    def admit_all(sub, views, subject, named) -> bool:
        asked.append((sub, tuple(views), subject, tuple(named)))
        return True

    with light_candidates():
        plain = list(itertools.islice(family.generate(room_scene, np.random.default_rng(3)), FIRST))
        gated_items, last_asked = [], []
        with gated(admit_all):
            for item in itertools.islice(family.generate(room_scene, np.random.default_rng(3)), FIRST):
                gated_items.append(item)
                last_asked.append(asked[-1] if asked else None)  # the gate's last question when the item came
    assert len(gated_items) == len(plain) > 0
    for item, same, question in zip(gated_items, plain, last_asked):
        if type(item) is not Candidate:
            assert item.to_dict() == same.to_dict()
            continue
        assert item[:4] == same[:4] and item.selection() == same.selection()
        assert item.build().to_dict() == same.build().to_dict()
        assert question == (item.sub_question_type, tuple(item.views), item.subject, tuple(item.named))


#: The modules whose ``build_mcq`` a family's per-candidate option draws go through.
_MCQ_MODULES = (
    "geometry", "compass_cache", "camera_object_relative_direction", "camera_rotation", "camera_translation", "object_size_comparison",
)


@pytest.mark.parametrize("family", [f for f in selected_families(None) if f.name in {
    "cross_view_cardinal_direction", "object_size_comparison", "camera_object_relative_direction", "object_proxy_cardinal_direction",
    "camera_rotation", "camera_translation",
}], ids=lambda f: f.name)
def test_refused_candidates_are_passed_over_without_draws(room_scene, family, monkeypatch) -> None:
    """A gate refusing every other subject: a refused subject is never offered, only
    :data:`PASSED_OVER` stands in for it; what is offered builds exactly; and under a gate that
    refuses everything no option is drawn (``build_mcq`` is never called), while one that admits
    everything draws them."""
    import importlib

    from spacedg.plugins.candidates import PASSED_OVER, gated

    calls = [0]
    for name in _MCQ_MODULES:
        module = importlib.import_module(f"spacedg.plugins.questions.{name}")
        plain_mcq = module.build_mcq

        def counted(*args, _plain=plain_mcq, **kwargs):
            calls[0] += 1
            return _plain(*args, **kwargs)

        monkeypatch.setattr(module, "build_mcq", counted)
    refused: set[str] = set()

    def every_other(sub, views, subject, named) -> bool:
        if subject in refused or zlib.crc32(subject.encode()) % 2:
            refused.add(subject)
            return False
        return True

    with light_candidates(), gated(every_other):
        items = list(itertools.islice(family.generate(room_scene, np.random.default_rng(5)), FIRST))
    offered = [item for item in items if item is not PASSED_OVER]
    assert offered and refused and len(offered) < len(items)
    for item in offered:
        assert item.subject not in refused
        record = item.build()
        assert item.selection() == record.geometry["selection"] and item.subject == record.geometry["selection"]["subject"]
    calls[0] = 0
    with light_candidates(), gated(lambda *args: False):
        items = list(itertools.islice(family.generate(room_scene, np.random.default_rng(5)), FIRST))
    assert items and all(item is PASSED_OVER for item in items) and calls[0] == 0
    with light_candidates(), gated(lambda *args: True):
        assert list(itertools.islice(family.generate(room_scene, np.random.default_rng(5)), 20)) and calls[0] > 0


def test_admission_is_the_gate_of_the_scan_it_is_taken_in() -> None:
    from spacedg.plugins.candidates import admission, gated

    outside = admission()
    assert outside("s", ("v",), "object:1", (1,))
    asked = []

    def gate(*candidate) -> bool:
        asked.append(candidate)
        return False

    with gated(gate):
        inside = admission()
        assert not inside("s", ("v",), "object:1", (1,)) and asked == [("s", ("v",), "object:1", (1,))]
    assert outside("s", ("v",), "object:2", (2,)) and len(asked) == 1


def test_admitted_is_true_outside_a_gate() -> None:
    from spacedg.plugins.candidates import admitted, gated

    assert admitted("s", ("v",), "object:1", (1,))
    with gated(lambda *args: False):
        assert not admitted("s", ("v",), "object:1", (1,))
    assert admitted("s", ("v",), "object:1", (1,))


class _GatedFamily:
    """A family whose stream asks the gate, as the built-in ones do: subjects ``s0 … s{n-1}``
    (each offered ``repeats`` times, on views ``v{k}``), drawing one number per admitted candidate."""

    name = "gated_demo"
    sub_question_types = ("only",)

    def __init__(self, subjects: int, repeats: int) -> None:
        self.subjects, self.repeats, self.asked, self.drawn = subjects, repeats, 0, 0

    def generate(self, scene, rng):
        from spacedg.plugins.candidates import PASSED_OVER, admitted, offer

        for r in range(self.repeats):
            for k in range(self.subjects):
                subject, views = f"s{k}", (f"v{r}",)
                self.asked += 1
                if not admitted(self.sub_question_types[k % len(self.sub_question_types)], views, subject, (k,)):
                    yield PASSED_OVER
                    continue
                self.drawn += 1
                rng.random()
                yield offer(self.sub_question_types[k % len(self.sub_question_types)], views, subject, (k,), lambda s=subject: {"subject": s}, lambda: None)

    def check_record(self, record, scene_id=None) -> None:
        pass


class _TwinOf3:
    def has_twin_ids(self, views, ids) -> bool:
        return 3 in ids  # object 3 always has a twin


def test_the_pool_gate_applies_the_pool_rules_before_a_candidate_is_made() -> None:
    """:func:`spacedg.qa.build._pool` with a gating family: at most ``ALTERNATES`` records per
    subject, at most ``want`` subjects, twins left out and counted, and refused candidates count
    as scanned (``max_scan`` bounds the candidates asked about, not only those made)."""
    from collections import Counter
    from types import SimpleNamespace

    from spacedg.qa.build import ALTERNATES, _pool
    from spacedg.qa.index import QABuildConfig

    scene = SimpleNamespace(id="demo")
    family = _GatedFamily(subjects=6, repeats=ALTERNATES + 3)
    twins: Counter[str] = Counter()
    pooled = _pool(family, scene, QABuildConfig(per_sub_type=1, pool_factor=10, max_scan=10_000), _TwinOf3(), twins)  # want 10
    per_subject = Counter(p.candidate.subject for p in pooled)
    assert set(per_subject) == {"s0", "s1", "s2", "s4", "s5"}  # s3 names a twin
    assert all(n == ALTERNATES for n in per_subject.values())
    assert family.drawn == len(pooled)  # nothing drawn for a refused candidate
    assert twins["gated_demo"] == ALTERNATES + 3  # every offer of s3
    full = _GatedFamily(subjects=6, repeats=ALTERNATES + 3)
    pooled = _pool(full, scene, QABuildConfig(per_sub_type=1, pool_factor=4, max_scan=10_000), _TwinOf3(), Counter())  # want 4
    assert [p.candidate.subject for p in pooled] == ["s0", "s1", "s2", "s4"] and full.asked == 6  # a fifth subject ends the scan
    small = _GatedFamily(subjects=6, repeats=ALTERNATES + 3)
    pooled = _pool(small, scene, QABuildConfig(per_sub_type=1, pool_factor=10, max_scan=10), _TwinOf3(), Counter())
    assert small.asked == 11 and len(pooled) == 8  # ten scanned, two of them refused (s3 twice), then the scan ends


def test_a_full_sub_type_refuses_new_subjects_while_another_fills() -> None:
    """Two sub types: eight "even" subjects come first, then five "odd" ones. With ``want`` 5,
    the sixth to eighth even subjects are passed over (the scan goes on: "odd" is not full), the
    odd ones fill their sub type, and the next new subject ends the scan."""
    from collections import Counter
    from types import SimpleNamespace

    from spacedg.plugins.candidates import PASSED_OVER, admitted, offer
    from spacedg.qa.build import _pool
    from spacedg.qa.index import QABuildConfig

    seen: list[str] = []

    class TwoSubTypes:
        name = "two_sub_types"
        sub_question_types = ("even", "odd")

        def generate(self, scene, rng):
            order = [("even", f"e{k}") for k in range(8)] + [("odd", f"o{k}") for k in range(6)]
            for sub, subject in order:
                seen.append(subject)
                if not admitted(sub, ("v",), subject, ()):
                    yield PASSED_OVER
                    continue
                yield offer(sub, ("v",), subject, (), lambda s=subject: {"subject": s}, lambda: None)

        def check_record(self, record, scene_id=None) -> None:
            pass

    class NoTwins:
        def has_twin_ids(self, views, ids) -> bool:
            return False

    pooled = _pool(TwoSubTypes(), SimpleNamespace(id="demo"), QABuildConfig(per_sub_type=1, pool_factor=5, max_scan=10_000), NoTwins(), Counter())
    assert [p.candidate.subject for p in pooled] == ["e0", "e1", "e2", "e3", "e4", "o0", "o1", "o2", "o3", "o4"]
    assert seen[-1] == "o5"  # asked, then the scan ended: every sub type had its five subjects


def test_passed_over_outside_the_pool_is_a_plugin_error(room_scene) -> None:
    """A third-party family that yields ``PASSED_OVER`` where no pool is gating (a plain
    ``generate``) gets one clear plugin error, not a stray marker among its records."""
    from spacedg.errors import PluginError
    from spacedg.plugins.candidates import PASSED_OVER
    from spacedg.plugins.question_family import QuestionFamily
    from spacedg.plugins.specs import AnswerType, TaskGroup

    def generate(scene, rng):
        yield PASSED_OVER

    family = QuestionFamily(
        name="passes_over", task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.YN},
        sub_question_types=("only",), num_views=(1,), needs=frozenset(), generate=generate,
    )
    with pytest.raises(PluginError, match="PassedOver"):
        list(family.generate(room_scene, np.random.default_rng(0)))


def test_offer_if_admitted_is_admitted_then_offer() -> None:
    from spacedg.plugins.candidates import PASSED_OVER, gated, offer_if_admitted

    built = object()
    args = ("s", ("v",), "object:1", (1,), dict, lambda: built)
    assert offer_if_admitted(*args) is built  # outside the index: the record
    asked = []
    with light_candidates(), gated(lambda *q: asked.append(q) or False):
        assert offer_if_admitted(*args) is PASSED_OVER
    with light_candidates(), gated(lambda *q: True):
        item = offer_if_admitted(*args)
    assert type(item) is Candidate and item[:4] == args[:4] and asked == [args[:4]]
