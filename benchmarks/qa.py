"""Question generation on the built-in synthetic rooms: rate, counts, answer balance, blind baseline.

Prints numbers only (never part of the test run).

    .venv/bin/python benchmarks/qa.py                      # 4 default rooms (seeds 0-3)
    .venv/bin/python benchmarks/qa.py --rooms 2 --per-sub-type 10

For each room (``generate_room(seed)``, default size: 150k–300k Gaussians, 48–120 views at
640×480): the time to attach instance visibility and covisibility (no cache), then the time to
generate the question index (:func:`spacedg.qa.build.generate_records`, all eleven
families) and its rate in questions per second. Then, per family, the rate measured by
generating that family alone (every room). Finally the balance table on all rooms: correct
letter over A–D, yes/no share, and the leave-one-room-out blind baseline (most frequent answer
per sub type, learnt on the other rooms) against chance.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

from spacedg.qa.build import generate_records, prepare_scene
from spacedg.qa.index import QABuildConfig
from spacedg.qa.stats import answer_balance, blind_baseline, count_table, format_table
from spacedg.scene.synthetic import RoomConfig, generate_room
from spacedg.plugins import list_question_families


def _machine() -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, load {load:.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rooms", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0, help="first room seed; QA seed too")
    parser.add_argument("--per-sub-type", type=int, default=25)
    args = parser.parse_args()
    print(f"machine: {_machine()}")
    config = QABuildConfig(seed=args.seed, per_sub_type=args.per_sub_type)

    prepared = []
    rows = []
    by_scene = {}
    for i in range(args.rooms):
        scene = generate_room(args.seed + i, RoomConfig(), scene_id=f"room-{args.seed + i:06d}")
        timings: dict[str, float] = {}
        scene = prepare_scene(scene, None, config, progress=False, timings=timings)
        t0 = time.perf_counter()
        records = generate_records(scene, config)
        gen = time.perf_counter() - t0
        prepared.append(scene)
        by_scene[scene.id] = records
        rows.append({
            "scene": scene.id, "gaussians": len(scene.gaussians), "views": len(scene.views), "instances": len(scene.instances),
            "visibility_s": timings["visibility_s"], "covisibility_s": timings["covisibility_s"],
            "records": len(records), "generate_s": gen, "questions_per_s": len(records) / gen if gen > 0 else float("nan"),
        })
    print("\n## Per room (prepare = visibility + covisibility from renders, no cache)\n")
    print(format_table(rows))

    print("\n## Per family (all rooms, capped at --per-sub-type per sub type per room)\n")
    fam_rows = []
    for family in list_question_families():
        cfg = QABuildConfig(seed=args.seed, families=(family.name,), per_sub_type=args.per_sub_type)
        t0 = time.perf_counter()
        n = sum(len(generate_records(scene, cfg)) for scene in prepared)
        took = time.perf_counter() - t0
        fam_rows.append({"family": family.name, "records": n, "seconds": took, "questions_per_s": n / took if took > 0 else float("nan")})
    print(format_table(fam_rows))

    every = [r for rs in by_scene.values() for r in rs]
    print("\n## Counts\n")
    print(format_table(count_table(every)))
    bal = answer_balance(every)
    print(f"\nMCQ correct letter ({bal['mcq_n']} records): " + "  ".join(f"{k} {v:.1f}%" for k, v in bal["letters"].items()))
    print(f"YN ({bal['yn_n']} records): yes {bal['yes_pct']:.1f}%")
    print("\n## Blind baseline (leave-one-room-out majority per sub type, accuracy %)\n")
    print(format_table(blind_baseline(by_scene)))


if __name__ == "__main__":
    main()
