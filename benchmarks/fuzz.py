"""Long fuzz run: ≥ 10,000 seeded hostile or random cases against spacedg's public entry points.

Families and what they feed (``tests/fuzz_cases.py``): the readers (PLY binary/ASCII with edited
headers and poked values, .splat, .spz including decompression bombs, scene.json, COLMAP text and
binary, transforms.json, INRIA cameras.json, instance / ScanNet++ / EmbodiedScan JSON — mutated
valid files and random bytes, 5,000-digit integers, NaN, huge values), renders (random and
degenerate Gaussians and cameras: zero and 3e38 scales, points behind or at the camera, fisheye
lenses, defocus up to 10⁴ px, motion blur, both backends), degradations (every built-in at random
valid parameters including the hard limits, on black, white, random and HDR images, depth maps
with holes) and the command line (``spacedg`` subcommands in-process with hostile arguments).

Cases run in worker processes with a per-case timeout (a case over it is a hang: its worker is
killed and replaced). Prints the counts per family and overall — ok, clear errors, tracebacks,
non-finite outputs, hangs — and the details of every traceback, non-finite output and hang.
Exit status 1 if any of those occurred.

    .venv/bin/python benchmarks/fuzz.py [--cases 10800] [--workers 2] [--timeout 60] [--seed 0]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import queue
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.fuzz_cases import FAMILIES, OUTCOMES, Assets, Result, run_case  # noqa: E402

#: Share of the cases per family (renders and readers dominate; the CLI is slower per case).
WEIGHTS = {"ply": 10, "splat": 5, "spz": 5, "scene_json": 10, "colmap_text": 5, "colmap_bin": 5, "transforms": 6,
           "inria": 5, "instances": 6, "render": 25, "degradation": 12, "cli": 6}


def _worker(jobs: mp.Queue, results: mp.Queue, root: str, index: int) -> None:
    os.environ.setdefault("SPACEDG_DISABLE_PLUGIN_AUTOLOAD", "1")
    assets = Assets(Path(root) / "assets")
    work = Path(root) / f"worker{index}-{os.getpid()}"
    while True:
        job = jobs.get()
        if job is None:
            return
        family, seed = job
        results.put((index, "start", family, seed, time.perf_counter()))
        result = run_case(family, seed, assets, work / family)
        results.put((index, "done", result.family, result.seed, (result.outcome, result.detail)))


def plan(total: int, seed: int) -> list[tuple[str, int]]:
    weight = sum(WEIGHTS.values())
    cases = []
    for family in FAMILIES:
        count = max(1, round(total * WEIGHTS[family] / weight))
        cases += [(family, seed * 1_000_000 + k) for k in range(count)]
    return cases


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", type=int, default=10_800)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per case before it counts as a hang")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--families", default=",".join(FAMILIES), help="comma-separated subset")
    args = parser.parse_args()
    wanted = set(args.families.split(","))
    cases = [c for c in plan(args.cases, args.seed) if c[0] in wanted]
    ctx = mp.get_context("spawn")
    start = time.perf_counter()
    counts: dict[str, Counter] = defaultdict(Counter)
    problems: list[Result] = []
    with tempfile.TemporaryDirectory(prefix="spacedg-fuzz-") as root:
        Assets(Path(root) / "assets")  # build once before the workers read them
        jobs: mp.Queue = ctx.Queue()
        results: mp.Queue = ctx.Queue()
        for case in cases:
            jobs.put(case)
        workers: dict[int, mp.Process] = {}
        running: dict[int, tuple[str, int, float]] = {}

        def spawn(i: int) -> None:
            workers[i] = ctx.Process(target=_worker, args=(jobs, results, root, i), daemon=True)
            workers[i].start()

        for i in range(args.workers):
            spawn(i)
        done = 0
        last_report = time.perf_counter()
        while done < len(cases):
            try:
                index, kind, family, seed, payload = results.get(timeout=1.0)
                if kind == "start":
                    running[index] = (family, seed, time.monotonic())
                else:
                    running.pop(index, None)
                    outcome, detail = payload
                    counts[family][outcome] += 1
                    done += 1
                    if outcome in ("traceback", "nonfinite"):
                        problems.append(Result(family, seed, outcome, detail))
            except queue.Empty:
                pass
            now = time.monotonic()
            for index, (family, seed, began) in list(running.items()):
                if now - began > args.timeout or not workers[index].is_alive():
                    workers[index].kill()
                    workers[index].join()
                    outcome = "hang" if now - began > args.timeout else "traceback"
                    counts[family][outcome] += 1
                    problems.append(Result(family, seed, outcome, f"worker {'timed out' if outcome == 'hang' else 'died'} after {now - began:.0f} s"))
                    running.pop(index)
                    done += 1
                    spawn(index)
            if time.perf_counter() - last_report > 60:
                last_report = time.perf_counter()
                print(f"... {done}/{len(cases)} cases, {time.perf_counter() - start:.0f} s", flush=True)
        for _ in workers:
            jobs.put(None)
        for process in workers.values():
            process.join(timeout=10)
    seconds = time.perf_counter() - start
    columns = (*OUTCOMES, "hang")
    print(f"\n{'family':<13}" + "".join(f"{c:>11}" for c in columns) + f"{'cases':>9}")
    total: Counter = Counter()
    for family in FAMILIES:
        if family in counts:
            total.update(counts[family])
            print(f"{family:<13}" + "".join(f"{counts[family][c]:>11}" for c in columns) + f"{sum(counts[family].values()):>9}")
    print(f"{'all':<13}" + "".join(f"{total[c]:>11}" for c in columns) + f"{sum(total.values()):>9}")
    print(f"\n{sum(total.values())} cases in {seconds:.0f} s: {total['ok']} ok, {total['clear']} clear errors, "
          f"{total['traceback']} tracebacks, {total['nonfinite']} non-finite outputs, {total['hang']} hangs")
    for problem in problems[:50]:
        print(f"\n--- {problem.family} seed {problem.seed}: {problem.outcome}\n{problem.detail}")
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main())
