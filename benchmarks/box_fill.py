"""Box fill (issue 28 item 3): does every box hold its object, and is a moved box found and put back?

Prints numbers only (never part of the test run):

1. **false alarms**: built-in synthetic rooms (seeds 1..``--seeds``) with their true boxes:
   boxes flagged empty or misplaced (should be 0);
2. **moved boxes**: every small box (longest side under 30 cm) of room 5 moved by 7 cm along
   ±x and ±y: how many are flagged, and the error of the shift suggested to put them back;
3. **speed**: room 5 densified to ``--millions`` million Gaussians (copies jittered by 3 mm),
   its 24 boxes measured;
4. the fill table of room 5 with its cup moved by 7 cm (what ``scenes import`` prints).

    .venv/bin/python benchmarks/box_fill.py
    .venv/bin/python benchmarks/box_fill.py --seeds 4 --millions 1
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from spacedg.scene.box_fill import measure_box_fill  # noqa: E402
from spacedg.scene.model import Scene  # noqa: E402
from spacedg.scene.synthetic import CaptureConfig, RoomConfig, generate_room  # noqa: E402


def room(seed: int) -> Scene:
    return generate_room(seed, RoomConfig(gaussians=20_000, capture=CaptureConfig(160, 120, 4, 4), world_frame="z_up"))


def moved(scene: Scene, box_id: int, shift: np.ndarray) -> list:
    from dataclasses import replace

    return [replace(i, box=i.box.transformed(np.eye(3), shift)) if i.id == box_id else i for i in scene.instances]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--millions", type=float, default=2.3)
    args = parser.parse_args()
    alarms = 0
    for seed in range(1, args.seeds + 1):
        scene = room(seed)
        bad = measure_box_fill(scene.gaussians.means, scene.instances).bad
        alarms += len(bad)
        print(f"room {seed}: {len(scene.instances)} true boxes, flagged {[(r.id, r.label, r.status) for r in bad]}")
    print(f"false alarms: {alarms}")
    scene = room(5)
    flagged, errors, tried = 0, [], 0
    for inst in scene.instances:
        if float(inst.box.extents.max()) >= 0.3:
            continue
        for shift in (np.array([0.07, 0, 0]), np.array([-0.07, 0, 0]), np.array([0, 0.07, 0]), np.array([0, -0.07, 0])):
            tried += 1
            row = next(r for r in measure_box_fill(scene.gaussians.means, moved(scene, inst.id, shift)).rows if r.id == inst.id)
            if row.bad:
                flagged += 1
                if row.shift is not None:
                    errors.append(float(np.linalg.norm(np.array(row.shift) + shift)))
    err = np.array(errors)
    print(f"7 cm moves of small boxes: {flagged} of {tried} flagged; shift back error median {np.median(err) * 100:.1f} cm, "
          f"{(err < 0.02).mean():.0%} within 2 cm" if len(err) else f"7 cm moves: {flagged} of {tried} flagged")
    rng = np.random.default_rng(0)
    copies = max(1, round(args.millions * 1e6 / len(scene.gaussians)))
    big = np.concatenate([scene.gaussians.means + rng.normal(0, 0.003, scene.gaussians.means.shape) for _ in range(copies)])
    start = time.perf_counter()
    measure_box_fill(big, scene.instances)
    print(f"speed: {len(big):,} Gaussians x {len(scene.instances)} boxes in {time.perf_counter() - start:.2f} s")
    print(measure_box_fill(scene.gaussians.means, moved(scene, 16, np.array([0, -0.07, 0]))).text(limit=6))


if __name__ == "__main__":
    main()
