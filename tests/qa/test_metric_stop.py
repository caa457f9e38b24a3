"""A family whose answers are all metric stops its scan once the selection could take nothing
more (:meth:`spacedg.qa.build._PoolScan.pooled`): the same records as the full scan, fewer candidates read."""

from __future__ import annotations

from collections import Counter

import pytest

from spacedg.plugins.candidates import Candidate, offer
from spacedg.qa.build import _pool
from spacedg.qa.index import QABuildConfig, selected_families
from spacedg.qa.selection import select_records
from spacedg.qa.twins import TwinCheck
from spacedg.plugins.questions.view_sampling import VisibilityIndex


@pytest.fixture(scope="module")
def room_scene(qa_room_dirs):
    from spacedg.scene.io import load_scene
    from tests.room_qa import prepare_room

    folder = qa_room_dirs[0]
    return prepare_room(load_scene(folder), folder / "cache")


def _selected(scene, family, config, metric_stop):
    pool = _pool(family, scene, config, TwinCheck(VisibilityIndex(scene)), Counter(), metric_stop=metric_stop)
    chosen = select_records(pool, config.per_sub_type if config.mode == "bench" else config.per_sub_type * 4, mode=config.mode)
    return pool, [r.materialised().to_dict() for r in chosen]


@pytest.mark.parametrize("mode, per_sub_type", [("bench", 25), ("bench", 3), ("train", 25)])
@pytest.mark.parametrize("family", [f for f in selected_families(None) if f.name in {
    "inter_object_distance", "camera_object_distance_estimation", "object_bounding_size_estimation"}], ids=lambda f: f.name)
def test_the_stop_keeps_the_records_of_the_full_scan(room_scene, family, mode, per_sub_type) -> None:
    from spacedg.qa.modes import quota

    config = QABuildConfig(mode=mode, per_sub_type=per_sub_type)
    full_pool, full = _selected(room_scene, family, config, metric_stop=False)
    stopped_pool, stopped = _selected(room_scene, family, config, metric_stop=True)
    assert stopped == full and full
    assert [r.geometry["selection"] for r in stopped_pool] == [r.geometry["selection"] for r in full_pool[: len(stopped_pool)]]
    # the stop ran where every sub type found its quota of subjects
    if all(sum(r["sub_question_type"] == sub for r in full) >= quota(per_sub_type, mode) for sub in family.sub_question_types):
        assert len(stopped_pool) < len(full_pool)


def test_a_cell_or_a_record_without_an_entry_turns_the_stop_off(room_scene) -> None:
    """A metric-declared family that offers a balanced (cell) candidate, or a record without a
    selection entry, is scanned to the end (the selection reads the whole pool for those)."""
    from spacedg.plugins.question_family import FamilyFactory
    from spacedg.plugins.specs import AnswerType, TaskGroup

    def stream(kinds):
        def generate(scene, rng):
            for k in range(40):
                subject = f"object:{k}"
                entry = {"subject": subject}
                if k == 0 and kinds == "cell":  # a balanced candidate first
                    entry = {"subject": subject, "cell": "c", "role": "a", "roles": ["a", "b"]}
                elif k == 0 and kinds == "plain":  # an entry the selection does not read as one (no subject)
                    entry = {}
                yield offer("s", (next(iter(scene.views)),), subject, (), lambda e=entry: e, lambda: None)
        return generate

    for kinds, expected in (("metric", 2), ("cell", 40), ("plain", 40)):  # quota 2: the metric stream stops after its second subject
        family = FamilyFactory(stream(kinds), name=f"demo_{kinds}", task_group=TaskGroup.OBJECT_CENTRIC,
                               answer_types={AnswerType.NA}, sub_question_types=("s",), num_views=(1,), description="demo")()
        config = QABuildConfig(per_sub_type=2)
        pool = _pool(family, room_scene, config, TwinCheck(VisibilityIndex(room_scene)), Counter(), metric_stop=True)
        assert len(pool) == expected and all(type(p.candidate) is Candidate for p in pool)
