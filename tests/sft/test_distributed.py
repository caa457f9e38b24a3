"""The launches a real multi-GPU run uses, on CPU: torchrun, 2 processes, gloo, the tiny Qwen2.5-VL.

DDP is the reference. FSDP2 (sharded the way accelerate shards it: spacedg turns accelerate's FSDP
path on for CPU) must give the same losses, resume bit-exactly from its sharded checkpoint (full
model and LoRA) and write a ``final/`` that ``spacedg predict`` loads; FSDP1 and DeepSpeed ZeRO-3
(its CPU accelerator; skipped without deepspeed) must train the same and export the same weights.
Each rank's parameter, gradient and optimizer bytes are checked against spacedg.sft.memory.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file
from tests.sft.configs import ROOT, FAST


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _torchrun(rooms: Path, out: Path, *overrides: str) -> dict:
    """``torchrun --nproc_per_node 2 -m spacedg.sft +experiment=tiny ...`` of this checkout; its summary."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(PYTHONPATH=str(ROOT), TOKENIZERS_PARALLELISM="false")
    torchrun = Path(sys.executable).with_name("torchrun")
    result = subprocess.run(
        [str(torchrun), "--nproc_per_node", "2", "--master_port", str(_port()), "-m", "spacedg.sft", "+experiment=tiny",
         f"data.scenes=[{rooms}]", f"output_dir={out}", *FAST, *overrides],
        cwd=out.parent, env=env, capture_output=True, text=True, timeout=600,
    )
    assert result.returncode == 0, result.stderr[-4000:]
    return json.loads((out / "train_summary.json").read_text())


def _weights(folder: Path) -> dict[str, torch.Tensor]:
    return load_file(str(folder / "model.safetensors"))


def _resume(rooms: Path, whole: Path, out: Path, *overrides: str) -> dict:
    """Resume in ``out`` from ``whole``'s checkpoint-2 (``resume=auto``)."""
    shutil.copytree(whole / "checkpoint-2", out / "checkpoint-2")
    return _torchrun(rooms, out, "resume=auto", *overrides)


def _check_memory(summary: dict) -> None:
    ranks = summary["memory"]["per_rank"]
    assert len(ranks) == 2
    for measured in ranks:
        assert {k: measured[k] for k in ("params", "grads", "optimizer")} == measured["predicted"]


@pytest.fixture(scope="module")
def ddp(rooms, tmp_path_factory) -> tuple[dict, Path]:
    out = tmp_path_factory.mktemp("ddp") / "run"
    return _torchrun(rooms, out), out


def test_torchrun_two_process_ddp(ddp) -> None:
    summary, out = ddp
    assert summary["distributed"] == {"world_size": 2, "parallel_mode": "distributed", "launch": "ddp",
                                      "mixed_precision": "no", "fsdp": False, "deepspeed": False,
                                      "model_class": "DistributedDataParallel", "wrapped_classes": None,
                                      "weights_read_by": "every rank"}
    assert summary["global_step"] == 4 and summary["last_evaluation"]["eval_samples"] == 4
    _check_memory(summary)
    assert (out / "final" / "model.safetensors").is_file()


def test_fsdp2_resumes_bit_exactly_and_writes_a_final_model(ddp, rooms, tmp_path) -> None:
    reference, ddp_out = ddp
    whole = _torchrun(rooms, tmp_path / "whole", "train=fsdp")
    assert whole["distributed"]["launch"] == "fsdp2" and whole["distributed"]["fsdp"]
    assert whole["distributed"]["model_class"] == "FSDPQwen2_5_VLForConditionalGeneration"
    assert whole["distributed"]["wrapped_classes"] == ["Qwen2_5_VLDecoderLayer", "Qwen2_5_VLVisionBlock"]
    assert whole["distributed"]["weights_read_by"] == "rank 0"  # rank 1 received its shards (cpu_ram_efficient_loading)
    assert whole["losses"] == pytest.approx(reference["losses"], abs=1e-6)  # sharding changes nothing
    _check_memory(whole)  # each rank holds exactly its shards
    assert (tmp_path / "whole" / "checkpoint-2" / "pytorch_model_fsdp_0").is_dir()  # sharded checkpoints
    resumed = _resume(rooms, tmp_path / "whole", tmp_path / "resumed", "train=fsdp")
    assert resumed["losses"] == whole["losses"] and resumed["train_loss"] == whole["train_loss"]
    final = _weights(tmp_path / "whole" / "final")
    again = _weights(tmp_path / "resumed" / "final")
    assert final.keys() == again.keys() and all(torch.equal(final[k], again[k]) for k in final)
    plain = _weights(ddp_out / "final")
    assert final.keys() == plain.keys() and max(float((final[k] - plain[k]).abs().max()) for k in final) < 1e-5
    # spacedg predict loads and runs final/
    from spacedg.data.dataset import SpaceDGDataset
    from spacedg.eval.predict import dataset_source, predict

    dataset = SpaceDGDataset("val", ["haze"], scenes=[rooms], image_size=(64, 48), max_questions=2)
    done = predict(tmp_path / "whole" / "final", dataset_source(dataset), tmp_path / "pred.jsonl", max_new_tokens=4,
                   limit=1, progress=False)
    assert done.answered == 1


def test_lora_under_fsdp2_resumes_bit_exactly(rooms, tmp_path) -> None:
    whole = _torchrun(rooms, tmp_path / "whole", "train=fsdp", "model.lora=true")
    _check_memory(whole)
    resumed = _resume(rooms, tmp_path / "whole", tmp_path / "resumed", "train=fsdp", "model.lora=true")
    assert resumed["losses"] == whole["losses"]
    final, again = _weights(tmp_path / "whole" / "final"), _weights(tmp_path / "resumed" / "final")
    assert all(torch.equal(final[k], again[k]) for k in final)
    assert not (tmp_path / "whole" / "final" / "adapter_config.json").exists()  # merged


def _deepspeed() -> bool:
    try:
        import deepspeed  # noqa: F401
    except Exception:
        return False
    return True


@pytest.mark.parametrize("launch", [
    # FSDP1 on CPU: accelerate's plugin refuses sync_module_states without an accelerator, and
    # cpu_ram_efficient_loading needs it
    ("train=fsdp1", "train.fsdp_config.sync_module_states=false", "train.fsdp_config.cpu_ram_efficient_loading=false"),
    pytest.param(("train=zero3",), marks=pytest.mark.skipif(not _deepspeed(), reason="deepspeed is not installed")),
], ids=["fsdp1", "zero3"])
def test_fsdp1_and_zero3_train_and_export_the_same(ddp, rooms, tmp_path, launch) -> None:
    reference, ddp_out = ddp
    summary = _torchrun(rooms, tmp_path / "run", *launch)
    assert summary["distributed"]["launch"] == launch[0].split("=")[1]
    assert summary["losses"] == pytest.approx(reference["losses"], abs=1e-5)
    final, plain = _weights(tmp_path / "run" / "final"), _weights(ddp_out / "final")
    assert final.keys() == plain.keys() and max(float((final[k] - plain[k]).abs().max()) for k in final) < 1e-5
    if launch[0] == "train=zero3":
        assert summary["last_evaluation"] is None  # no generation on a partitioned model
        assert all(m["optimizer"] == m["predicted"]["optimizer"] for m in summary["memory"]["per_rank"])
