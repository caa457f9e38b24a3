"""Bad arguments fail at the call: every public entry point of the online side checks its
arguments up front and raises a SpaceDGError naming the argument, what it got and what it accepts.

Dataset arguments are checked before any scene is read: the scene folder given here does not exist,
so an argument that slipped through would end in an InvalidDataError about the folder instead.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
import torch

from spacedg.data.chat import chat_collate, chat_messages
from spacedg.data.dataset import SpaceDGDataset
from spacedg.data.export import export_bench
from spacedg.data.pipeline import ItemPlan, PipelineOptions, degrade, degrade_image, degrade_plan, degrade_variants, replay
from spacedg.data.workers import loader_plan
from spacedg.devices import resolve_device
from spacedg.errors import InvalidDataError, ParameterError, SpaceDGError, UnknownPluginError
from spacedg.scene.store import ByteLRU, assign_splits, scene_dirs_of

NOWHERE = ["/nonexistent/spacedg-scenes"]


@pytest.fixture
def no_cuda(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)


@pytest.fixture
def one_gpu(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)


DATASET_CASES = [
    ({"split": "test"}, r"split must be one of \['train', 'val', 'bench'\], got 'test'"),
    ({"split": None}, "split must be one of"),
    ({"split_fractions": (1, 0, 0)}, r"split_fractions must be \(val, bench\).*got \(1, 0, 0\)"),
    ({"split_fractions": (0.6, 0.6)}, r"split_fractions \(val, bench\) must sum to at most 1"),
    ({"split_fractions": (-0.1, 0.1)}, r"split_fractions val must be a number in \[0, 1\], got -0.1"),
    ({"split_fractions": "0.1,0.1"}, r"split_fractions must be \(val, bench\)"),
    ({"split_fractions": (float("nan"), 0.1)}, "split_fractions val"),
    ({"image_size": (0, 48)}, r"image_size width must be an integer >= 1, got 0"),
    ({"image_size": (64.5, 48)}, r"image_size width must be an integer"),
    ({"image_size": 64}, r"image_size must be \(width, height\)"),
    ({"image_size": "64x48"}, r"image_size must be \(width, height\)"),
    ({"image_size": (64, 48, 3)}, r"image_size must be \(width, height\)"),
    ({"image_size": (100_000, 100_000)}, "image_size"),
    ({"degradations": 3.5}, "degradations must be a chain"),
    ({"degradations": ["haze", "haze"]}, "repeat a chain"),
    ({"degradations": [{"name": "haze", "params": {"density": "thick"}}]}, "must be a finite number"),
    ({"degradations": "haze(density=1"}, "unbalanced"),
    ({"degradations": [{"name": "haze", "params": {"density": 1e9}}]}, "outside its hard limits"),
    ({"families": "object_counting"}, r"families must be a list of names"),
    ({"families": []}, "families must be a non-empty list"),
    ({"families": [3]}, "families must be a non-empty list of non-empty strings"),
    ({"families": ["a"], "question_types": ["a"]}, "give families= only"),
    ({"severity": "6"}, "severity must be one of"),
    ({"clean_prob": 1.5}, r"clean_prob must be a number in \[0, 1\], got 1.5"),
    ({"clean_prob": "0.5"}, "clean_prob must be a number"),
    ({"clean_prob": True}, "clean_prob must be a number"),
    ({"seed": 1.5}, "seed must be an integer, got 1.5"),
    ({"seed": "7"}, "seed must be an integer"),
    ({"split_seed": None}, "split_seed must be an integer"),
    ({"cache": -1}, r"cache \(bytes\) must be an integer >= 0, got -1"),
    ({"qa_config": {"seed": 0}}, "qa_config must be a QABuildConfig"),
    ({"on_bad_scene": "ignore"}, "on_bad_scene must be one of"),
    ({"backend": "vulkan"}, "backend must be one of"),
    ({"device": "gpu"}, "device must be a torch device.*got 'gpu'"),
    ({"device": 0}, "device must be a torch device"),
    ({"builtin_rooms": 2, "scenes": None}, "builtin_rooms must be an integer >= 3, got 2"),
    ({"max_questions": 0}, "max_questions must be an integer >= 1, got 0"),
    ({"defer_render": "yes"}, "defer_render must be True or False"),
    ({"workers": -1}, "workers must be an integer >= 0, got -1"),
    ({"render_threads": 0}, "render_threads must be an integer >= 1, got 0"),
    ({"scenes": []}, "scenes must be a scene folder or a non-empty list"),
    ({"scenes": [3]}, "scenes must be a scene folder"),
]


@pytest.mark.parametrize(("kwargs", "match"), DATASET_CASES, ids=[next(iter(k)) + f"-{i}" for i, (k, _) in enumerate(DATASET_CASES)])
def test_dataset_bad_argument_fails_at_the_call(kwargs: dict, match: str) -> None:
    kwargs = {"scenes": NOWHERE, **kwargs}
    split = kwargs.pop("split", "train")
    with pytest.raises(ParameterError, match=match) as caught:
        SpaceDGDataset(split, **kwargs)
    assert "SpaceDGDataset" in str(caught.value) or "degradation" in str(caught.value)


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"families": ["object_countin"]}, UnknownPluginError, "(?i)did you mean 'object_counting'"),
    ({"degradations": ["hazee"]}, UnknownPluginError, "(?i)did you mean 'haze'"),
    ({"degradations": ["haze:99"]}, ParameterError, "unknown preset '99'"),
])
def test_dataset_unknown_names_fail_at_the_call(kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        SpaceDGDataset("train", scenes=NOWHERE, **kwargs)


def test_dataset_checks_arguments_before_reading_scenes() -> None:
    with pytest.raises(InvalidDataError, match="no such scene folder"):  # every argument fine: the folder is next
        SpaceDGDataset("train", [{"name": "haze", "params": {"density": 3.5}}], scenes=NOWHERE, families=["object_counting"])


def test_question_types_is_a_deprecated_name_of_families() -> None:
    with pytest.warns(DeprecationWarning, match="use families="), pytest.raises(InvalidDataError):
        SpaceDGDataset("train", scenes=NOWHERE, question_types=["object_counting"])
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        with pytest.raises(InvalidDataError):
            SpaceDGDataset("train", scenes=NOWHERE, families=["object_counting"])


@pytest.mark.parametrize(("device", "match"), [
    ("cuda", r"asks for CUDA, but this torch has no usable CUDA device"),
    ("cuda:0", "asks for CUDA"),
])
def test_cuda_without_cuda_fails_at_the_call(no_cuda, device: str, match: str) -> None:
    with pytest.raises(ParameterError, match=match):
        SpaceDGDataset("train", scenes=NOWHERE, device=device)
    with pytest.raises(ParameterError, match=match):
        PipelineOptions(device=device)


def test_cuda_index_beyond_the_machine_fails(one_gpu) -> None:
    with pytest.raises(ParameterError, match=r"'cuda:7': this machine has 1 CUDA device\(s\)"):
        SpaceDGDataset("train", scenes=NOWHERE, device="cuda:7")
    assert resolve_device("cuda:0") == torch.device("cuda:0") and resolve_device(None) is None
    assert resolve_device(" cpu ") == torch.device("cpu")


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"motion": "quick"}, "PipelineOptions.motion must be one of"),
    ({"degrade_on": "gpu"}, "PipelineOptions.degrade_on must be one of"),
    ({"backend": "opengl"}, "PipelineOptions.backend must be one of"),
    ({"default_preset": 3}, "PipelineOptions.default_preset must be a preset name"),
    ({"mixture_preset": ""}, "PipelineOptions.mixture_preset must be a preset name"),
    ({"settings": {"near": 0.1}}, "PipelineOptions.settings must be a RasterSettings"),
    ({"device": "tpu:x"}, "PipelineOptions.device must be a torch device"),
    ({"image_size": (64, -1)}, "PipelineOptions.image_size height must be an integer >= 1"),
])
def test_pipeline_options_bad_argument(kwargs: dict, match: str) -> None:
    with pytest.raises(ParameterError, match=match):
        PipelineOptions(**kwargs)


@pytest.mark.parametrize(("call", "match"), [
    (lambda: degrade(None, [], "haze"), "degrade: views must be a view name or a list of view names"),
    (lambda: degrade(None, [3], "haze"), "degrade: views must be"),
    (lambda: degrade(None, ["v"], "haze", seed=1.5), "degrade: seed must be an integer, got 1.5"),
    (lambda: degrade(None, ["v"], "haze", options={"motion": "fast"}), "options must be a PipelineOptions"),
    (lambda: degrade_variants(None, ["v"], "haze"), "degrade_variants: chains must be a list of chains"),
    (lambda: degrade_variants(None, ["v"], ["haze"], progress="yes"), "progress must be True or False"),
    (lambda: degrade_plan(None, ("rec", "haze", 0)), "degrade_plan: plan must be an ItemPlan"),
    (lambda: replay(None, ["v"], {"name": "haze"}), "replay: provenance must be a list"),
    (lambda: replay(None, ["v"], [{"name": "haze", "params": {}}]), "a provenance entry is a mapping"),
    (lambda: degrade_image(__import__("numpy").zeros((4, 4, 3), "uint8"), "low_res", seed="1"), "degrade_image: seed"),
    (lambda: degrade_image(__import__("numpy").zeros((4, 4, 3), "uint8"), "low_res", default_preset=None), "default_preset"),
])
def test_pipeline_bad_argument_fails_before_rendering(call, match: str) -> None:
    with pytest.raises(ParameterError, match=match):
        call()


@pytest.mark.parametrize(("call", "match"), [
    (lambda: chat_messages("q", -1), "chat_messages: n_images must be an integer >= 0, got -1"),
    (lambda: chat_messages(None, 1), "chat_messages: question must be a string"),
    (lambda: chat_messages("q", 1, answer=3), "chat_messages: answer must be a string"),
    (lambda: chat_collate({"question": "q"}), "chat_collate: batch must be a list of dataset items"),
    (lambda: chat_collate([], with_answer="no"), "with_answer must be True or False"),
    (lambda: loader_plan(cores=0), "loader_plan: cores must be an integer >= 1, got 0"),
    (lambda: loader_plan(workers=-1), "loader_plan: workers must be an integer >= 0"),
    (lambda: loader_plan(render_threads=1.5), "loader_plan: render_threads must be an integer"),
    (lambda: loader_plan(processes="2"), "loader_plan: processes must be an integer"),
    (lambda: assign_splits(["a", "b", "c"], (1, 0, 0)), r"assign_splits: fractions must be \(val, bench\)"),
    (lambda: assign_splits("abc"), "scene_ids must be a list of scene id strings"),
    (lambda: assign_splits(["a"], seed="x"), "assign_splits: seed must be an integer"),
    (lambda: scene_dirs_of("rooms"), "scene_dirs_of: paths must be a list of folder paths"),
    (lambda: ByteLRU(-1, len), "ByteLRU: max_bytes must be an integer >= 0"),
    (lambda: ByteLRU(10, 3), "ByteLRU: size_of must be a function"),
    (lambda: export_bench("dataset", "out"), "export_bench: dataset must be a SpaceDGDataset"),
])
def test_other_entry_points_fail_at_the_call(call, match: str) -> None:
    with pytest.raises(ParameterError, match=match):
        call()


def test_export_bench_checks_its_own_arguments(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    dataset = SpaceDGDataset.__new__(SpaceDGDataset)  # an instance without scenes: only the type is looked at
    for kwargs, match in [
        ({"out_dir": None}, "out_dir must be a folder path"),
        ({"shard": (2, 2)}, r"shard i must be an integer in \[0, 1\], got 2"),
        ({"shard": "0/2"}, r"shard must be \(i, n\)"),
        ({"shard": (0, 0)}, "shard n must be an integer >= 1"),
        ({"progress": None}, "progress must be True or False"),
    ]:
        with pytest.raises(ParameterError, match=match):
            export_bench(dataset, **{"out_dir": tmp_path, **kwargs})
    assert issubclass(ParameterError, SpaceDGError) and ItemPlan.__dataclass_params__.frozen
