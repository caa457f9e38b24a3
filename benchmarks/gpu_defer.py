"""``SpaceDGDataset(device=D, defer_render=True)`` once, as the README's GPU example uses it.

Two forked DataLoader workers plan a batch of bench items (question text, no images: CUDA never
enters them), this process renders it with ``render_batch`` on ``D``; the same items read
directly (``dataset[i]`` in this process) must give the same images. Prints shapes, where the
images were degraded and the time per batch.

    python benchmarks/gpu_defer.py SCENES_FOLDER cuda     # benchmarks/gpu_check.sh's `defer` step
"""

from __future__ import annotations

import sys
import time

import torch
from torch.utils.data import DataLoader

import spacedg


def main(scenes: str, device: str) -> None:
    dataset = spacedg.SpaceDGDataset("bench", scenes=[scenes], split_fractions=(0, 1), image_size=(640, 480),
                                     device=device, defer_render=True)
    loader = DataLoader(dataset, batch_size=10, num_workers=2, collate_fn=list)
    batch = next(iter(loader))
    assert all("images" not in item for item in batch), "workers must not render"
    if device.startswith("cuda"):
        torch.cuda.synchronize()
    start = time.perf_counter()
    items = dataset.render_batch(batch)
    if device.startswith("cuda"):
        torch.cuda.synchronize()
    seconds = time.perf_counter() - start
    print(f"defer_render on {device}: {len(items)} items planned by 2 workers, rendered here in {seconds * 1e3:.0f} ms "
          f"(first batch: kernels and scene load included)")
    print(f"  images {tuple(items[0]['images'].shape)} {items[0]['images'].dtype}; chains {[item['degradation_type'] for item in items]}")
    print(f"  item 0 stats: { {k: round(v, 2) if isinstance(v, float) else v for k, v in items[0].get('stats', {}).items()} }")
    direct = spacedg.SpaceDGDataset("bench", scenes=[scenes], split_fractions=(0, 1), image_size=(640, 480), device=device)
    same = [torch.equal(items[i]["images"], direct[i]["images"]) for i in range(len(items))]
    print(f"  deferred == direct dataset[i]: {sum(same)} of {len(same)}")
    assert all(same), "deferred renders differ from direct ones"


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
