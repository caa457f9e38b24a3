"""The SFT configs: each default lives once, in YAML; the instantiated data config builds the
datasets the app built before; bad keys and degradation names fail early with spacedg's errors."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
import yaml

import spacedg.sft
from spacedg.data.chain import BENCH_DEGRADATIONS
from spacedg.data.chat import item_images
from spacedg.data.dataset import SpaceDGDataset
from spacedg.errors import ParameterError, UnknownPluginError
from spacedg.sft import app
from spacedg.sft.config import build
from spacedg.sft.data import ChatJsonlDataset
from spacedg.sft.model import ModelOptions
from spacedg.sft.sources import DataOptions, ValOptions
from spacedg.data.public_format import public_fields
from tests.sft.configs import ROOT, compose_sft

CONF = ROOT / "conf"
SFT = Path(spacedg.sft.__file__).parent


def _yaml(path: Path) -> dict:
    return yaml.safe_load(path.read_text())


def _group_keys() -> set[str]:
    """Every key of the model, data and data.val groups."""
    config = compose_sft()
    return {k for node in (config.model, config.data, config.data.val) for k in node if not k.startswith("_")}


def _python_defaults(keys: set[str], folder: Path = SFT) -> list[str]:
    """Where the modules of ``folder`` give one of ``keys`` a default: a parameter or dataclass
    field with a default, or ``.get("key", default)`` / ``.setdefault("key", ...)``."""
    found = []
    for path in sorted(folder.glob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                args = node.args
                positional = args.posonlyargs + args.args
                with_default = positional[len(positional) - len(args.defaults):] if args.defaults else []
                with_default += [a for a, d in zip(args.kwonlyargs, args.kw_defaults) if d is not None]
                found += [f"{path.name}:{node.lineno} {node.name}({a.arg}=...)" for a in with_default if a.arg in keys]
            elif isinstance(node, ast.ClassDef):
                found += [f"{path.name}:{item.lineno} {node.name}.{item.target.id} = ..." for item in node.body
                          if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name)
                          and item.value is not None and item.target.id in keys]
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in ("get", "setdefault")
                  and len(node.args) == 2 and isinstance(node.args[0], ast.Constant) and node.args[0].value in keys):
                found.append(f"{path.name}:{node.lineno} .{node.func.attr}({node.args[0].value!r}, ...)")
    return found


def test_no_config_key_has_a_python_default() -> None:
    keys = _group_keys()
    assert {"clean_prob", "seed", "builtin_rooms", "max_length", "lora_r", "max_new_tokens"} <= keys
    assert _python_defaults(keys) == []


def test_the_detector_finds_python_defaults(tmp_path) -> None:
    """The scan above would see a default reintroduced in any of its three forms."""
    (tmp_path / "bad.py").write_text(
        "from dataclasses import dataclass\n"
        "def f(x, *, clean_prob=0.1): ...\n"
        "@dataclass\nclass C:\n    seed: int = 0\n"
        "def g(d): return d.get('builtin_rooms', 16)\n"
    )
    assert len(_python_defaults({"clean_prob", "seed", "builtin_rooms"}, tmp_path)) == 3


def test_composing_tiny_yields_the_yaml_values() -> None:
    online = _yaml(CONF / "data" / "online.yaml")
    config = compose_sft("+experiment=tiny")
    assert config.data.clean_prob == online["clean_prob"] == 0.1
    assert config.data.val.clean_prob == online["val"]["clean_prob"]
    data = build(config.data, "data")
    assert isinstance(data, DataOptions) and isinstance(data.val, ValOptions)
    assert data.clean_prob == online["clean_prob"] and data.seed == online["seed"]
    # the experiment's own values win over the group's
    tiny = _yaml(CONF / "experiment" / "tiny.yaml")
    assert data.builtin_rooms == tiny["data"]["builtin_rooms"] and data.image_size == tiny["data"]["image_size"]
    model = build(config.model, "model")
    assert isinstance(model, ModelOptions)
    assert model.lora_r == _yaml(CONF / "model" / "tiny.yaml")["lora_r"]
    assert model.freeze_vision is _yaml(CONF / "model" / "base.yaml")["freeze_vision"]


def _repeats(values: dict, defaults: dict, where: str) -> list[str]:
    """Keys of ``values`` that set what ``defaults`` already sets, to the same value."""
    out = []
    for key, value in values.items():
        if isinstance(value, dict) and isinstance(defaults.get(key), dict):
            out += _repeats(value, defaults[key], f"{where}.{key}")
        elif key != "defaults" and key in defaults and defaults[key] == value:
            out.append(f"{where}.{key}")
    return out


def test_configs_override_only_what_differs() -> None:
    base = _yaml(CONF / "model" / "base.yaml")
    for path in sorted((CONF / "model").glob("*.yaml")):
        if path.name != "base.yaml":
            assert _yaml(path)["defaults"][0] == "base"
            assert _repeats(_yaml(path), base, path.stem) == []
    groups = {"data": _yaml(CONF / "data" / "online.yaml"), "train": _yaml(CONF / "train" / "default.yaml")}
    for path in sorted((CONF / "experiment").glob("*.yaml")):
        assert _repeats(_yaml(path), groups, path.stem) == []


# ------------------------------------------------------------------ the instantiated data config


def _same(built: SpaceDGDataset, expected: SpaceDGDataset, indices: list[int]) -> None:
    assert len(built) == len(expected) > 0
    for name in ("split", "chains", "clean_prob", "severity", "seed", "options"):
        assert getattr(built, name) == getattr(expected, name), name
    assert [built.plan(i) for i in range(len(built))] == [expected.plan(i) for i in range(len(expected))]
    for i in indices:
        a, b = built[i], expected[i]
        assert a["degradation"] == b["degradation"] and a["question"] == b["question"]
        assert np.array_equal(a["images"].numpy(), b["images"].numpy())


def test_instantiated_data_builds_the_datasets_of_before(rooms) -> None:
    """The arguments the app passed to SpaceDGDataset before the configs were instantiated
    (``+experiment=tiny``: the nine at a random severity, clean with probability 0.1, 64×48)."""
    data = build(compose_sft("+experiment=tiny", f"data.scenes=[{rooms}]", "data.max_questions=12",
                             "data.val.samples=3").data, "data")
    common = {"scenes": [str(rooms)], "question_types": None, "severity": "random", "clean_prob": 0.1,
              "image_size": (64, 48), "seed": 0, "builtin_rooms": 3}
    train = data.train_data().dataset
    expected = SpaceDGDataset("train", list(BENCH_DEGRADATIONS), max_questions=12, **common)
    degraded = next(i for i in range(len(train)) if not train.plan(i).chain.is_clean)
    _same(train, expected, [degraded])
    val = data.val_dataset()
    _same(val, SpaceDGDataset("val", list(BENCH_DEGRADATIONS), max_questions=None, **common), [])
    chosen = [val[int(i)] for i in sorted(np.random.default_rng(0).permutation(len(val))[:3])]  # the app's spread
    items = data.val_items()
    # asked and scored in the bench's form (existence as lettered options)
    assert [item["truth"]["answer"] for item in items] == [public_fields(item)["answer"] for item in chosen]
    assert [item["degradation_type"] for item in items] == [item["degradation_type"] for item in chosen]
    assert all(np.array_equal(a, b) for item, old in zip(items, chosen) for a, b in zip(item["images"], item_images(old)))
    # on two processes each renders its share: every other item of the spread, in index order
    shares = [data.val_items(rank, 2) for rank in range(2)]
    for share, expected_share in zip(shares, (items[0::2], items[1::2])):
        assert [item["truth"] for item in share] == [item["truth"] for item in expected_share]
        assert all(np.array_equal(a, b) for x, y in zip(share, expected_share) for a, b in zip(x["images"], y["images"]))
    with pytest.raises(ParameterError, match="rank"):
        data.val_items(2, 2)


def test_jsonl_source_still_evaluates_on_the_val_split(rooms, tmp_path) -> None:
    line = '{"messages": [{"role": "user", "content": "Is it? <image>"}, {"role": "assistant", "content": "yes"}], "images": ["a.png"]}\n'
    (tmp_path / "train.jsonl").write_text(line)
    overrides = ["+experiment=tiny", "data.source=jsonl", f"data.jsonl={tmp_path / 'train.jsonl'}", f"data.scenes=[{rooms}]"]
    data = build(compose_sft(*overrides).data, "data")
    assert isinstance(data.train_data(), ChatJsonlDataset)
    val = data.val_dataset()  # the JSONL trains; evaluation renders the val split of data.scenes, as with online data
    online = build(compose_sft("+experiment=tiny", f"data.scenes=[{rooms}]").data, "data").val_dataset()
    _same(val, online, [0])
    assert data.val_description().startswith("8 items of the val split")
    off = build(compose_sft(*overrides, "data.val.samples=0").data, "data")
    assert off.val_dataset() is None and off.val_items() == [] and off.val_description().startswith("none")


def test_a_chain_with_parameters_comes_through_the_config_as_the_dataset_takes_it() -> None:
    """``data.degradations`` as mappings (``{name, params}``), alone or in a chain, reach the dataset as plain
    lists and dicts, parsed to the same chains as the Python form (``per_pixel`` of the sensor: docs/degradations.md)."""
    from spacedg.data.chain import Chain

    python_form = [{"name": "low_light", "params": {"per_pixel": 1}}, [{"name": "over_exposure", "params": {"per_pixel": 1}}, "jpeg_compression"]]
    data = build(compose_sft(
        "+experiment=tiny",
        "data.degradations=[{name: low_light, params: {per_pixel: 1}}, [{name: over_exposure, params: {per_pixel: 1}}, jpeg_compression]]",
    ).data, "data")
    assert data.degradations == python_form
    assert [Chain.parse(c) for c in data.degradations] == [Chain.parse(c) for c in python_form]
    assert Chain.parse(data.degradations[0]).items[0].params == {"per_pixel": 1}


# ------------------------------------------------------------------ errors


@pytest.mark.parametrize(("override", "error", "message"), [
    ("+data.colour=red", ParameterError, r"data: unknown key 'colour'; the known keys are source, jsonl, scenes, .*val"),
    ("+data.val.colour=red", ParameterError, r"data\.val: unknown key 'colour'; the known keys are samples, "),
    ("+model.colour=red", ParameterError, r"model: unknown key 'colour'; the known keys are path, dtype, "),
    ("~model.lora_r", ParameterError, r"model: key 'lora_r' is missing"),
    ("model=base", ParameterError, r"model\.path is not set \(\?\?\?\)"),
    ("model.dtype=float64x", ParameterError, r"unknown dtype"),  # the target's own error, not Hydra's wrapper
    ("data.source=disk", ParameterError, r"data\.source must be online or jsonl"),
    ("data.severity=7", ParameterError, r"data\.severity must be one of"),
    ("data.val.batch_size=0", ParameterError, r"data\.val\.batch_size must be an integer >= 1"),
    ("data.degradations=[hazee]", UnknownPluginError, r"data\.degradations: .*hazee.*haze"),
    ("data.degradations=[haze+haze]", ParameterError, r"data\.degradations: .*appears twice"),
    ("data.val.degradations=[haze:9]", ParameterError, r"data\.val\.degradations: .*9"),
    ("data.degradations=[{name: low_light, params: {per_pixl: 1}}]", ParameterError, r"data\.degradations: .*per_pixl.*Did you mean 'per_pixel'"),
    ("data.degradations=[{name: low_light, params: {per_pixel: 0.5}}]", ParameterError, r"data\.degradations: .*per_pixel.*integer"),
])
def test_bad_configs_fail_before_any_model_or_index(override, error, message, tmp_path, monkeypatch) -> None:
    def untouchable(*args, **kwargs):
        raise AssertionError("built something before the config was checked")

    monkeypatch.setattr(app, "prepare_model", untouchable)
    monkeypatch.setattr("spacedg.data.dataset.ensure_indexes", untouchable)
    monkeypatch.setattr(app, "save_tiny_vlm", untouchable)
    with pytest.raises(error, match=message):
        app.run(compose_sft("+experiment=tiny", f"output_dir={tmp_path}", override))


def test_an_empty_val_split_fails_before_training_with_what_to_do() -> None:
    """The app builds the val split at start-up (its items render later, at the first evaluation): a split
    without questions stops the run there, saying how to train without evaluation."""
    from types import SimpleNamespace

    data = SimpleNamespace(val_dataset=lambda: [], scenes_description=lambda: "3 built-in rooms")
    with pytest.raises(ParameterError, match=r"val split of 3 built-in rooms holds no questions.*data.val.samples=0"):
        app._val_share(data, 0, 1)
    assert app._val_share(SimpleNamespace(val_dataset=lambda: None), 0, 1) is None  # data.val.samples=0
