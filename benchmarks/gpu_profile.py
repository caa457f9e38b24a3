"""Where the time of one gsplat-backend render goes on a GPU: torch.profiler's CUDA kernels and CPU
ops of ``render(..., backend="gsplat")`` against ``gsplat.rasterization`` on the same Gaussians
(benchmarks/device_paths.random_scene, 640×480), the top rows by total CUDA time and by CPU time.

    python benchmarks/gpu_profile.py --device cuda --n 1000000
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from device_paths import gsplat_own, random_scene  # noqa: E402


def main() -> None:
    import torch
    from torch.profiler import ProfilerActivity, profile

    from spacedg.render import render

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--n", type=int, default=1_000_000)
    parser.add_argument("--rows", type=int, default=14)
    args = parser.parse_args()
    g, cam = random_scene(args.n, seed=args.n)
    runs = {
        "ours (gsplat backend)": lambda: render(g, cam, outputs="rgb,alpha", backend="gsplat", device=args.device),
        "gsplat.rasterization": gsplat_own(g, cam, args.device),
    }
    for name, run in runs.items():
        run()
        torch.cuda.synchronize()
        with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
            for _ in range(3):
                run()
            torch.cuda.synchronize()
        print(f"\n=== {name}, {args.n} Gaussians, 3 renders")
        print(prof.key_averages().table(sort_by="cuda_time_total", row_limit=args.rows, max_name_column_width=48))
        print(prof.key_averages().table(sort_by="cpu_time_total", row_limit=8, max_name_column_width=48))


if __name__ == "__main__":
    main()
