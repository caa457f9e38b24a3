"""All eleven families together on synthetic rooms: registration, coverage, determinism, invariance."""

from __future__ import annotations

import math

import pytest

from tests.qa_scenes import random_rigid
from tests.room_qa import ROOM_CONFIG
from spacedg.qa.build import generate_records, prepare_scene
from spacedg.qa.index import QABuildConfig
from spacedg.plugins import list_question_families
from spacedg.plugins.specs import AnswerType

ELEVEN = {
    "camera_translation", "camera_rotation", "camera_object_distance_estimation", "camera_object_relative_direction",
    "cross_view_cardinal_direction", "inter_object_distance", "object_proxy_cardinal_direction", "object_size_comparison",
    "object_bounding_size_estimation", "object_existence_estimation", "object_counting",
}
#: Sub types the issue names; each must appear on the four test rooms.
NAMED_SUB_TYPES = {
    ("camera_translation", "main_dir"), ("camera_translation", "distance_exact"), ("camera_translation", "distance_threshold"),
    ("camera_object_distance_estimation", "bbox_center_distance"), ("camera_object_relative_direction", "bbox_center_direction"),
    ("camera_object_relative_direction", "relpos_A_facing_B"), ("object_size_comparison", "longest_side_compare"),
    ("object_size_comparison", "top_height_compare"),
}
CONFIG = ROOM_CONFIG  # seed 7, 15 per sub type


@pytest.fixture(scope="module")
def prepared(room_records):
    """The four session rooms, prepared once per session (shared with test_recompute.py)."""
    return [scene for scene, _ in room_records]


@pytest.fixture(scope="module")
def records_by_scene(room_records):
    """Their records at CONFIG, generated once per session (shared with test_recompute.py)."""
    return {scene.id: records for scene, records in room_records}


def test_eleven_families_registered():
    assert {f.name for f in list_question_families()} >= ELEVEN


def test_every_family_and_named_sub_type_appears(records_by_scene):
    every = [r for rs in records_by_scene.values() for r in rs]
    assert {r.question_type for r in every} >= ELEVEN
    assert {(r.question_type, r.sub_question_type) for r in every} >= NAMED_SUB_TYPES
    rotation = {r.sub_question_type.rsplit("_", 1)[1] for r in every if r.question_type == "camera_rotation"}
    assert rotation == {"single", "dual"}
    assert {r.sub_question_type for r in every if r.question_type == "camera_object_distance_estimation"} >= {"single_view", "bbox_center_distance"}


def test_deterministic(prepared, records_by_scene):
    scene = prepared[1]
    again = generate_records(scene, CONFIG)
    assert [r.to_dict() for r in again] == [r.to_dict() for r in records_by_scene[scene.id]]


def _comparable(record):
    answer = record.answer
    if record.answer_type is AnswerType.NA:
        answer = round(float(answer), 2)
    elif record.answer_type is AnswerType.SIZE_LIST:
        answer = tuple(round(float(v), 1) for v in answer)
    return (record.id, record.question, record.options, answer)


@pytest.mark.parametrize("seed", [0, 1])
def test_answers_invariant_under_rigid_motion_of_the_scene(prepared, records_by_scene, seed):
    """Moving and turning the whole scene (any up) changes no question, option or answer.

    Two random rigid motions on two rooms: motion ``seed`` moves room ``seed`` (each generation
    of a room's records costs seconds, so not every motion moves every room)."""
    for scene in prepared[seed:seed + 1]:
        moved = scene.transformed(*random_rigid(seed))
        assert not all(math.isclose(a, b) for a, b in zip(moved.up, scene.up))
        original = [_comparable(r) for r in records_by_scene[scene.id]]
        assert [_comparable(r) for r in generate_records(moved, CONFIG)] == original


def test_scorer_routes_every_generated_record_and_accepts_its_answer(records_by_scene):
    """The scorer's SpaceDG routing agrees with each record's answer type, and the true answer,
    written as a model would, scores 1; a wrong letter scores 0."""
    from spacedg.eval import route, score

    for records in records_by_scene.values():
        for r in records:
            assert route(r.question_type, r.sub_question_type) is r.answer_type, (r.question_type, r.sub_question_type)
            if r.answer_type is AnswerType.SIZE_LIST:
                text = "[" + ", ".join(f"{v:.2f}" for v in r.answer) + "]"
            else:
                text = str(r.answer)
            assert score(f"Thinking... <answer>{text}</answer>", r).score == 1.0, (r.id, text)
            if r.answer_type is AnswerType.MCQ:
                wrong = next(k for k in "ABCD" if k != r.answer)
                assert score(f"<answer>{wrong}</answer>", r).score == 0.0


def test_answer_balance_and_blind_baseline(records_by_scene):
    """Correct letter uniform over A–D within ±4 points, yes/no 50 ± 4, and a blind model that
    always gives the most frequent answer of the sub type (learnt on the other rooms) is no
    better than chance + 5 points."""
    from spacedg.qa.stats import answer_balance, blind_baseline

    every = [r for rs in records_by_scene.values() for r in rs]
    balance = answer_balance(every)
    assert balance["mcq_n"] >= 200 and balance["yn_n"] >= 50
    assert all(abs(share - 25.0) <= 4.0 for share in balance["letters"].values()), balance
    assert balance["mcq3_n"] > 0 and all(abs(share - 100 / 3) <= 6.0 for share in balance["letters3"].values()), balance  # size comparisons
    assert abs(balance["yes_pct"] - 50.0) <= 4.0, balance
    overall = blind_baseline(records_by_scene)[-1]
    assert overall["question_type"] == "ALL"
    assert overall["letter_prior"] <= overall["chance"] + 5.0, overall


def test_questions_about_a_real_splat_object(shared_splats):
    """A real .splat object (the shared teapot) placed in a room becomes an instance that questions
    name, measure and locate like the procedural furniture; sizes are its box's."""
    from spacedg.scene.synthetic import CaptureConfig, ExternalObject, RoomConfig, generate_room

    teapot = ExternalObject.from_splat(shared_splats / "teapot" / "teapot_10k.splat", size_m=0.35)
    room = generate_room(5, RoomConfig(gaussians=30_000, capture=CaptureConfig(320, 240, 24, 32), external=(teapot,), row_probability=0.0))
    config = QABuildConfig(seed=0, per_sub_type=40)
    scene = prepare_scene(room, None, config, progress=False)
    ids = {inst.id for inst in scene.instances if inst.label == "teapot"}
    assert ids
    records = generate_records(scene, config)
    naming = [r for r in records if any(ref["id"] in ids for ref in r.geometry.get("refs", []))]
    assert len({r.question_type for r in naming}) >= 3
    for r in naming:
        if r.question_type == "object_bounding_size_estimation":
            box = scene.instance(r.geometry["object"]["id"]).box
            assert list(r.answer) == [round(v, 2) for v in sorted(box.extents)]
            assert max(r.answer) == pytest.approx(0.35, abs=0.011)
