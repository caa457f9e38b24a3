"""A family that declares ``metric_only`` stops its scan once the selection could take nothing more
(:meth:`spacedg.qa.build._PoolScan.pooled`): the same records as the full scan, fewer candidates read."""

from __future__ import annotations

from collections import Counter

import pytest

from spacedg.errors import PluginError
from spacedg.plugins.candidates import Candidate, offer
from spacedg.qa import build
from spacedg.qa.build import _pool
from spacedg.qa.index import QABuildConfig, selected_families
from spacedg.qa.modes import quota
from spacedg.qa.selection import select_records
from spacedg.qa.twins import TwinCheck
from spacedg.plugins.questions.view_sampling import VisibilityIndex

METRIC = ("inter_object_distance", "camera_object_distance_estimation", "object_bounding_size_estimation")


@pytest.fixture(scope="module")
def room_scene(qa_room_dirs):
    from spacedg.scene.io import load_scene
    from tests.room_qa import prepare_room

    folder = qa_room_dirs[0]
    return prepare_room(load_scene(folder), folder / "cache")


def _selected(scene, family, config, stop_early):
    pool = _pool(family, scene, config, TwinCheck(VisibilityIndex(scene)), Counter(), stop_early=stop_early)
    chosen = select_records(pool, quota(config.per_sub_type, config.mode), mode=config.mode)
    return pool, [r.materialised().to_dict() for r in chosen]


def test_the_built_in_metric_families_declare_it_and_no_other_does() -> None:
    assert {f.name for f in selected_families(None) if f.metric_only} == set(METRIC)


@pytest.mark.parametrize("mode, per_sub_type", [("bench", 25), ("bench", 3), ("train", 25)])
@pytest.mark.parametrize("family", [f for f in selected_families(None) if f.name in METRIC], ids=lambda f: f.name)
def test_the_stop_keeps_the_records_of_the_full_scan(room_scene, family, mode, per_sub_type) -> None:
    config = QABuildConfig(mode=mode, per_sub_type=per_sub_type)
    full_pool, full = _selected(room_scene, family, config, stop_early=False)
    stopped_pool, stopped = _selected(room_scene, family, config, stop_early=True)
    assert stopped == full and full
    assert [r.geometry["selection"] for r in stopped_pool] == [r.geometry["selection"] for r in full_pool[: len(stopped_pool)]]
    if all(sum(r["sub_question_type"] == sub for r in full) >= quota(per_sub_type, mode) for sub in family.sub_question_types):
        assert len(stopped_pool) < len(full_pool)  # every sub type found its quota: the stop ran


def test_the_stop_reads_fewer_candidates_where_the_quota_is_small(room_scene) -> None:
    family = next(f for f in selected_families(None) if f.name == "inter_object_distance")
    config = QABuildConfig(per_sub_type=3)
    full_pool, full = _selected(room_scene, family, config, stop_early=False)
    stopped_pool, stopped = _selected(room_scene, family, config, stop_early=True)
    assert stopped == full and len(full) == 3 and len(stopped_pool) < len(full_pool) // 2


def _demo_family(kinds: str, metric_only: bool = True):
    from spacedg.plugins.question_family import FamilyFactory
    from spacedg.plugins.specs import AnswerType, TaskGroup

    def generate(scene, rng):
        for k in range(40):
            subject = f"object:{k}"
            entry = {"subject": subject}
            if k == 5 and kinds == "cell":  # a balanced candidate before the quota is met
                entry = {"subject": subject, "cell": "c", "role": "a", "roles": ["a", "b"]}
            elif k == 5 and kinds == "plain":  # an entry the selection does not read as one (no subject)
                entry = {}
            sub = "t" if k == 5 and kinds == "undeclared" else "s"
            yield offer(sub, (next(iter(scene.views)),), subject, (), lambda e=entry: e, lambda: None)

    return FamilyFactory(generate, name=f"demo_{kinds}", task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.NA},
                         sub_question_types=("s",), num_views=(1,), description="demo", metric_only=metric_only)()


def test_a_declared_family_stops_and_one_that_breaks_the_declaration_is_refused(room_scene) -> None:
    config = QABuildConfig(per_sub_type=8)
    index = TwinCheck(VisibilityIndex(room_scene))
    pool = _pool(_demo_family("metric"), room_scene, config, index, Counter(), stop_early=True)
    assert len(pool) == 8 and all(type(p.candidate) is Candidate for p in pool)  # its quota of subjects, then the stop
    assert len(_pool(_demo_family("metric", metric_only=False), room_scene, config, index, Counter(), stop_early=True)) == 40
    assert len(_pool(_demo_family("metric"), room_scene, config, index, Counter(), stop_early=False)) == 40
    for kinds, what in (("cell", "balanced record"), ("plain", "without a selection entry"), ("undeclared", "undeclared sub type 't'")):
        for stop in (True, False):  # held to its promise with a judge too (no stop then)
            with pytest.raises(PluginError, match=f"declares metric_only.*{what}"):
                _pool(_demo_family(kinds), room_scene, config, index, Counter(), stop_early=stop)


@pytest.mark.parametrize("name", ["object_bounding_size_estimation", "object_proxy_cardinal_direction"])  # metric_only, plain_rounds
def test_a_judge_turns_the_stop_off(room_scene, monkeypatch, name) -> None:
    """The stops are exact only when every pooled record is accepted: with a judge the family is read to the end."""
    asked = []
    plain_pool = build._pool

    def spy(*args, **kwargs):
        asked.append(kwargs.get("stop_early"))
        return plain_pool(*args, **kwargs)

    class KeepAll:
        def keep(self, record) -> bool:
            return True

    monkeypatch.setattr(build, "_pool", spy)
    family = next(f for f in selected_families(None) if f.name == name)
    index = TwinCheck(VisibilityIndex(room_scene))
    build._family_records(family, room_scene, QABuildConfig(), None, None, None, index, Counter())
    build._family_records(family, room_scene, QABuildConfig(), KeepAll(), None, None, index, Counter())
    assert asked == [True, False]
