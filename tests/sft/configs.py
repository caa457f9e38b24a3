"""The packaged SFT configs as the tests use them: composed with Hydra, built with spacedg.sft.config.build."""

from __future__ import annotations

import dataclasses
from functools import cache
from pathlib import Path
from typing import Any

from hydra import compose, initialize_config_module
from omegaconf import DictConfig

from spacedg.sft.config import build
from spacedg.sft.model import ModelOptions


def compose_sft(*overrides: str) -> DictConfig:
    """``conf/sft.yaml`` composed with ``overrides`` (as on the command line)."""
    with initialize_config_module(config_module="spacedg.conf", version_base="1.3"):
        return compose("sft", overrides=list(overrides))


@cache
def _tiny() -> ModelOptions:
    return build(compose_sft("model=tiny").model, "model")


def model_options(path: str = "tiny:qwen2_5_vl", **changes: Any) -> ModelOptions:
    """``conf/model/tiny.yaml`` as :class:`ModelOptions`, with ``path`` and ``changes`` (validated again)."""
    return dataclasses.replace(_tiny(), path=path, **changes)


#: The repository root (``python -m spacedg.sft`` runs from there).
ROOT = Path(__file__).resolve().parents[2]
#: Overrides that make a recipe run take seconds: 4 steps, saves and evaluations every 2, 4 val samples.
FAST = ["train.max_steps=4", "train.save_steps=2", "train.eval_steps=2", "data.val.samples=4", "data.max_questions=16"]
