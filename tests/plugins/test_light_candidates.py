"""Light candidates (:mod:`spacedg.plugins.candidates`) are the records the families yield
otherwise: same records, same order, same draws; a candidate's fields are its record's."""

from __future__ import annotations

import itertools

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
