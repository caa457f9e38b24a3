"""SFT step speed and loss on a tiny VLM: full fine-tuning, LoRA, gradient checkpointing.

Prints a table only (never part of the test run).

    .venv/bin/python benchmarks/sft.py --scenes runs/demo/scenes          # after `make demo`
    .venv/bin/python benchmarks/sft.py --scenes runs/demo/scenes --steps 40 --size 128x96

Each configuration runs ``spacedg.sft.app.run`` on the same online samples (train split,
the nine degradations, severity random) for ``--steps`` optimizer steps of ``--batch``
samples: seconds of ``trainer.train`` (its ``train_runtime``; rendering included: samples are
rendered online; model set-up and token measurement excluded),
steps/s, samples/s, and the first and last logged loss. Evaluation is off.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

CONFIGS = {
    "full (ViT frozen)": [],
    "full + grad. checkpointing": ["model.gradient_checkpointing=true"],
    "LoRA r=8": ["model.lora=true"],
    "LoRA + grad. checkpointing": ["model.lora=true", "model.gradient_checkpointing=true"],
}


def main() -> None:
    from hydra import compose, initialize_config_module

    from spacedg.sft.app import run

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", type=Path, required=True)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--size", default="64x48", help="rendered WxH")
    parser.add_argument("--family", default="qwen2_5_vl")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    print(f"tiny {args.family}, {args.steps} steps × {args.batch} samples at {width}×{height}, online data")
    print(f"{'configuration':<30}{'seconds':>9}{'steps/s':>9}{'samples/s':>11}{'loss first':>12}{'loss last':>11}")
    for name, overrides in CONFIGS.items():
        with tempfile.TemporaryDirectory() as tmp, initialize_config_module(config_module="spacedg.conf", version_base="1.3"):
            cfg = compose("sft", overrides=[
                "+experiment=tiny", f"model.path=tiny:{args.family}", f"data.scenes=[{args.scenes}]", f"output_dir={tmp}",
                f"data.image_size=[{width},{height}]", "data.val.samples=0", "data.max_questions=null",
                f"train.max_steps={args.steps}", f"train.per_device_train_batch_size={args.batch}", f"train.save_steps={args.steps}",
                "+train.disable_tqdm=true", *overrides,
            ])
            summary = run(cfg)
            seconds = summary["train_runtime_s"]
            losses = summary["losses"]
            print(f"{name:<30}{seconds:>9.2f}{args.steps / seconds:>9.2f}{args.steps * args.batch / seconds:>11.1f}"
                  f"{losses[0]:>12.3f}{losses[-1]:>11.3f}")
            del summary


if __name__ == "__main__":
    main()
