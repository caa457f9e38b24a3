"""SFT recipe (spacedg.sft) with a real tiny VLM on CPU: labels, overfitting, resume, the Hydra
app from an installed wheel, exported JSONL data and config errors (the configs themselves:
test_config.py; the torchrun launches: test_distributed.py).

Losses are deterministic on this CPU for a fixed seed; runs use the four small session rooms.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from transformers import Trainer

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.sft.app import run
from spacedg.sft.collator import IGNORE_INDEX, SFTCollator
from spacedg.sft.config import build
from spacedg.sft.data import BudgetedDataset, token_lengths
from spacedg.sft.model import prepare_model
from spacedg.sft.trainer import SFTTrainer
from spacedg.vlm import load_vlm
from tests.sft.configs import FAST, ROOT, compose_sft, model_options


def _config(rooms: Path, out: Path, *overrides: str):
    return compose_sft("+experiment=tiny", f"data.scenes=[{rooms}]", f"output_dir={out}", *FAST, *overrides)


def _data(rooms: Path):
    """8 training samples of the rooms at 64×48: haze or low_res at a random severity, clean with probability 0.3."""
    config = _config(rooms, Path("unused"), "data.degradations=[haze,low_res]", "data.clean_prob=0.3", "data.max_questions=8")
    return build(config.data, "data").train_data()


def test_supervised_tokens_are_exactly_the_answer(rooms) -> None:
    model, processor = prepare_model(model_options())
    samples = [_data(rooms)[i] for i in range(4)]
    batch = SFTCollator(processor, 4096)(samples)
    for row, sample in enumerate(samples):
        supervised = batch["input_ids"][row][batch["labels"][row] != IGNORE_INDEX]
        answer = sample["conversation"][-1]["content"][0]["text"]
        assert answer.startswith("<answer>") and answer.endswith("</answer>")
        assert processor.tokenizer.decode(supervised) == answer + "<|im_end|>"
    assert (batch["labels"][batch["attention_mask"] == 0] == IGNORE_INDEX).all()
    # the measured lengths (blank images of the rendered size) are the real ones
    data = _data(rooms)
    lengths = token_lengths(data, processor)
    real = [int(SFTCollator(processor, 4096)([data[i]])["attention_mask"].sum()) for i in range(4)]
    assert lengths[:4] == real


def test_over_budget_samples_are_dropped_and_counted(rooms) -> None:
    _, processor = prepare_model(model_options())
    data = _data(rooms)
    lengths = token_lengths(data, processor)
    limit = sorted(lengths)[len(lengths) // 2]
    budgeted = BudgetedDataset(data, lengths, limit)
    assert budgeted.dropped == sum(n > limit for n in lengths) > 0 and len(budgeted) + budgeted.dropped == len(data)
    collator = SFTCollator(processor, limit)
    long_one = data[lengths.index(max(lengths))]
    short_one = data[lengths.index(min(lengths))]
    batch = collator([long_one, short_one])
    assert batch["input_ids"].shape[0] == 1 and collator.dropped == 1
    with pytest.raises(InvalidDataError, match="longer than data.max_length"):
        BudgetedDataset(data, lengths, 16)


def test_a_few_steps_overfit_a_fixed_batch(rooms) -> None:
    torch.manual_seed(0)
    model, processor = prepare_model(model_options())
    batch = SFTCollator(processor, 4096)([_data(rooms)[i] for i in range(2)])
    optimizer = torch.optim.AdamW([p for p in model.parameters() if p.requires_grad], lr=3e-3)
    losses = []
    model.train()
    for _ in range(30):
        loss = model(**batch).loss
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert losses[-1] < losses[0] / 5, losses  # measured: 6.1 → below 1.2


def test_resume_continues_from_the_saved_loss(rooms, tmp_path, monkeypatch) -> None:
    whole = run(_config(rooms, tmp_path / "whole"))
    assert whole["global_step"] == 4 and len(whole["losses"]) == 4
    assert whole["losses"][-1] < whole["losses"][0]
    assert whole["train_loss"] == pytest.approx(sum(whole["losses"]) / 4, rel=1e-6)
    measured = whole["memory"]["per_rank"][0]
    assert {k: measured[k] for k in ("params", "grads", "optimizer")} == measured["predicted"]
    for name in ("checkpoint-2", "checkpoint-4", "data_stats.json"):
        src = tmp_path / "whole" / name
        (shutil.copytree if src.is_dir() else shutil.copy)(src, tmp_path / "resumed" / name)
    # checkpoint-4's save was "interrupted": no trainer_state.json; resume=auto must take checkpoint-2
    (tmp_path / "resumed" / "checkpoint-4" / "trainer_state.json").unlink()
    with pytest.raises(ParameterError, match="incomplete"):
        run(_config(rooms, tmp_path / "resumed", f"resume={tmp_path / 'resumed' / 'checkpoint-4'}"))
    # through the Trainer too, frozen parts keep their weights bit-exact and trained parts move
    from safetensors.torch import load_file

    before = load_file(str(tmp_path / "whole" / "base-model" / "model.safetensors"))
    after = load_file(str(tmp_path / "whole" / "final" / "model.safetensors"))
    vision = [k for k in before if k.startswith("visual.") and ".merger." not in k]  # saved in hub key format
    language = [k for k in before if k.startswith(("model.layers.", "lm_head."))]
    assert vision and language and set(before) == set(after)
    assert all(torch.equal(before[k], after[k]) for k in vision)
    assert not any(torch.equal(before[k], after[k]) for k in language if k.endswith("proj.weight"))
    resumed = run(_config(rooms, tmp_path / "resumed", "resume=auto"))
    assert resumed["losses"] == whole["losses"]  # steps 3 and 4 continue exactly
    assert resumed["train_loss"] == whole["train_loss"]  # the mean over all 4 steps, not only the resumed 2
    # the stock Trainer path loses the trained weights here: its steps 3-4 differ
    monkeypatch.setattr(SFTTrainer, "_load_from_checkpoint", Trainer._load_from_checkpoint)
    stock = run(_config(rooms, tmp_path / "stock", f"resume={tmp_path / 'whole' / 'checkpoint-2'}"))
    assert stock["losses"][2:] != whole["losses"][2:]


def test_run_writes_checkpoints_predict_can_load(rooms, tmp_path) -> None:
    summary = run(_config(rooms, tmp_path / "run", "model.lora=true", "model.min_pixels=1024", "model.max_pixels=4096"))
    out = tmp_path / "run"
    from spacedg.vlm import load_processor

    budget = load_processor(out / "checkpoint-2").image_processor.size
    assert (budget["shortest_edge"], budget["longest_edge"]) == (1024, 4096)  # the pixel budget travels with checkpoints
    assert (out / "checkpoint-2" / "adapter_model.safetensors").is_file()
    assert (out / "checkpoint-2" / "processor_config.json").is_file() and (out / "checkpoint-2" / "spacedg_sft.yaml").is_file()
    evaluation = summary["last_evaluation"]
    assert evaluation["eval_samples"] == 4 and 0.0 <= evaluation["eval_score"] <= 1.0
    assert any(k.startswith("eval_score_") for k in evaluation)
    stats = json.loads((out / "data_stats.json").read_text())
    assert stats["kept"] + stats["dropped_over_budget"] == stats["samples"] == 16
    assert stats["parameters"]["merger"]["trainable"] == 0  # LoRA trains the adapters only (freeze_merger: auto)
    for folder in (out / "final", out / "checkpoint-4"):
        model, processor = load_vlm(folder)
        assert processor.chat_template and model.config.model_type == "qwen2_5_vl"
    # spacedg predict records the pixel budget it used: the model's own when none is given
    from spacedg.data.dataset import SpaceDGDataset
    from spacedg.eval.predict import dataset_source, predict
    from spacedg.eval.predictions import meta_path

    dataset = SpaceDGDataset("val", ["haze"], scenes=[rooms], image_size=(64, 48), max_questions=2)
    result = predict(out / "final", dataset_source(dataset), tmp_path / "pred.jsonl", max_new_tokens=4, limit=1,
                     progress=False)
    assert result.answered == 1
    assert json.loads(meta_path(tmp_path / "pred.jsonl").read_text())["image_pixels"] == {"min": 1024, "max": 4096}


def test_exported_jsonl_as_training_data(rooms, tmp_path) -> None:
    from spacedg.data.dataset import SpaceDGDataset
    from spacedg.data.export import export_bench

    dataset = SpaceDGDataset("train", ["haze"], scenes=[rooms], image_size=(64, 48), max_questions=6, clean_prob=0.5)
    export_bench(dataset, tmp_path / "export", progress=False)
    summary = run(_config(rooms, tmp_path / "run", "data.source=jsonl", f"data.jsonl={tmp_path / 'export' / 'train.jsonl'}",
                          "train.max_steps=2"))
    assert summary["global_step"] == 2 and summary["data"]["samples"] == 6
    # the exported data trains; the evaluation still renders the val split (it used to be silently off)
    assert summary["last_evaluation"]["eval_samples"] == 4 and "val split" in summary["evaluation"]


def test_config_errors(rooms, tmp_path) -> None:
    with pytest.raises(ParameterError, match="train: .*no_such_key"):
        run(_config(rooms, tmp_path / "a", "+train.no_such_key=1"))
    with pytest.raises(ParameterError, match="resume=.*no such checkpoint"):
        run(_config(rooms, tmp_path / "b", f"resume={tmp_path / 'missing'}"))
    with pytest.raises(ParameterError, match="model: unknown key 'colour'; the known keys are path, dtype, .*lora"):
        run(_config(rooms, tmp_path / "d", "+model.colour=red"))
    with pytest.raises(ParameterError, match="data.jsonl=PATH"):
        run(_config(rooms, tmp_path / "c", "data.source=jsonl"))


def _env_without_repo() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    env["TOKENIZERS_PARALLELISM"] = "false"
    return env


def _reuse_numba_cache(checkout: Path, installed: Path) -> int:
    """Copy the checkout's compiled numba kernels (``__pycache__/*.nbi``, ``*.nbc``) beside the
    installed copies of the same modules; returns the number of files copied.

    numba keys a cached kernel by its module, function, line and the sha256 of the module's
    source, never by its path, so the installed copy loads the kernels the test run already
    compiled instead of compiling them again (~20 s on one core). Compiling from a fresh tree is
    the same code path as the checkout's own first compile in CI; a kernel whose source differs
    (or that the checkout has not compiled yet) is simply compiled as before."""
    copied = 0
    for cached in checkout.rglob("__pycache__/*.nb[ic]"):
        target = installed / cached.relative_to(checkout)
        if target.parent.parent.is_dir():
            target.parent.mkdir(exist_ok=True)
            shutil.copy2(cached, target)
            copied += 1
    return copied


def test_sft_runs_from_an_installed_wheel(rooms, tmp_path) -> None:
    """`python -m spacedg.sft +experiment=tiny` from a wheel installed into a folder of its own,
    run in a temporary directory: the configs come from the package, not the checkout. (The
    installed copy reuses the checkout's compiled numba kernels: :func:`_reuse_numba_cache`.)"""
    wheels, site = tmp_path / "wheels", tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(wheels), str(ROOT)],
                   check=True, capture_output=True, timeout=300)
    wheel = next(wheels.glob("spacedg-*.whl"))
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
                   check=True, capture_output=True, timeout=300)
    _reuse_numba_cache(ROOT / "spacedg", site / "spacedg")
    work = tmp_path / "work"
    work.mkdir()
    env = {**_env_without_repo(), "PYTHONPATH": str(site)}
    where = subprocess.run([sys.executable, "-c", "import spacedg, spacedg.conf; print(spacedg.__file__)"], cwd=work, env=env,
                           capture_output=True, text=True, check=True)
    assert where.stdout.strip().startswith(str(site))
    user_conf = tmp_path / "my-conf" / "experiment"
    user_conf.mkdir(parents=True)
    (user_conf / "mine.yaml").write_text("# @package _global_\ndefaults:\n  - tiny\ntrain:\n  max_steps: 2\n  save_steps: 2\n")
    result = subprocess.run(
        [sys.executable, "-m", "spacedg.sft", "--config-dir", str(tmp_path / "my-conf"), "+experiment=mine",
         f"data.scenes=[{rooms}]", "output_dir=out", "data.val.samples=2", "data.max_questions=8"],
        cwd=work, env=env, capture_output=True, text=True, timeout=600,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads((work / "out" / "train_summary.json").read_text())
    assert summary["global_step"] == 2 and (work / "out" / "final" / "config.json").is_file()
    assert (work / "out" / "app.log").is_file()  # Hydra's log keeps its name (conf/sft.yaml: hydra.job.name)
    script = subprocess.run([str(site / "bin" / "spacedg-sft"), "+experiment=tiny", "--cfg", "job"], cwd=work, env=env,
                            capture_output=True, text=True, timeout=120)
    assert script.returncode == 0 and "path: tiny:qwen2_5_vl" in script.stdout  # the console script finds the packaged configs


def test_a_val_share_renders_once_and_not_where_the_launch_does_not_evaluate(monkeypatch) -> None:
    """The app hands the trainer a ValShare (this rank's items, rendered at its first evaluation): a launch
    that shards the weights (FSDP, ZeRO-3) returns before it, so it renders nothing; a rank whose share is
    empty (fewer val samples than ranks) still joins the gather of the others' scores."""
    from types import SimpleNamespace

    from spacedg.sft.trainer import ValShare

    calls = []
    share = ValShare(lambda: calls.append(1) or [{"degradation_type": "haze"}])
    sharded = SimpleNamespace(val_items=share, shards_parameters=True)
    assert SFTTrainer.evaluate(sharded) == {} and calls == []  # FSDP / ZeRO-3: never rendered
    assert share.rendered() == share.rendered() == [{"degradation_type": "haze"}] and calls == [1]  # rendered once, kept
    # rank 1 of 2 with nothing to answer: it gathers rank 0's score all the same
    gathered_by = []

    def gather(parts: list, mine: list) -> None:
        gathered_by.append(mine)
        parts[:] = [[("haze", 1.0)], mine]

    monkeypatch.setattr(torch.distributed, "all_gather_object", gather)
    logged = []
    rank = SimpleNamespace(
        val_items=ValShare(lambda: []), shards_parameters=False, args=SimpleNamespace(process_index=1, world_size=2),
        accelerator=SimpleNamespace(unwrap_model=lambda model: model), model=torch.nn.Linear(1, 1), val_batch_size=1,
        log=logged.append, callback_handler=SimpleNamespace(on_evaluate=lambda *args: "control"), state=None, control=None,
    )
    assert bool(rank.val_items)
    metrics = SFTTrainer.evaluate(rank)
    assert gathered_by == [[]] and metrics == {"eval_score": 1.0, "eval_score_haze": 1.0, "eval_samples": 1.0} == logged[0]
