"""SpaceDGDataset (spacedg.data.dataset): splits, determinism across workers and processes,
degradation choices, errors, DistributedSampler, chat_collate, bad scenes, pickling.

Small rooms (``qa_room_dirs``: 30k Gaussians) rendered at 64×48, a few question families.
Everything that forks DataLoader workers runs in a fresh interpreter, so that what the main
process has (or has not) rendered before the fork is under the test's control.
"""

from __future__ import annotations

import hashlib
import json
import math
import pickle
import re
import shutil
import subprocess
import sys
import warnings
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DistributedSampler

from spacedg.data.chain import CLEAN
from spacedg.data.chat import chat_collate, format_question
from spacedg.data.public_format import public_fields
from spacedg.data.dataset import SpaceDGDataset
from spacedg.scene.io import load_scene
from spacedg.scene.store import BUILTIN_ROOMS_FOLDER, builtin_scene_dirs
from spacedg.data.chain import BENCH_DEGRADATIONS
from spacedg.qa.index import QABuildConfig, index_paths, read_index
from spacedg.errors import InvalidDataError, ParameterError, UnknownPluginError
from spacedg.eval.scoring import ANSWER_PROMPT, score
from tests.conftest import private_copies

SIZE = (64, 48)  # (width, height)
#: one-view COUNT, two-view MCQ (camera_rotation), two-view NA (inter_object_distance), SIZE_LIST
FAMILIES = ("camera_rotation", "inter_object_distance", "object_bounding_size_estimation", "object_counting")
CONFIG = QABuildConfig(seed=0, per_sub_type=2, families=FAMILIES)
MIX = ["haze", "low_res:3", "jpeg_compression", "defocus", "water_droplets", {"name": "low_light", "params": {"exposure": 0.05}}]
INDEX_FILES = shutil.ignore_patterns("*.qa.*", "cache")  # full and selection indexes
#: The train items the DataLoader and determinism tests render (of 32): over epochs 0 and 1 they
#: draw every entry of MIX and clean, at a fraction of the renders of the whole split.
MIX_QUESTIONS = 12


def make(rooms: list[Path], split: str = "train", degradations=None, **kwargs) -> SpaceDGDataset:
    kwargs.setdefault("image_size", SIZE)
    kwargs.setdefault("qa_config", CONFIG)
    return SpaceDGDataset(split, degradations, scenes=rooms, **kwargs)


def digest(item: dict) -> str:
    return hashlib.sha256(item["images"].numpy().tobytes()).hexdigest()


@pytest.fixture(scope="module")
def rooms(qa_room_dirs, tmp_path_factory) -> list[Path]:
    """Copies of the four session rooms (the dataset writes indexes into scene folders), indexed
    once; their visibility caches come along (``loader_run`` builds everything afresh)."""
    root = tmp_path_factory.mktemp("dataset_rooms")
    dirs = private_copies(qa_room_dirs, root)
    make(dirs)  # builds the four question indexes (in a separate interpreter)
    return dirs


@pytest.fixture(scope="module")
def splits(rooms) -> dict[str, SpaceDGDataset]:
    return {split: make(rooms, split) for split in ("train", "val", "bench")}


# ------------------------------------------------------------------ splits and records
def test_splits_disjoint_by_scene_and_cover_all(rooms, splits):
    all_ids = {load_scene(d).id for d in rooms}
    scenes = {split: set(ds.scene_dirs) for split, ds in splits.items()}
    assert all(scenes.values()), scenes
    assert not scenes["train"] & scenes["val"] and not scenes["train"] & scenes["bench"] and not scenes["val"] & scenes["bench"]
    assert scenes["train"] | scenes["val"] | scenes["bench"] == all_ids
    for split, ds in splits.items():
        assert ds.records and {r.scene_id for r in ds.records} <= scenes[split]
    # every question of every scene is in exactly one split
    total = sum(len(read_index(index_paths(load_scene(d).id, d, CONFIG.families)[0])) for d in rooms)
    assert sum(len(ds.records) for ds in splits.values()) == total


def test_records_are_the_index_records(rooms, splits):
    for ds in splits.values():
        expected = [
            r for d in rooms if load_scene(d).id in ds.scene_dirs for r in read_index(index_paths(load_scene(d).id, d, CONFIG.families)[0])
        ]
        assert ds.records == expected
        assert {r.question_type for r in ds.records} <= set(FAMILIES)
    assert any(len(r.views) == 2 for r in splits["train"].records) and any(len(r.views) == 1 for r in splits["train"].records)


@pytest.mark.parametrize("split", ["train", "val", "bench"])
def test_every_item_matches_its_index_record(splits, split):
    ds = splits[split]
    by_id = {r.id: r for r in ds.records}
    indices = range(len(ds)) if split != "bench" else range(0, len(ds), 11)  # bench: every 11th item (all offsets hit)
    for i in indices:
        item = ds[i]
        record = by_id[item["record_id"]]
        assert record is ds.plan(i).record
        assert item["question"] == record.question
        assert item["options"] == list(record.options)
        expected_answer = list(record.answer) if isinstance(record.answer, tuple) else record.answer
        assert item["answer"] == expected_answer and type(item["answer"]) is type(expected_answer)
        assert item["question_type"] == record.question_type
        assert item["sub_question_type"] == record.sub_question_type
        assert item["task_group"] == record.task_group.value
        assert item["answer_type"] == record.answer_type.value
        assert item["scene_id"] == record.scene_id and item["views"] == list(record.views)
        assert item["index"] == i
        images = item["images"]
        assert isinstance(images, torch.Tensor) and images.dtype == torch.uint8 and images.is_contiguous()
        assert tuple(images.shape) == (len(record.views), 3, SIZE[1], SIZE[0])
        assert set(item["stats"]) == {"render_ms", "linear_ms", "encode_ms", "display_ms"}


def test_out_of_range_index(splits):
    ds = splits["val"]
    with pytest.raises(IndexError):
        ds[len(ds)]
    with pytest.raises(IndexError):
        ds.plan(-1)


# ------------------------------------------------------------------ bench protocol
def test_bench_split_is_every_question_under_clean_and_nine(splits):
    ds = splits["bench"]
    assert [c.name for c in ds.chains] == list(BENCH_DEGRADATIONS)
    assert len(ds) == len(ds.records) * 10
    seen: dict[str, Counter] = defaultdict(Counter)
    for i in range(len(ds)):
        plan = ds.plan(i)
        record, name = plan.record, plan.degradation_type
        seen[record.id][name] += 1
        assert plan.chain.is_clean == (name == CLEAN) and plan.index == i
    assert set(seen) == {r.id for r in ds.records}
    for counts in seen.values():
        assert counts == Counter({CLEAN: 1, **{name: 1 for name in BENCH_DEGRADATIONS}})
    # the ten items of the first question: provenance of each degradation at the bench preset
    items = [ds[i] for i in range(10)]
    assert len({it["record_id"] for it in items}) == 1
    assert items[0]["degradation_type"] == CLEAN and items[0]["degradation"] == []
    for item in items[1:]:
        names = [step["name"] for step in item["degradation"]]
        assert names == [item["degradation_type"]] and item["degradation"][0]["preset"] == "bench"
        assert not torch.equal(item["images"], items[0]["images"]), item["degradation_type"]


# ------------------------------------------------------------------ determinism
def test_same_index_same_bytes_in_process(rooms):
    a = make(rooms, "train", MIX, clean_prob=0.3, max_questions=MIX_QUESTIONS)
    b = make(rooms, "train", MIX, clean_prob=0.3, max_questions=MIX_QUESTIONS, cache=0)  # no cache at all: every item rendered afresh
    n = len(a)
    forward = [digest(a[i]) for i in range(n)]
    backward = [digest(b[i]) for i in reversed(range(n))][::-1]
    assert forward == backward
    assert [digest(a[i]) for i in range(n)] == forward  # second pass: renders from a's cache
    whole = make(rooms, "train", MIX, clean_prob=0.3)  # plans only (no render): the whole train split
    other = make(rooms, "train", MIX, clean_prob=0.3, split_fractions=(0.1, 0.1))
    n = len(whole)
    assert [other.plan(i).chain.text for i in range(n)] == [whole.plan(i).chain.text for i in range(n)]


def test_splits_do_not_follow_the_sample_seed(rooms, splits):
    held_out = set(splits["val"].scene_dirs) | set(splits["bench"].scene_dirs)
    for seed in (1, 2, 3):
        assert not set(make(rooms, "train", qa_config=CONFIG, seed=seed).scene_dirs) & held_out, seed


LOADER_SCRIPT = r"""
import hashlib, json, sys
import torch
from numba.np.ufunc import parallel
from torch.utils.data import DataLoader
from spacedg.data.dataset import SpaceDGDataset
from spacedg.qa.index import QABuildConfig

args = json.loads(sys.argv[1])
config = QABuildConfig(**args["config"])
ds = SpaceDGDataset("train", args["degradations"], scenes=args["scenes"], image_size=tuple(args["size"]),
                    qa_config=config, clean_prob=args["clean_prob"], max_questions=args["max_questions"])
out = {"records": [r.id for r in ds.records], "len": len(ds),
       "numba_threads_started": bool(parallel._is_initialized), "cuda_initialized": torch.cuda.is_initialized()}

def table(loader):
    return {str(item["index"]): [item["degradation_type"], hashlib.sha256(item["images"].numpy().tobytes()).hexdigest()]
            for batch in loader for item in batch}

loader = DataLoader(ds, batch_size=2, num_workers=2, persistent_workers=True, collate_fn=lambda b: b)
for epoch in (0, 1):
    ds.set_epoch(epoch)
    out[f"workers2_epoch{epoch}"] = table(loader)
ds.set_epoch(0)
out["workers0_epoch0"] = table(DataLoader(ds, batch_size=2, num_workers=0, collate_fn=lambda b: b))
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def loader_run(rooms, tmp_path_factory) -> dict:
    """A fresh interpreter builds the same dataset from unindexed copies of the rooms (so it builds
    the indexes itself), then reads it with 2 persistent workers (epochs 0 and 1) and in-process."""
    root = tmp_path_factory.mktemp("loader_rooms")
    copies = [str(shutil.copytree(d, root / d.name, ignore=INDEX_FILES)) for d in rooms]
    args = {"scenes": copies, "config": CONFIG.to_dict(), "size": list(SIZE), "degradations": MIX, "clean_prob": 0.3,
            "max_questions": MIX_QUESTIONS}
    script = root / "loader_script.py"
    script.write_text(LOADER_SCRIPT)
    proc = subprocess.run([sys.executable, str(script), json.dumps(args)], capture_output=True, text=True, timeout=300,
                          cwd=root, check=False)
    assert proc.returncode == 0, proc.stderr[-4000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _in_process_table(ds: SpaceDGDataset, epoch: int) -> dict[str, list[str]]:
    ds.set_epoch(epoch)
    return {str(i): [ds.plan(i).degradation_type, digest(ds[i])] for i in range(len(ds))}


def test_same_bytes_across_worker_counts_and_processes(rooms, loader_run):
    ds = make(rooms, "train", MIX, clean_prob=0.3, max_questions=MIX_QUESTIONS)
    assert loader_run["records"] == [r.id for r in ds.records] and loader_run["len"] == len(ds)
    here = _in_process_table(ds, 0)
    assert set(here) == {str(i) for i in range(len(ds))}
    assert loader_run["workers0_epoch0"] == here
    assert loader_run["workers2_epoch0"] == here
    assert len({name for name, _ in here.values()}) >= 4  # a real mix of clean and degraded items
    assert "low_light" in {name for name, _ in here.values()}  # the mapping with explicit params, rendered in workers


def test_construction_starts_no_numba_threads_or_cuda(loader_run):
    # the dataset was built (indexes included) before the DataLoader forked its workers
    assert loader_run["numba_threads_started"] is False
    assert loader_run["cuda_initialized"] is False


def test_set_epoch_reaches_persistent_workers(rooms, loader_run):
    ds = make(rooms, "train", MIX, clean_prob=0.3, max_questions=MIX_QUESTIONS)
    assert loader_run["workers2_epoch1"] == _in_process_table(ds, 1)
    # over both epochs the workers rendered every entry of MIX and clean
    names = {name for epoch in (0, 1) for name, _ in loader_run[f"workers2_epoch{epoch}"].values()}
    assert names == {CLEAN, "haze", "low_res", "jpeg_compression", "defocus", "water_droplets", "low_light"}, names


PEEK_SCRIPT = r"""
import hashlib, json, sys
import numba
from torch.utils.data import DataLoader, get_worker_info
from spacedg.data.dataset import SpaceDGDataset
from spacedg.qa.index import QABuildConfig
from spacedg.render import threads

def serial_flag(_):
    sys.stdout.write(f"WORKER serial {threads.serial_mode()}\n")  # one write: the two workers' lines never interleave
    sys.stdout.flush()

if __name__ == "__main__":  # forkserver / spawn re-import this file in their workers
    args = json.loads(sys.argv[1])
    ds = SpaceDGDataset("val", scenes=args["scenes"], image_size=tuple(args["size"]), qa_config=QABuildConfig(**args["config"]))
    first = ds[0]  # a user looks at one sample first: the main process renders
    print("LAYER", numba.threading_layer(), "serial", threads.serial_mode())
    loader = DataLoader(ds, batch_size=2, num_workers=2, collate_fn=list, worker_init_fn=serial_flag)
    items = {item["index"]: hashlib.sha256(item["images"].numpy().tobytes()).hexdigest() for batch in loader for item in batch}
    print(json.dumps(items))
"""


def test_dataloader_after_an_in_process_sample(rooms, tmp_path):
    """``ds[0]`` then ``DataLoader(ds, num_workers=2)`` (the default fork context) works: workers
    forked after the main process started numba's OpenMP threads run spacedg's kernels serially,
    and their items are the bytes this process renders."""
    script = tmp_path / "peek_script.py"
    script.write_text(PEEK_SCRIPT)
    args = {"scenes": [str(d) for d in rooms], "config": CONFIG.to_dict(), "size": list(SIZE)}
    proc = subprocess.run([sys.executable, str(script), json.dumps(args)], capture_output=True, text=True, timeout=180,
                          check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.strip().splitlines()
    layer = next(line for line in lines if line.startswith("LAYER"))
    assert layer.endswith("serial False"), layer
    if layer.startswith("LAYER omp"):  # (a numba with TBB picks that fork-safe layer and needs no serial twins)
        assert lines.count("WORKER serial True") == 2, lines
    from_workers = {int(k): v for k, v in json.loads(lines[-1]).items()}
    ds = make(rooms, "val")
    assert from_workers == {i: digest(ds[i]) for i in range(len(ds))}  # bit-identical to this process's items


# ------------------------------------------------------------------ train / val choices
def test_clean_prob_one_is_all_clean(rooms):
    ds = make(rooms, "train", ["haze", "low_res:3"], clean_prob=1.0)
    assert len(ds) == len(ds.records)
    assert all(ds.plan(i).chain.is_clean and ds.plan(i).degradation_type == CLEAN for i in range(len(ds)))
    for i in range(0, len(ds), 5):
        item = ds[i]
        assert item["degradation_type"] == CLEAN and item["degradation"] == []
    # no degradations at all (the train default) is clean too
    default = make(rooms, "train")
    assert default.chains == [] and all(default.plan(i).degradation_type == CLEAN for i in range(len(default)))


def test_clean_prob_zero_uses_only_the_given_degradations(rooms):
    ds = make(rooms, "train", ["haze", "low_res:3"], clean_prob=0.0)
    assert [c.text for c in ds.chains] == ["haze:bench", "low_res:3"]
    names = [ds.plan(i).degradation_type for i in range(len(ds))]
    assert set(names) == {"haze", "low_res"}
    presets = {"haze": "bench", "low_res": "3"}
    for i in range(len(ds)):
        item = ds[i]
        assert [(s["name"], s["preset"]) for s in item["degradation"]] == [(names[i], presets[names[i]])]
        assert item["degradation_type"] == names[i]


def test_view_depths_are_measured_once_per_scene_and_read_back(rooms, monkeypatch):
    """A chain that reads the scene depth (haze) gets every view's depth from the scene folder's
    ``cache/<id>.view-depths.npz``, measured for the whole scene when the scene is first needed: the values
    view_depth measures, the same items (bytes and provenance) whether measured or read, nothing measured once
    the table is there; a stale or unreadable table is measured again and replaced; a folder that cannot be
    written keeps them in the process; a chain that reads no depth (JPEG) writes no table."""
    from spacedg.data import pipeline, view_depth_cpu, view_depths
    from spacedg.data.view_depths import ensure_view_depths, view_depths_path
    from spacedg.scene.derived_cache import write_npz_entry

    for folder in rooms:
        view_depths_path(load_scene(folder).id, folder).unlink(missing_ok=True)
    make(rooms, "train", ["jpeg_compression"], clean_prob=0.0)[0]
    assert not any(view_depths_path(load_scene(f).id, f).exists() for f in rooms)
    pipeline.clear_depth_caches()
    first = make(rooms, "train", ["haze"], clean_prob=0.0)
    assert not any(view_depths_path(load_scene(f).id, f).exists() for f in rooms)  # nothing before a scene is needed
    items = [first[i] for i in (0, len(first) - 1)]  # two scenes
    scene = first.scene(first.records[0].scene_id)
    folder = first.scene_dirs[scene.id]
    path = view_depths_path(scene.id, folder)
    assert path.exists() and path.parent.name == "cache"

    def from_file() -> dict:
        return {name: None if math.isnan(d) else float(d) for name, d in zip(sorted(scene.views), np.load(path)["depth"].tolist())}

    pipeline.clear_depth_caches()
    table = from_file()
    assert sorted(table) == sorted(scene.views) and any(d is not None for d in table.values())
    assert table == {name: pipeline.view_depth(scene, scene.camera(name)) for name in scene.views}

    def measured(*args, **kwargs):
        raise AssertionError("a view depth was measured although the scene folder holds them")

    pipeline.clear_depth_caches()
    monkeypatch.setattr(view_depth_cpu, "nearest_per_cell", measured)
    again = make(rooms, "train", ["haze"], clean_prob=0.0)
    for i, item in zip((0, len(again) - 1), items):
        repeat = again[i]
        assert digest(repeat) == digest(item) and repeat["degradation"] == item["degradation"]
    monkeypatch.undo()

    for broken in (lambda: write_npz_entry(path, "another scene's key", {"depth": np.zeros(len(scene.views))}), lambda: path.write_bytes(b"not an npz")):
        broken()
        pipeline.clear_depth_caches()
        ensure_view_depths(scene, folder)
        assert from_file() == table  # measured again and replaced

    def read_only(*args, **kwargs):
        raise PermissionError("read-only folder")

    path.unlink()
    pipeline.clear_depth_caches()
    monkeypatch.setattr(view_depths, "write_npz_entry", read_only)
    fallback = make(rooms, "train", ["haze"], clean_prob=0.0)
    assert digest(fallback[0]) == digest(items[0]) and fallback[0]["degradation"] == items[0]["degradation"]
    assert not path.exists() and pipeline.view_depths_known(fallback.scene(scene.id))  # kept in the process


def test_set_epoch_redraws_choices_deterministically(rooms):
    a = make(rooms, "train", MIX, clean_prob=0.3)
    b = make(rooms, "train", MIX, clean_prob=0.3)

    def plans(ds, epoch):
        ds.set_epoch(epoch)
        return [ds.plan(i).chain.text for i in range(len(ds))]

    e0, e1 = plans(a, 0), plans(a, 1)
    assert e0 != e1
    assert plans(b, 1) == e1 and plans(b, 0) == e0
    a.set_epoch(1)
    b.set_epoch(1)
    assert [digest(a[i]) for i in range(6)] == [digest(b[i]) for i in range(6)]
    a.set_epoch(0)
    assert plans(a, 0) == e0
    # the same chain in two epochs draws new parameters and noise (the sample seed includes the epoch)
    haze = make(rooms, "train", ["haze"], clean_prob=0.0)
    first = haze[0]
    haze.set_epoch(1)
    second = haze[0]
    assert first["degradation"][0]["params"] != second["degradation"][0]["params"]
    assert not torch.equal(first["images"], second["images"])


def test_val_split_is_one_item_per_question(splits, rooms):
    ds = make(rooms, "val", ["haze"], clean_prob=0.5)
    assert len(ds) == len(ds.records) == len(splits["val"].records)
    assert {ds.plan(i).degradation_type for i in range(len(ds))} <= {CLEAN, "haze"}


def test_severity_random_draws_a_level_per_item(rooms):
    ds = make(rooms, "train", ["haze", "low_res"], severity="random", clean_prob=0.0)
    assert [c.text for c in ds.chains] == ["haze", "low_res"]
    chains = [ds.plan(i).chain.text for i in range(len(ds))]
    assert all(re.fullmatch(r"(haze|low_res):[1-5]", c) for c in chains), chains
    assert len({c.split(":")[1] for c in chains}) >= 3
    assert [ds.plan(i).chain.text for i in range(len(ds))] == chains
    item = ds[0]
    assert item["degradation_type"] == chains[0].split(":")[0]
    assert item["degradation"][0]["preset"] == chains[0].split(":")[1]


def test_severity_level_applies_to_names_without_preset(rooms):
    ds = make(rooms, "train", ["haze", "jpeg_compression:5"], severity="2", clean_prob=0.0)
    assert [c.text for c in ds.chains] == ["haze:2", "jpeg_compression:5"]


def test_all_covers_the_nine_builtins(rooms):
    ds = make(rooms, "train", "all", clean_prob=0.0)
    assert set(BENCH_DEGRADATIONS) <= {c.name for c in ds.chains}
    bench = make(rooms, "bench", "all")
    assert len(bench) == len(bench.records) * (len(bench.chains) + 1)


def test_all_includes_a_third_party_degradation(rooms, third_party):
    ds = make(rooms, "bench", "all")
    names = [c.name for c in ds.chains]
    assert "vignetting" in names and set(BENCH_DEGRADATIONS) <= set(names)
    assert len(ds) == len(ds.records) * (len(names) + 1)
    k = names.index("vignetting") + 1  # offset of the vignetting item of each question
    item = ds[k]
    assert item["degradation_type"] == "vignetting" and [s["name"] for s in item["degradation"]] == ["vignetting"]
    assert not torch.equal(item["images"], ds[0]["images"])
    train = make(rooms, "train", ["vignetting"], clean_prob=0.0)
    assert {train.plan(i).degradation_type for i in range(len(train))} == {"vignetting"}


def test_mixtures_and_chains_are_accepted(rooms):
    ds = make(rooms, "bench", ["night_capture", "haze+low_res"])
    assert len(ds) == len(ds.records) * 3
    item = ds[1]
    assert item["degradation_type"] == "night_capture"
    assert sorted(s["name"] for s in item["degradation"]) == ["low_light", "low_res", "motion_blur"]
    item = ds[2]
    assert item["degradation_type"] == "haze+low_res"
    assert sorted(s["name"] for s in item["degradation"]) == ["haze", "low_res"]


def test_degradation_type_of_a_chain_with_a_preset(rooms):
    ds = make(rooms, "bench", ["haze:3+low_res"])
    assert ds.plan(1).degradation_type == "haze+low_res"


# ------------------------------------------------------------------ errors
@pytest.mark.parametrize("kwargs, match", [
    ({"split": "test"}, "split"),
    ({"severity": "6"}, "severity"),
    ({"severity": "high"}, "severity"),
    ({"clean_prob": 1.5}, "clean_prob"),
    ({"clean_prob": -0.1}, "clean_prob"),
    ({"clean_prob": math.nan}, "clean_prob"),
    ({"on_bad_scene": "ignore"}, "on_bad_scene"),
    ({"image_size": (0, 48)}, "image_size"),
    ({"degradations": ["haze", "haze"]}, "repeat"),
])
def test_bad_arguments_raise_parameter_error(rooms, kwargs, match):
    kwargs = dict(kwargs)
    split = kwargs.pop("split", "train")
    degradations = kwargs.pop("degradations", None)
    with pytest.raises(ParameterError, match=match):
        make(rooms, split, degradations, **kwargs)


def test_unknown_question_type_names_a_suggestion(rooms):
    with pytest.raises(UnknownPluginError, match=r"(?i)object_countin.*did you mean 'object_counting'"):
        make(rooms, "train", families=["object_countin"])
    ds = make(rooms, "train", families=["object_counting"])
    assert ds.records and {r.question_type for r in ds.records} == {"object_counting"}


@pytest.mark.parametrize("name, error, match", [
    ("hazee", UnknownPluginError, r"(?i)unknown degradation 'hazee'.*did you mean 'haze'"),
    ("haze:99", ParameterError, r"unknown preset '99'"),
    ("night_captur", UnknownPluginError, r"(?i)did you mean the mixture 'night_capture'"),
])
def test_unknown_degradation_is_one_clear_error(rooms, name, error, match):
    # at construction (the documented behaviour) or, at the latest, on the first item
    with pytest.raises(error, match=match):
        ds = make(rooms, "train", [name], clean_prob=0.0)
        ds[0]


@pytest.mark.parametrize("name", ["hazee", "haze:99"])
def test_unknown_degradation_fails_at_construction(rooms, name):
    with pytest.raises((UnknownPluginError, ParameterError)):
        make(rooms, "train", [name], clean_prob=0.0)


# ------------------------------------------------------------------ DistributedSampler
@pytest.mark.parametrize("split, shuffle", [("bench", False), ("train", False), ("train", True)])
def test_distributed_sampler_ranks_partition_the_dataset(rooms, split, shuffle):
    ds = make(rooms, split, MIX if split == "train" else None, clean_prob=0.3)
    ranks = []
    for rank in (0, 1):
        sampler = DistributedSampler(ds, num_replicas=2, rank=rank, shuffle=shuffle, seed=5)
        sampler.set_epoch(3)
        ranks.append(list(sampler))
    padding = (-len(ds)) % 2  # DistributedSampler repeats this many indices to even the ranks
    assert len(ranks[0]) == len(ranks[1]) == (len(ds) + padding) // 2
    assert set(ranks[0]) | set(ranks[1]) == set(range(len(ds)))
    assert len(set(ranks[0]) & set(ranks[1])) == padding
    if padding == 0:
        assert not set(ranks[0]) & set(ranks[1])
    # what each rank reads is what plan() says, whichever rank reads it
    i = ranks[1][0]
    item = ds[i]
    assert item["index"] == i and item["record_id"] == ds.plan(i).record.id and item["degradation_type"] == ds.plan(i).degradation_type


# ------------------------------------------------------------------ chat_collate
def _answer_payload(answer) -> str:
    if isinstance(answer, list):
        return "[" + ", ".join(f"{v:.2f}" for v in answer) + "]"
    return str(answer)


def test_chat_collate_builds_messages(splits):
    ds = splits["bench"]
    wanted = {}
    for i in range(0, len(ds), 10):  # the clean item of each question
        wanted.setdefault((ds.plan(i).record.answer_type.value, len(ds.plan(i).record.views)), i)
    assert {n for _, n in wanted} == {1, 2} and len({t for t, _ in wanted}) >= 3, wanted
    batch = [ds[i] for i in wanted.values()]
    out = chat_collate(batch)
    assert set(out) == {"messages", "images", "answers", "items"} and out["items"] == batch
    for item, conversation, images, answer in zip(batch, out["messages"], out["images"], out["answers"]):
        system, user, assistant = conversation
        assert system == {"role": "system", "content": [{"type": "text", "text": ANSWER_PROMPT}]}
        assert user["role"] == "user"
        views = len(item["views"])
        assert user["content"][:views] == [{"type": "image"}] * views
        assert user["content"][views:] == [{"type": "text", "text": format_question(item["question"], item["options"])}]
        if item["options"]:
            assert user["content"][-1]["text"].endswith("\n" + "\n".join(item["options"]))
        expected = f"<answer>{_answer_payload(item['answer'])}</answer>"
        assert answer == expected and assistant == {"role": "assistant", "content": [{"type": "text", "text": expected}]}
        assert len(images) == views
        for image, tensor in zip(images, item["images"]):
            assert isinstance(image, np.ndarray) and image.dtype == np.uint8 and image.shape == (SIZE[1], SIZE[0], 3)
            assert np.array_equal(image, tensor.permute(1, 2, 0).numpy())
        # the training target scores full marks with the SpaceDG scorer
        assert score(answer, ds.records[[r.id for r in ds.records].index(item["record_id"])]).score == pytest.approx(1.0)
    no_answer = chat_collate(batch, with_answer=False, system_prompt="short")
    assert all(len(c) == 2 and c[0]["content"][0]["text"] == "short" for c in no_answer["messages"])


def test_every_training_target_scores_full_marks(splits):
    """The assistant target of every record, in the bench's form (existence as lettered options),
    scores 1 against the row the bench exports for it."""
    for ds in splits.values():
        for record in ds.records:
            item = {"images": torch.zeros((len(record.views), 3, 2, 2), dtype=torch.uint8), "question": record.question,
                    "options": list(record.options), "views": list(record.views), "record_id": record.id,
                    "answer_type": record.answer_type.value, "question_type": record.question_type,
                    "sub_question_type": record.sub_question_type,
                    "answer": list(record.answer) if isinstance(record.answer, tuple) else record.answer}
            (answer,) = chat_collate([item])["answers"]
            row = public_fields(item)
            truth = {**row, "options": {line[0]: line[3:] for line in row["options"]}}
            assert score(answer, truth).score == pytest.approx(1.0), (record.answer_type, record.answer, answer)
            if record.question_type == "object_existence_estimation":
                assert row["answer_type"] == "MCQ" and answer in ("<answer>A</answer>", "<answer>B</answer>")


# ------------------------------------------------------------------ bad scenes
@pytest.fixture
def corrupted(rooms, splits, tmp_path):
    """Copies of the rooms (indexes included) with the bench scene's scene.json replaced by garbage."""
    dirs = [Path(shutil.copytree(d, tmp_path / d.name)) for d in rooms]
    (bad_id,) = splits["bench"].scene_dirs
    bad = next(d for d in dirs if d.name == bad_id)
    (bad / "scene.json").write_bytes(b"\x00garbage{{{ not json")
    return dirs, bad


def test_corrupted_scene_fails_naming_its_folder(corrupted):
    dirs, bad = corrupted
    with pytest.raises(InvalidDataError, match=re.escape(str(bad))) as info:
        make(dirs, "train")
    assert "scene.json" in str(info.value) and "on_bad_scene='skip'" in str(info.value)


def test_corrupted_scene_skipped_on_request(corrupted):
    dirs, bad = corrupted
    good_ids = {d.name for d in dirs if d != bad}
    seen = set()
    empty = []
    for split in ("train", "val", "bench"):
        with pytest.warns(UserWarning, match=re.escape(str(bad))):
            ds = make(dirs, split, on_bad_scene="skip")
        assert list(ds.skipped) == [str(bad)] and "scene.json" in ds.skipped[str(bad)]
        assert bad.name not in ds.scene_dirs
        if not ds.records:  # the skipped scene keeps its split slot (no other scene moves): that split may be empty
            empty.append(split)
            continue
        assert all(r.scene_id != bad.name for r in ds.records)
        item = ds[0]
        assert item["images"].shape[0] == len(item["views"])
        seen |= set(ds.scene_dirs)
    assert seen == good_ids and len(empty) <= 1


def test_skipping_a_scene_keeps_the_other_scenes_splits(corrupted, splits):
    dirs, _bad = corrupted
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        for split in ("train", "val"):
            assert set(make(dirs, split, on_bad_scene="skip").scene_dirs) == set(splits[split].scene_dirs)


# ------------------------------------------------------------------ pickling
class _Recorder(pickle.Pickler):
    def __init__(self, file) -> None:
        super().__init__(file, protocol=pickle.HIGHEST_PROTOCOL)
        self.types: set[str] = set()

    def reducer_override(self, obj):
        self.types.add(type(obj).__name__)
        return NotImplemented


def test_dataset_pickles_small_without_gaussians(rooms):
    import io

    ds = make(rooms, "bench")
    ds[0]
    ds[1]  # the cache now holds a scene and clean renders
    assert ds._scenes is not None and ds._scenes.bytes > 2_000_000
    buffer = io.BytesIO()
    recorder = _Recorder(buffer)
    recorder.dump(ds)
    assert len(buffer.getvalue()) < 2_000_000
    assert not recorder.types & {"Gaussians", "Scene", "Frame", "ByteLRU"}, recorder.types
    copy = pickle.loads(buffer.getvalue())
    assert copy._scenes is None and len(copy) == len(ds) and copy.records == ds.records
    assert torch.equal(copy[1]["images"], ds[1]["images"])


def test_default_scenes_are_the_builtin_rooms_made_on_first_use(tmp_path, monkeypatch, capfd):
    """Without ``scenes=``, the built-in rooms are generated into $SPACEDG_HOME (with a progress
    bar) and indexed on first use, then reused. (Visibility at a small size: the rooms are
    full-size, and indexing them at the default sizes was most of this test's time.)"""
    monkeypatch.setenv("SPACEDG_HOME", str(tmp_path))
    config = QABuildConfig(per_sub_type=1, families=("object_counting",), visibility_size=(40, 30), covisibility_size=(20, 15))
    ds = SpaceDGDataset("bench", builtin_rooms=3, qa_config=config, image_size=SIZE, degradations=["low_res"])
    assert "built-in rooms (first use)" in capfd.readouterr().err
    assert BUILTIN_ROOMS_FOLDER == "rooms-v2"  # rooms made before wall rows (``rooms``) are never reused
    assert sorted(p.name for p in (tmp_path / BUILTIN_ROOMS_FOLDER).iterdir()) == [".spacedg-rooms-version", "room-000000", "room-000001", "room-000002"]
    assert len(ds.scene_dirs) == 1 and len(ds) == 2 * len(ds.records) and ds[0]["images"].dtype == torch.uint8
    again = SpaceDGDataset("bench", builtin_rooms=3, qa_config=config, image_size=SIZE, degradations=["low_res"])
    assert "first use" not in capfd.readouterr().err and [r.id for r in again.records] == [r.id for r in ds.records]
    old = tmp_path / "old-rooms"  # rooms of an older generator (no version file) are refused, not reused
    (old / "room-000000").mkdir(parents=True)
    (old / "room-000000" / "scene.json").write_text("{}")
    with pytest.raises(InvalidDataError, match="generator version unknown"):
        builtin_scene_dirs(3, root=old)


# ------------------------------------------------------------------ device: who renders
def test_deferred_items_render_in_the_main_process(rooms) -> None:
    plain = make(rooms, "bench", ["haze", "low_res"])
    deferred = make(rooms, "bench", ["haze", "low_res"], defer_render=True)
    planned = [deferred[i] for i in range(3)]
    assert all("images" not in item and "degradation" not in item for item in planned)
    rendered = deferred.render_batch(planned)
    for i, item in enumerate(rendered):
        expected = plain[i]
        assert torch.equal(item["images"], expected["images"])
        assert item["degradation"] == expected["degradation"] and item["question"] == expected["question"]
    with pytest.raises(ParameterError, match="collate_fn=list"):
        deferred.render_batch(planned[0])


@pytest.fixture
def fake_cuda(monkeypatch: pytest.MonkeyPatch) -> None:
    """torch reports one CUDA device (construction checks the device; these tests never reach CUDA)."""
    monkeypatch.setattr(torch.version, "cuda", "12.8")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)


def test_device_dataset_refuses_to_render_in_a_worker(rooms, monkeypatch: pytest.MonkeyPatch, fake_cuda) -> None:
    import types

    import torch.utils.data

    dataset = make(rooms, "bench", ["haze"], device="cuda:0")  # construction never touches CUDA
    monkeypatch.setattr("spacedg.render.threads.set_render_threads", lambda n: n)  # (the test process keeps its threads)
    monkeypatch.setattr(torch.utils.data, "get_worker_info", lambda: types.SimpleNamespace(num_workers=2, id=0))
    with pytest.raises(ParameterError, match="num_workers=0.*defer_render=True"):
        dataset[0]
    deferred = make(rooms, "bench", ["haze"], device="cuda:0", defer_render=True)
    assert "question" in deferred[0]  # planning in a worker is fine


def test_export_fingerprint_records_device_degradations(rooms, fake_cuda) -> None:
    from spacedg.data.export import dataset_fingerprint

    cpu = dataset_fingerprint(make(rooms, "bench", ["jpeg_compression"]))
    assert dataset_fingerprint(make(rooms, "bench", ["jpeg_compression"], device="cpu")) == cpu  # a CPU device: the numpy path
    assert dataset_fingerprint(make(rooms, "bench", ["jpeg_compression"], device="cuda:0")) != cpu  # kornia's JPEG on the GPU


def test_worker_defaults_come_from_the_machine_and_set_worker_threads(rooms, monkeypatch):
    """``ds.workers`` / ``ds.render_threads`` follow :func:`loader_plan`; in a worker the first item
    sets numba's threads for the DataLoader's actual worker count (or the given count)."""
    import types

    import numba
    import torch.utils.data

    from spacedg.data.workers import loader_plan

    monkeypatch.delenv("SPACEDG_WORKERS", raising=False)
    monkeypatch.delenv("SPACEDG_RENDER_THREADS", raising=False)
    ds = make(rooms, "val")
    plan = loader_plan()
    assert (ds.workers, ds.render_threads) == (plan.workers, plan.render_threads)
    assert make(rooms, "val", workers=3, render_threads=1).workers == 3
    before = numba.get_num_threads()
    seen = []
    monkeypatch.setattr("spacedg.render.threads.set_render_threads", lambda n: seen.append(n) or n)
    monkeypatch.setattr(torch.utils.data, "get_worker_info", lambda: types.SimpleNamespace(num_workers=1, id=0))
    ds._set_worker_threads()
    given = make(rooms, "val", render_threads=1)
    given._set_worker_threads()
    assert seen == [loader_plan(workers=1).render_threads, 1]
    assert numba.get_num_threads() == before  # (the setter was replaced: the test process keeps its threads)


# ------------------------------------------------------------------ chains as objects, end to end
def _full(name: str, seed: int = 3) -> dict:
    from spacedg.plugins.registry import get_degradation

    return get_degradation(name).sample_params("bench", np.random.default_rng(seed))


#: Every chain form over every built-in: explicit params (all nine; haze with one parameter, the
#: README's headline call), name:preset, a mapping without params, a tuple, a DegradationChoice,
#: a Chain object, mixtures, a ``+`` chain and a list.
EVERY_FORM = [
    {"name": "haze", "params": {"density": 3.5}},
    *({"name": n, "params": _full(n)} for n in BENCH_DEGRADATIONS if n != "haze"),
    "water_droplets:3", {"name": "low_light", "preset": "2"}, ("defocus", "4"),
    "night_capture", "hazy_long_range", "compressed_portrait",
    "haze:3+low_res", ["motion_blur:1", {"name": "jpeg_compression", "params": {"quality": 30}}],
    {"name": "low_light", "params": {"per_pixel": 1}},  # the rest from the preset, the pitch at the output size
]


def test_headline_mapping_with_explicit_params_renders(rooms) -> None:
    """The README's headline call: a mapping with explicit params (failed on every item before chains were objects)."""
    ds = SpaceDGDataset("train", scenes=rooms, degradations=[{"name": "haze", "params": {"density": 3.5}}],
                        clean_prob=0.0, image_size=SIZE, qa_config=CONFIG)
    item = ds[0]
    (step,) = item["degradation"]
    assert step["name"] == "haze" and step["params"]["density"] == 3.5 and step["preset"] == "bench"
    assert item["degradation_type"] == "haze" and item["images"].shape[-2:] == (SIZE[1], SIZE[0])
    assert ds.provenance(0) == item["degradation"]


def test_parameters_that_erase_the_view_warn_once_per_scene_and_deliver_the_item(rooms) -> None:
    """Haze of density 100 and airlight 1 (within its hard limits) turns every view white: each item is
    delivered as asked, and one ErasedViewWarning per scene names the parameters (spacedg.data.erased_views),
    though the scaled depth_ref differs between the items."""
    import warnings

    from spacedg.data import erased_views
    from spacedg.errors import ErasedViewWarning

    erased_views._REPORTED.clear()  # this process may have reported haze before
    erase = {"name": "haze", "params": {"density": 100.0, "airlight": 1.0}}
    ds = SpaceDGDataset("train", scenes=rooms, degradations=[erase], clean_prob=0.0, image_size=SIZE, qa_config=CONFIG)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        firsts: dict[str, list[int]] = {}
        for i in range(len(ds)):
            firsts.setdefault(ds.plan(i).record.scene_id, []).append(i)
        items = [ds[i] for indices in firsts.values() for i in indices[:2]]  # two items of each train scene
    assert all(bool((item["images"] == 1.0).all()) or bool((item["images"] == 255).all()) for item in items)
    scenes = {item["scene_id"] for item in items}
    messages = [str(w.message) for w in caught if issubclass(w.category, ErasedViewWarning)]
    assert len(scenes) >= 2 and len(messages) == len(scenes) and all("haze {density: 100, airlight: 1" in m for m in messages)
    assert {m.split(" of scene ")[1].split(" ")[0] for m in messages} == scenes


def test_every_chain_form_survives_workers_provenance_and_replay(rooms) -> None:
    """Each chain form over every built-in: planned in forked DataLoader workers (from a pickled
    dataset), the worker's plan rendered by the pipeline, its provenance equal to ``provenance(i)``,
    and replaying the provenance gives the same bytes. (Rendering inside workers, a mapping with
    explicit params included, is ``test_same_bytes_across_worker_counts_and_processes``: ``MIX``.)"""
    from torch.utils.data import DataLoader

    from spacedg.data.chain import Chain
    from spacedg.data.pipeline import ItemPlan, replay

    ds = make(rooms, "bench", EVERY_FORM, max_questions=1)
    assert len(ds) == len(EVERY_FORM) + 1 and all(isinstance(c, Chain) for c in ds.chains)
    assert {n for c in ds.chains for n in c.name.split("+")} >= set(BENCH_DEGRADATIONS)
    deferred = pickle.loads(pickle.dumps(make(rooms, "bench", EVERY_FORM, max_questions=1, defer_render=True)))
    assert deferred.chains == ds.chains
    planned = [item for batch in DataLoader(deferred, batch_size=4, num_workers=2, collate_fn=list) for item in batch]
    assert [item["plan"] for item in planned] == [ds.plan(i) for i in range(len(ds))]
    assert all(isinstance(item["plan"], ItemPlan) for item in planned)
    there = deferred.render_batch(planned)
    scene = load_scene(ds.scene_dirs[there[0]["scene_id"]])
    for i, b in enumerate(there):
        a, plan = ds[i], ds.plan(i)
        assert set(a) == set(b) and a["index"] == b["index"] == i and a["degradation_type"] == plan.degradation_type
        assert torch.equal(a["images"], b["images"]) and a["degradation"] == b["degradation"] == ds.provenance(i)
        assert {step["name"] for step in a["degradation"]} == {c.name for c in plan.chain.choices()}
        replayed = replay(scene, a["views"], a["degradation"], ds.options)
        assert np.array_equal(replayed.images, a["images"].permute(0, 2, 3, 1).numpy()), plan.chain.text
        assert Chain.parse(plan.chain.text) == plan.chain
    assert there[1]["degradation"][0]["params"]["density"] == 3.5
    (sensor,) = there[-1]["degradation"]
    assert sensor["name"] == "low_light" and sensor["params"]["per_pixel"] == 1 and sensor["params"]["pitch"] < 1.0


def test_an_item_is_planned_once_and_its_chain_never_parsed_again(rooms, monkeypatch: pytest.MonkeyPatch) -> None:
    from spacedg.data import chain as chain_module

    ds = make(rooms, "train", ["haze:2+low_res", {"name": "defocus", "params": {"aperture": 2.0}}], clean_prob=0.0)
    plans, texts = [], []
    real_plan, real_text = SpaceDGDataset.plan, chain_module._item_from_text
    monkeypatch.setattr(SpaceDGDataset, "plan", lambda self, index: plans.append(index) or real_plan(self, index))
    monkeypatch.setattr(chain_module, "_item_from_text", lambda text: texts.append(text) or real_text(text))
    for i in range(3):
        ds[i]
    assert plans == [0, 1, 2] and texts == []
