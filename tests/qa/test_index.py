"""Question index per scene (spacedg.qa.build, spacedg.qa.index), the judge hook and `spacedg qa build/stats`."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from tests.qa_scenes import CLEAR, build, camera, obj
from spacedg.cli import main
from spacedg.qa.build import build_scene_index
from spacedg.qa.index import QABuildConfig, index_paths, read_index
from spacedg.qa.judge import DescriptionJudge, parse_verdict
from spacedg.errors import FileFormatError, ParameterError


def test_build_reuse_and_rebuild(qa_room_dirs, tmp_path):
    room = tmp_path / "room"
    shutil.copytree(qa_room_dirs[0], room)
    config = QABuildConfig(seed=3, families=("object_counting", "camera_translation"), per_sub_type=5)
    first = build_scene_index(room, config, progress=False)
    assert not first.reused and first.records
    jsonl, meta = index_paths(first.scene_id, room, config.families)
    assert jsonl.name == f"{first.scene_id}.qa.camera_translation+object_counting.jsonl"
    assert not index_paths(first.scene_id, room)[0].exists()  # a selection never writes the full index
    assert first.path == jsonl and meta.is_file() and (room / "cache" / f"{first.scene_id}.visibility.npz").is_file()
    assert read_index(jsonl) == first.records
    subs = {}
    for r in first.records:
        subs[(r.question_type, r.sub_question_type)] = subs.get((r.question_type, r.sub_question_type), 0) + 1
    assert max(subs.values()) <= 5 and {q for q, _ in subs} == {"object_counting", "camera_translation"}
    second = build_scene_index(room, config, progress=False)
    assert second.reused and second.records == first.records
    forced = build_scene_index(room, config, progress=False, force=True)
    assert not forced.reused and [r.to_dict() for r in forced.records] == [r.to_dict() for r in first.records]
    other_seed = build_scene_index(room, QABuildConfig(seed=4, families=config.families, per_sub_type=5), progress=False)
    assert not other_seed.reused and other_seed.records != first.records
    # editing the scene (its scene.json) makes the index stale
    record = json.loads((room / "scene.json").read_text())
    record["metadata"]["note"] = "edited"
    (room / "scene.json").write_text(json.dumps(record))
    assert not build_scene_index(room, QABuildConfig(seed=4, families=config.families, per_sub_type=5), progress=False).reused


def test_corrupt_index_line_is_named(tmp_path):
    path = tmp_path / "x.qa.jsonl"
    path.write_text('{"id": "broken"\n')
    with pytest.raises(FileFormatError, match=r"x\.qa\.jsonl:1"):
        read_index(path)


def test_bad_config_and_unknown_family(qa_room_dirs, tmp_path):
    with pytest.raises(ParameterError, match="per_sub_type"):
        QABuildConfig(per_sub_type=0)
    with pytest.raises(LookupError, match="camera_translaton|did you mean"):
        build_scene_index(qa_room_dirs[0], QABuildConfig(families=("camera_translaton",)), out_dir=tmp_path, progress=False)


@pytest.mark.parametrize("reply, keep", [
    ("KEEP", True), ("keep.", True), ("Answer: KEEP", True), ("DROP", False), ("KEEP or DROP", False),
    ("", False), ("I think it is fine", False), (None, False), ("keeping", False),
])
def test_parse_verdict(reply, keep):
    assert parse_verdict(reply) is keep


def test_judge_drops_only_judged_ambiguous_references():
    views = {"a": camera((0, 0, 1.5))}
    insts = [obj(1, "chair", (2, 0, 0.4), description="red chair"), obj(2, "chair", (2, 1, 0.4), description="blue chair"),
             obj(3, "table", (3, 0, 0.4), description="oak table")]
    scene = build(insts, views, {"a": {1: CLEAR, 2: CLEAR, 3: CLEAR}})
    asked = []

    def judge(image, label, description):
        asked.append((image.shape, label, description))
        return "DROP" if description == "red chair" else "KEEP"

    dj = DescriptionJudge(scene, judge, image_for=lambda s, v: np.zeros((4, 4, 3), np.uint8))

    class R:  # only geometry["refs"] is read
        def __init__(self, refs):
            self.geometry = {"refs": refs}

    assert not dj.keep(R([{"id": 1, "view": "a"}]))
    assert dj.keep(R([{"id": 2, "view": "a"}]))
    assert dj.keep(R([{"id": 3, "view": "a"}]))  # no other table: never asked
    assert dj.keep(R([]))
    assert [a[2] for a in asked] == ["red chair", "blue chair"] and dj.calls == 2
    assert not dj.keep(R([{"id": 1, "view": "a"}])) and dj.calls == 2  # cached

    def broken(image, label, description):
        raise RuntimeError("model crashed")

    assert not DescriptionJudge(scene, broken, image_for=lambda s, v: np.zeros((4, 4, 3), np.uint8)).keep(R([{"id": 2, "view": "a"}]))


def test_cli_build_and_stats(qa_room_dirs, tmp_path, capsys):
    out = tmp_path / "qa"
    argv = ["qa", "build", str(qa_room_dirs[0]), str(qa_room_dirs[1]), "--out", str(out),
            "--families", "object_counting,object_existence_estimation", "--per-sub-type", "6", "--jobs", "1"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    # a family selection has its own index beside the (absent) full one
    assert "records in" in text and len(list(out.glob("*.qa.object_counting+object_existence_estimation.jsonl"))) == 2
    assert not list(out.glob("*.qa.jsonl"))
    assert main(argv) == 0 and "reused" in capsys.readouterr().out
    assert main(["qa", "stats", str(out)]) == 2 and "pass --families" in capsys.readouterr().err
    assert main(["qa", "stats", str(out), "--json", "--families", "object_existence_estimation,object_counting"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["scenes"] == 2 and report["records"] == sum(row["n"] for row in report["counts"])
    assert {row["question_type"] for row in report["counts"]} == {"object_counting", "object_existence_estimation"}
    assert report["blind_baseline"][-1]["question_type"] == "ALL"
    files = sorted(map(str, out.glob("*.jsonl")))
    assert report["repeats"][-1]["repeats"] == 0 and report["blind"]["rows"] and "ambiguities" in report
    assert main(["qa", "stats", *files]) == 0
    text = capsys.readouterr().out
    assert "Blind stress test" in text and "Repeats" in text and "Ambiguities" in text
    assert "Counting answers (bench)" in text and "Selection modes" in text
    # the dense train index goes beside the bench one; stats reports both modes
    assert main([*argv, "--mode", "train"]) == 0 and len(list(out.glob("*.qa-train.object_counting+object_existence_estimation.jsonl"))) == 2
    capsys.readouterr()
    assert main(["qa", "stats", str(out), "--json", "--no-blind", "--families", "object_counting,object_existence_estimation"]) == 0
    report = json.loads(capsys.readouterr().out)
    modes = {row["mode"]: row for row in report["modes"]}
    assert set(modes) == {"bench", "train"} and modes["train"]["records"] > modes["bench"]["records"] == report["records"]
    assert sum(report["count_answers"].values()) == sum(r["n"] for r in report["counts"] if r["question_type"] == "object_counting")
    assert main(["qa", "stats", str(tmp_path / "nothing")]) == 2
    assert "no such file" in capsys.readouterr().err
    # an unknown family is one error before the build starts: no table header, no index written
    assert main(["qa", "build", str(qa_room_dirs[0]), "--out", str(tmp_path / "typo"), "--families", "object_countin"]) == 2
    captured = capsys.readouterr()
    assert "unknown question family 'object_countin'" in captured.err and "records" not in captured.out
    assert not (tmp_path / "typo").exists() or not list((tmp_path / "typo").glob("*.jsonl"))


def test_judge_in_generation_drops_and_counts(qa_room_dirs, tmp_path):
    """A judge that answers DROP removes exactly the records naming an object whose image shows
    a same-label neighbour; one that answers KEEP changes nothing. Real renders feed the judge."""
    from spacedg.scene.io import load_scene
    from spacedg.qa.build import generate_records, prepare_scene
    from spacedg.plugins.questions.view_sampling import VisibilityIndex, same_label_neighbours

    config = QABuildConfig(seed=1, per_sub_type=6, families=("object_bounding_size_estimation", "inter_object_distance"))
    scene = prepare_scene(load_scene(qa_room_dirs[0]), tmp_path, config, progress=False)  # has visible same-label sets
    plain = generate_records(scene, config)
    shapes = set()

    def keep_all(image, label, description):
        shapes.add((image.shape, str(image.dtype)))
        return "KEEP"

    assert generate_records(scene, config, judge=keep_all) == plain
    dropped: dict[str, int] = {}
    strict = generate_records(scene, config, judge=lambda image, label, description: "DROP", dropped=dropped)
    index = VisibilityIndex(scene)
    for record in strict:
        for ref in record.geometry["refs"]:
            assert not same_label_neighbours(index, ref["view"], scene.instance(ref["id"]))
    assert sum(dropped.values()) > 0 and shapes == {((240, 320, 3), "uint8")}


def test_qa_preview_sheet_and_cli(qa_room_dirs, tmp_path, capsys):
    """`spacedg qa preview` draws one panel per picked question (real renders, boxes of named objects)."""
    import cv2

    from spacedg.scene.io import load_scene
    from spacedg.qa.preview import ascii_text, qa_sheet

    room = tmp_path / "room"
    shutil.copytree(qa_room_dirs[1], room)
    out = tmp_path / "qa.png"
    assert main(["qa", "preview", str(room), "--out", str(out)]) == 2  # preview reads the index, never builds it
    assert f"spacedg qa build {room}" in capsys.readouterr().err
    index = build_scene_index(room, progress=False)
    assert main(["qa", "preview", str(room), "--out", str(out), "--n", "3", "--families",
                 "inter_object_distance,object_counting", "--thumb-width", "96"]) == 0
    assert "3 questions" in capsys.readouterr().out
    image = cv2.imread(str(out))
    assert image is not None and image.shape[1] >= 2 * 96
    record = next(r for r in index.records if r.question_type == "inter_object_distance")
    scene = load_scene(room)
    sheet = qa_sheet(scene, [record], thumb_width=96, progress=False)
    bare = qa_sheet(scene, [dataclasses.replace(record, geometry={**record.geometry, "refs": []})], thumb_width=96, progress=False)
    drawn = np.any(sheet != bare, axis=2)
    assert sheet.dtype == np.uint8 and drawn.sum() > 20  # the boxes of the two named objects
    red, blue = sheet[drawn][:, 0].astype(int), sheet[drawn][:, 2].astype(int)
    assert np.mean(np.abs(red - blue) > 60) > 0.5  # drawn in red (object 1) and blue (object 2)
    assert ascii_text("15° – ×") == "15 deg - x"
    assert main(["qa", "preview", str(room), "--out", str(out), "--families", "no_such_type"]) == 2
    assert "no questions of type" in capsys.readouterr().err


def test_selection_names_and_paths(tmp_path):
    from spacedg.qa.index import MAX_SELECTION_CHARS, selection_name

    assert selection_name(()) == "" and index_paths("room", tmp_path) == (tmp_path / "room.qa.jsonl", tmp_path / "room.qa.meta.json")
    assert selection_name(["object_counting", "camera_rotation", "object_counting"]) == "camera_rotation+object_counting"
    assert index_paths("room", tmp_path, ("b", "a"))[1] == tmp_path / "room.qa.a+b.meta.json"
    long = [f"family_number_{k:02d}" for k in range(12)]
    name = selection_name(long)
    assert name.startswith("families-") and len(name) == len("families-") + 12 and name == selection_name(long[::-1])
    assert len("+".join(long)) > MAX_SELECTION_CHARS
    with pytest.raises(ParameterError, match="not a family name"):
        selection_name(["../escape"])
    assert QABuildConfig(families=("b", "a", "b")).families == ("a", "b")
    with pytest.raises(ParameterError, match="not one string"):
        QABuildConfig(families="object_counting")


def test_selection_never_replaces_the_full_index(qa_room_dirs, tmp_path):
    """Building a family selection leaves the full index (bytes and key) as it was; the selection's
    records are exactly that family's records in the full index (per-(scene, family) seeds)."""
    room = shutil.copytree(qa_room_dirs[2], tmp_path / "room", ignore=shutil.ignore_patterns("*.qa.*"))
    full = build_scene_index(room, QABuildConfig(per_sub_type=3), progress=False)
    before = [p.read_bytes() for p in index_paths(full.scene_id, room)]
    part = build_scene_index(room, QABuildConfig(per_sub_type=3, families=("camera_translation",)), progress=False, force=True)
    assert part.path == index_paths(full.scene_id, room, ("camera_translation",))[0] != full.path
    assert [p.read_bytes() for p in index_paths(full.scene_id, room)] == before
    assert build_scene_index(room, QABuildConfig(per_sub_type=3), progress=False).reused
    assert part.records and part.records == [r for r in full.records if r.question_type == "camera_translation"]
