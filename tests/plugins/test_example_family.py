"""The example question-family package ``tests/plugins/spacedg-nearest-object``, installed as a real
distribution (pip, its own target folder): listed by ``spacedg plugins``, built by ``qa build
--families`` into a selection index beside the full one, answers re-derived from each record's
``geometry`` block alone, and served by ``SpaceDGDataset(question_types=[...])`` from the full index.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from spacedg.cli import main
from spacedg.qa.build import prepare_scene
from spacedg.qa.index import QABuildConfig, index_is_current, index_paths, read_index
from spacedg.plugins import get_question_family, list_question_families
from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.questions.language import object_phrase
from spacedg.scene.io import load_scene
from tests.conftest import private_copies

SPACEDG_SCRIPT = Path(sys.executable).parent / "spacedg"
NAME = "nearest_object"
CONFIG = QABuildConfig(per_sub_type=4)


@pytest.fixture(scope="module")
def rooms(qa_room_dirs, tmp_path_factory) -> list[Path]:
    """Private copies of the four session rooms (with their visibility caches, without indexes)."""
    return private_copies(qa_room_dirs, tmp_path_factory.mktemp("family_rooms"))


def rederive(record) -> str:
    """The correct letter from the geometry block alone: the option whose box centre is nearest the camera."""
    g = record.geometry
    (view,) = record.views
    eye = np.asarray(g["cameras"][view], dtype=np.float64)[:3, 3]
    distances = [float(np.linalg.norm(np.asarray(o["center"]) - eye)) for o in g["objects"]]
    nearest = int(np.argmin(distances))
    assert sorted(distances)[1] - distances[nearest] >= g["min_margin_m"]
    assert np.allclose(distances, g["distances_m"])
    for option, o in zip(record.options, g["objects"]):
        assert option[3:] == object_phrase(o["label"], o["description"])
    assert [r["id"] for r in g["refs"]] == [o["id"] for o in g["objects"]] and {r["view"] for r in g["refs"]} == {view}
    assert all(v["class"] == "visible" for v in g["visibility"])
    return MCQ_LETTERS[nearest]


def test_listed_by_spacedg_plugins(family_plugin) -> None:
    result = subprocess.run([str(SPACEDG_SCRIPT), "plugins", "--json"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    plugin = next(p for p in json.loads(result.stdout)["plugins"] if p["name"] == NAME)
    assert (plugin["distribution"], plugin["version"], plugin["builtin"]) == ("spacedg-nearest-object", "0.1.0", False)
    (family,) = plugin["question_families"]
    assert (family["name"], family["task_group"], family["answer_types"], family["num_views"], family["sub_question_types"]) == (
        NAME, "camera_object", ["MCQ"], [1], ["closest_of_four"])
    text = subprocess.run([str(SPACEDG_SCRIPT), "plugins"], capture_output=True, text=True, timeout=120)
    assert "spacedg-nearest-object 0.1.0, third-party" in text.stdout


def test_generation_is_seeded_balanced_and_rederivable(family_plugin, rooms) -> None:
    family = get_question_family(NAME)
    assert family.origin.distribution == "spacedg-nearest-object" and NAME in [f.name for f in list_question_families()]
    scene = prepare_scene(load_scene(rooms[0]), rooms[0] / "cache", progress=False)
    records = list(family.generate(scene, np.random.default_rng(3)))
    assert records and records == list(family.generate(scene, np.random.default_rng(3)))
    assert len({r.id for r in records}) == len(records)
    letters = Counter(r.answer for r in records)
    assert max(letters.values()) - min(letters[k] for k in MCQ_LETTERS) <= 1, letters  # dealt from shuffled A-D blocks
    for record in records:
        assert rederive(record) == record.answer


def test_qa_build_families_writes_beside_the_full_index(family_plugin, qa_room_dirs, tmp_path, capsys) -> None:
    """`qa build --families` writes a selection index, validated records; the full index is never replaced."""
    rooms = private_copies(qa_room_dirs, tmp_path)
    argv = ["qa", "build", *map(str, rooms), "--families", NAME, "--per-sub-type", str(CONFIG.per_sub_type), "--jobs", "1"]
    assert main(argv) == 0
    assert f".qa.{NAME}.jsonl" in capsys.readouterr().out
    selection = {}
    for room in rooms:
        scene_id = load_scene(room).id
        path, meta = index_paths(scene_id, room, (NAME,))
        assert path.name == f"{scene_id}.qa.{NAME}.jsonl" and meta.is_file()
        assert not index_paths(scene_id, room)[0].exists()
        selection[scene_id] = read_index(path)  # every line re-validated as a QARecord
        for record in selection[scene_id]:
            get_question_family(NAME).check_record(record, scene_id)
            assert rederive(record) == record.answer
    assert sum(map(len, selection.values())) > 0
    assert main(["qa", "stats", str(tmp_path), "--families", NAME, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["counts"][0]["question_type"] == NAME

    # the full index (every family, the plugin's included), then the selection again: the full index stays
    assert main(["qa", "build", str(rooms[0]), "--per-sub-type", str(CONFIG.per_sub_type)]) == 0
    full, full_meta = index_paths(load_scene(rooms[0]).id, rooms[0])
    before = (full.read_bytes(), full_meta.read_bytes())
    assert main(argv[:2] + [str(rooms[0])] + argv[3:]) == 0
    assert "reused" in capsys.readouterr().out
    assert main(argv[:2] + [str(rooms[0])] + argv[3:] + ["--force"]) == 0
    assert (full.read_bytes(), full_meta.read_bytes()) == before and index_is_current(rooms[0], CONFIG)
    records = read_index(full)
    assert {r.question_type for r in records} > {NAME, "object_counting"}
    # per-(scene, family) seeds: the selection holds exactly that family's records of the full index
    assert [r for r in records if r.question_type == NAME] == selection[load_scene(rooms[0]).id]


def test_dataset_serves_the_family_from_the_full_index(family_plugin, rooms) -> None:
    from spacedg.data.dataset import SpaceDGDataset

    ds = SpaceDGDataset("train", scenes=rooms, question_types=[NAME], qa_config=CONFIG, image_size=(64, 48))
    assert ds.records and {r.question_type for r in ds.records} == {NAME}
    for room in rooms:  # the indexes the dataset read are the full ones, built in a child process that found the plugin
        full = read_index(index_paths(load_scene(room).id, room)[0])
        assert NAME in {r.question_type for r in full} and len({r.question_type for r in full}) > 1
    item = ds[0]
    record = next(r for r in ds.records if r.id == item["record_id"])
    assert item["images"].shape == (1, 3, 48, 64) and item["question_type"] == NAME and item["answer"] == record.answer
    assert item["options"] == list(record.options) and rederive(record) == record.answer
