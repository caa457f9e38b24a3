"""What question building costs per scene, and how long a corpus takes on many cores.

Prints numbers only (never part of the test run).

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/qa_scale.py                  # built-in room seed 0
    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/qa_scale.py --seed 3 --scenes 2000 --cores 100

For one built-in room (``generate_room(seed)``: 150k–300k Gaussians, 48–120 views at 640×480),
each stage of ``spacedg qa build`` (visibility, covisibility, question generation; no cache) is
timed in wall seconds and in this process's CPU seconds (``time.process_time``: on a loaded
machine the CPU seconds are what a free core would take). ``qa build`` runs one process per scene
with ``cores // processes`` threads (:mod:`spacedg.qa.jobs`), scenes being independent, so
``--scenes`` scenes on ``--cores`` cores take about ``ceil(scenes / cores) × CPU seconds per scene``
(one thread per process once scenes outnumber cores). Real-size scenes (ScanNet++ DSLR: 300–500
views at 1752×1168, millions of Gaussians) cost more per scene: put their measured cost in
``--per-scene`` to project them.
"""

from __future__ import annotations

import argparse
import math
import time

from spacedg.qa.build import generate_records
from spacedg.qa.index import QABuildConfig
from spacedg.scene.covisibility import with_covisibility
from spacedg.scene.labelling import ensure_instance_ids
from spacedg.scene.synthetic import generate_room
from spacedg.scene.visibility import compute_visibility, with_visibility


def _timed(stages: dict[str, tuple[float, float]], name: str, fn):
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn()
    stages[name] = (time.perf_counter() - wall, time.process_time() - cpu)
    return out


def measure(seed: int) -> tuple[dict[str, tuple[float, float]], int, str]:
    """Stage → (wall s, CPU s) for one built-in room, its record count and a one-line description."""
    config = QABuildConfig()
    scene = ensure_instance_ids(generate_room(seed))
    stages: dict[str, tuple[float, float]] = {}
    table = _timed(stages, "visibility", lambda: compute_visibility(scene, image_size=config.visibility_size, progress=False))
    scene = with_visibility(scene, table)
    scene = _timed(stages, "covisibility", lambda: with_covisibility(scene, None, image_size=config.covisibility_size, progress=False))
    records = _timed(stages, "generate", lambda: generate_records(scene, config))
    about = f"room seed {seed}: {len(scene.gaussians):,} Gaussians, {len(scene.views)} views, {len(scene.instances)} objects"
    return stages, len(records), about


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scenes", type=int, default=2000, help="scenes to project (Holi-Spatial: 2,000+)")
    parser.add_argument("--cores", type=int, default=100)
    parser.add_argument("--per-scene", type=float, default=None, help="CPU s per scene to project instead of the measured one")
    args = parser.parse_args()
    stages, records, about = measure(args.seed)
    print(about)
    print(f"{'stage':<14} {'wall s':>8} {'CPU s':>8}")
    for name, (wall, cpu) in stages.items():
        print(f"{name:<14} {wall:>8.1f} {cpu:>8.1f}")
    total_cpu = sum(cpu for _, cpu in stages.values())
    print(f"{'total':<14} {sum(w for w, _ in stages.values()):>8.1f} {total_cpu:>8.1f}   ({records} records)")
    per_scene = total_cpu if args.per_scene is None else args.per_scene
    waves = math.ceil(args.scenes / args.cores)
    hours = waves * per_scene / 3600
    print(f"projection: {args.scenes} scenes on {args.cores} cores = {waves} waves x {per_scene:.0f} CPU s "
          f"= {hours:.2f} h ({hours * 60:.0f} min) with qa build --jobs {args.cores} (or --shard over machines)")


if __name__ == "__main__":
    main()
