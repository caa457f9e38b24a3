"""Reader/writer speed on real and synthetic data (prints times; never part of the test run).

    .venv/bin/python benchmarks/io_speed.py
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from spacedg.scene.io import read_ply, read_splat, write_ply
from spacedg.scene.synthetic import RoomConfig, generate_room
from spacedg.render.gaussians import Gaussians

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "splats"


def best_of(fn, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def random_gaussians(n: int, degree: int, seed: int = 0) -> Gaussians:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return Gaussians(rng.normal(size=(n, 3)), q, rng.uniform(1e-3, 0.1, (n, 3)), rng.uniform(0, 1, n),
                     rng.normal(size=(n, (degree + 1) ** 2, 3)) * 0.2)


def main() -> None:
    print(f"{'what':<44} {'seconds':>8} {'exact round trip':>17}")
    if (SHARED / "plant" / "plant.splat").is_file():
        t = best_of(lambda: read_splat(SHARED / "plant" / "plant.splat"))
        print(f"{'read plant.splat (113,648 Gaussians)':<44} {t:>8.3f} {'-':>17}")
    with tempfile.TemporaryDirectory() as tmp:
        for degree in (0, 3):
            g = random_gaussians(400_000, degree)
            path = Path(tmp) / f"d{degree}.ply"
            t_w = best_of(lambda: write_ply(path, g))
            t_r = best_of(lambda: read_ply(path))
            back = read_ply(path)
            again = Path(tmp) / "again.ply"
            write_ply(again, back)
            exact = all(np.array_equal(getattr(back, f), getattr(read_ply(again), f)) for f in ("means", "quats", "scales", "opacities", "sh"))
            print(f"{f'write 400k PLY, SH degree {degree} ({path.stat().st_size / 1e6:.0f} MB)':<44} {t_w:>8.3f} {'-':>17}")
            print(f"{f'read 400k PLY, SH degree {degree}':<44} {t_r:>8.3f} {str(exact):>17}")
    for seed in range(4):
        t = best_of(lambda: generate_room(seed), repeats=1)
        print(f"{f'generate_room({seed}) default config':<44} {t:>8.3f} {'-':>17}")
    t = best_of(lambda: generate_room(0, RoomConfig(gaussians=400_000)), repeats=1)
    print(f"{'generate_room(0, gaussians=400k)':<44} {t:>8.3f} {'-':>17}")


if __name__ == "__main__":
    main()
