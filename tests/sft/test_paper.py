"""The paper's training run as configs (conf/experiment/paper*.yaml): each resolves, says what the paper
says (Qwen3-VL-8B / InternVL3.5-8B, 1 epoch, global batch 2048 on 8 GPUs, FSDP), holds out exactly one
degradation category, and starts on tiny stand-ins up to and including the model load."""

from __future__ import annotations

import subprocess
import sys

import pytest
from omegaconf import OmegaConf

from spacedg.data.chain import BENCH_DEGRADATIONS
from spacedg.errors import ParameterError
from spacedg.plugins import get_degradation
from spacedg.sft.app import training_arguments
from spacedg.sft.config import build
from spacedg.sft.distributed import launch_of
from spacedg.sft.model import prepare_model
from spacedg.sft.sources import qa_config_for
from tests.sft.configs import ROOT, compose_sft

#: The paper's four degradation categories (registry names) and the ablation config holding each out.
CATEGORIES = ("optical_dynamic", "meteorological", "photometric", "digital")
PAPER = ["paper", "paper_internvl", "paper_clean", *(f"paper_no_{c}" for c in CATEGORIES)]


def test_every_paper_experiment_has_a_file() -> None:
    found = sorted(p.stem for p in (ROOT / "conf" / "experiment").glob("paper*.yaml"))
    assert found == sorted(PAPER)


@pytest.mark.parametrize("name", PAPER)
def test_paper_configs_resolve_with_the_papers_settings(name) -> None:
    cfg = compose_sft(f"+experiment={name}", "output_dir=/tmp/x")
    resolved = OmegaConf.to_container(cfg, resolve=True)  # what `--cfg job` prints, every interpolation resolved
    train, data, model = resolved["train"], resolved["data"], resolved["model"]
    assert train["num_train_epochs"] == 1 and train["max_steps"] == -1
    assert train["per_device_train_batch_size"] * train["gradient_accumulation_steps"] * 8 == 2048
    assert train["fsdp"] is True and train["fsdp_config"]["version"] == 2
    assert model["path"] == ("OpenGVLab/InternVL3_5-8B-HF" if name == "paper_internvl" else "Qwen/Qwen3-VL-8B-Instruct")
    assert not model["lora"] and model["freeze_vision"] and model["gradient_checkpointing"]
    assert data["qa_mode"] == "train" and data["val"]["degradations"] is None  # evaluated on all nine
    assert data["clean_prob"] == (1.0 if name == "paper_clean" else 0.1)
    options = build(cfg.data, "data")  # names checked like a run checks them
    assert options.qa_mode == "train"


def test_cfg_job_prints_the_resolved_config_without_importing_the_training_stack() -> None:
    """``python -m spacedg.sft +experiment=paper --cfg job`` is Hydra's work alone: the entry point
    (spacedg.sft.command) imports torch, transformers and peft only once a run starts (they took 6–7 s
    of every ``--cfg job``, ``--help`` and bad override)."""
    result = subprocess.run([sys.executable, "-X", "importtime", "-m", "spacedg.sft", "+experiment=paper", "--cfg", "job"],
                            cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "path: Qwen/Qwen3-VL-8B-Instruct" in result.stdout and "num_train_epochs: 1" in result.stdout
    imported = {line.rsplit("|", 1)[1].strip() for line in result.stderr.splitlines() if line.startswith("import time:")}
    assert "hydra" in imported and not imported & {"torch", "transformers", "peft", "numba", "spacedg.sft.app"}


@pytest.mark.parametrize("category", CATEGORIES)
def test_each_held_out_config_trains_on_the_other_categories(category) -> None:
    degradations = build(compose_sft(f"+experiment=paper_no_{category}").data, "data").degradations
    expected = [n for n in BENCH_DEGRADATIONS if get_degradation(n).category != category]
    assert sorted(degradations) == sorted(expected) and len(expected) < len(BENCH_DEGRADATIONS)


@pytest.mark.parametrize(("name", "family"), [("paper", "qwen3_vl"), ("paper_internvl", "internvl")])
def test_paper_configs_start_up_to_the_model_load_on_tiny_stand_ins(name, family, tmp_path) -> None:
    """As spacedg.sft.app.run starts: data options, model options, training arguments (FSDP2, one CPU
    process here), the launch, then the model load: the tiny model of the same family built in code."""
    cfg = compose_sft(f"+experiment={name}", f"model.path=tiny:{family}", f"output_dir={tmp_path}",
                      "train.bf16=false", "train.dataloader_num_workers=0", "data.val.samples=0")
    build(cfg.data, "data")
    options = build(cfg.model, "model")
    config = OmegaConf.to_container(cfg, resolve=True)
    args = training_arguments(config["train"], tmp_path, config["seed"], evaluate=False)
    assert args.gradient_accumulation_steps == 32 and args.per_device_train_batch_size == 8
    assert launch_of(args).name == "fsdp2"
    model, processor = prepare_model(options, mixed_precision="no", shards_parameters=True)
    assert family.replace("_", "") in type(model).__name__.lower() and processor is not None
    trained = {n for n, p in model.named_parameters() if p.requires_grad}
    vision = {n for n in trained if ("visual" in n and "merger" not in n) or "vision_tower" in n}
    assert trained and not vision  # the vision tower frozen, the language model (and merger) trained


def test_qa_mode_passes_through() -> None:
    assert qa_config_for(None) is None
    assert qa_config_for("train").mode == "train" and qa_config_for("bench").mode == "bench"
    with pytest.raises(ParameterError, match="data.qa_mode"):
        build(compose_sft("data.qa_mode=dense").data, "data")


def test_memory_of_the_papers_run_per_gpu() -> None:
    """The 8B models built from their config.json have their published sizes; the documented table's
    state is 16 bytes per trained and 4 per frozen parameter over 8 GPUs, and the run fits 80 GB."""
    from spacedg.sft.memory import counts
    from spacedg.sft.paper_models import INTERNVL3_5_8B, QWEN3_VL_8B, internvl3_5_8b, paper_rows, qwen3_vl_8b

    for build_model, config, published in ((qwen3_vl_8b, QWEN3_VL_8B, 8.77e9), (internvl3_5_8b, INTERNVL3_5_8B, 8.5e9)):
        model = build_model()
        c = counts(model, lora_rank=None)
        assert abs(c["vision"] + c["merger"] + c["language"] - published) < 0.01 * published
        small, large = paper_rows(model, config["text_config"], tokens=(12_000, 32_768))
        state = small["weights"] + small["grads"] + small["optimizer"]
        assert abs(state - (16 * small["trained"] + 4 * small["frozen"]) / 8e9) < 1e-6
        assert small["total"] < large["total"] < 40
