"""Four small synthetic rooms for ``benchmarks/gpu_check.sh``: seeds 0-3, 30k Gaussians, 24-32 views
at 640×480, saved as ``FOLDER/room-00000{0..3}`` (the names ``benchmarks/dataset.py --small --root``
reads from ``ROOT/small``, so the bench-question table uses them instead of generating its own).

    python benchmarks/gpu_rooms.py FOLDER [GAUSSIANS]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from spacedg.scene.io import save_scene
from spacedg.scene.synthetic import CaptureConfig, RoomConfig, generate_room


def main(folder: Path, gaussians: int) -> None:
    config = RoomConfig(gaussians=gaussians, capture=CaptureConfig(640, 480, 24, 32))
    for seed in range(4):
        target = folder / f"room-{seed:06d}"
        if (target / "scene.json").is_file():
            continue
        start = time.perf_counter()
        room = generate_room(seed, config, scene_id=target.name)
        save_scene(room, target)
        print(f"{target}: {len(room.gaussians):,} Gaussians, {len(room.views)} views, {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 30_000)
