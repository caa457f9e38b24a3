"""A real-size scene through ``spacedg qa build`` and an export: time, peak memory and scaling per stage.

Prints numbers only (never part of the test run).

    .venv/bin/python benchmarks/real_size.py --quick      # 3 small sizes: ~40 CPU s (minutes of wall time when loaded)
    .venv/bin/python benchmarks/real_size.py              # 400 views, 2 M Gaussians; 1/4, 1/2, 1 of each: ~25 CPU min
    .venv/bin/python benchmarks/real_size.py --sweep views --work /tmp/v --keep   # one sweep; merge runs:
    .venv/bin/python benchmarks/real_size.py --report /tmp/v/results.jsonl /tmp/g/results.jsonl

The scene is built in code at ScanNet++ DSLR scale: a built-in room (:func:`generate_room`) with
``--gaussians`` Gaussians, ``--views`` views at 1752×1168 (``--width``/``--height``) and 30–40
furniture instances, plus a few real ``.splat`` objects from ``--splats`` (the shared splats beside
the checkout, read at run time, never copied) when that folder exists. It is saved as a native scene
folder and each stage then runs in a **fresh child process** (one thread: ``NUMBA_NUM_THREADS``,
``OMP_NUM_THREADS`` = 1, ``qa build --jobs 1``):

- ``build``: generate the scene and save it (not part of the index; reported for completeness);
- ``load``: :func:`load_scene` of the folder;
- ``visibility``: per-view instance visibility (:func:`load_or_compute_visibility`, cached);
- ``covisibility``: the view covisibility matrix (:func:`with_covisibility`, cached);
- ``generate``: question generation and the index file (:func:`generate_records` + :func:`write_index`);
- ``export``: ``spacedg export --split bench --all-bench`` of ``--export-questions`` questions at
  the views' own size (``--export-size`` to change it), clean images, answerability off.

Each child reports the stage's wall seconds, its CPU seconds (``time.process_time``: all its
threads; on a shared machine this is what a free core would take) and its peak RSS
(``resource.getrusage(RUSAGE_SELF).ru_maxrss``: the whole process, interpreter and the scene
included, so it is what the stage needs, not what it adds). Every stage after ``load`` loads the
scene (and the caches of the stages before it) first; that load is not in its time.

Sizes: the full size, then ``--fractions`` of it in views (Gaussians full) and in Gaussians
(views full). The scaling exponent of each stage is the least-squares slope of log CPU s against
log views (resp. log Gaussians) over its sweep. The goal (issue 31): the whole index (load +
visibility + covisibility + generate) at full size in <= 10 min CPU on one core within 8 GB RSS,
and no stage growing faster than views².
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
#: The shared real splat objects beside the checkout (see their README: licences).
DEFAULT_SPLATS = REPO.parent / "shared" / "data" / "splats"
#: (folder, label, longest side in metres, placement) of the splat objects placed in the room.
SPLAT_OBJECTS = (("teapot", "teapot", 0.3, "support"), ("boot", "boot", 0.3, "floor"),
                 ("violin", "violin", 0.6, "support"), ("cat", "cat", 0.45, "floor"))
#: File (in the work folder) where every child appends its report; ``--report`` reads them back.
RESULTS = "results.jsonl"
INDEX_STAGES = ("load", "visibility", "covisibility", "generate")
STAGES = ("build", *INDEX_STAGES, "export")
#: The goal of issue 31 for the whole index at full size.
GOAL_CPU_S = 600.0
GOAL_RSS_MB = 8192.0
GOAL_VIEW_EXPONENT = 2.0
ONE_THREAD = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


# ------------------------------------------------------------------ the scene
def splat_objects(folder: Path | None) -> tuple:
    """The :data:`SPLAT_OBJECTS` found under ``folder`` as ``ExternalObject`` s (none if it is absent)."""
    from spacedg.scene.synthetic import ExternalObject

    if folder is None or not folder.is_dir():
        return ()
    found = []
    for name, label, size_m, placement in SPLAT_OBJECTS:
        path = folder / name / f"{name}_10k.splat"
        if path.is_file():
            found.append(ExternalObject.from_splat(path, label=label, size_m=size_m, placement=placement))
    return tuple(found)


def real_size_scene(gaussians: int, views: int, *, seed: int = 0, width: int = 1752, height: int = 1168,
                    splats: Path | None = DEFAULT_SPLATS, objects: tuple[int, int] = (30, 40)):
    """A built-in room at real size: ``gaussians`` Gaussians (within a few %), exactly ``views`` views
    of ``width × height`` pixels, ``objects`` (min, max) furniture instances plus the splat objects.

    The room's layout, furniture and Gaussians do not depend on ``views`` (independent random
    streams), so a views sweep renders the same room; a Gaussians sweep samples the same surfaces
    more or less densely."""
    from spacedg.scene.synthetic import CaptureConfig, RoomConfig, generate_room

    config = RoomConfig(gaussians=int(gaussians), min_objects=objects[0], max_objects=objects[1],
                        capture=CaptureConfig(width, height, int(views), int(views)), external=splat_objects(splats))
    return generate_room(seed, config, scene_id=f"real-{views}v-{gaussians // 1000}k")


# ----------------------------------------------------------- stages (child side)
def _load(folder: Path):
    from spacedg.scene.io import load_scene

    return load_scene(folder)


def _prepared(folder: Path, through: str):
    """The scene of ``folder`` with the cached stages before ``through`` attached."""
    from spacedg.qa.index import QABuildConfig
    from spacedg.scene.covisibility import with_covisibility
    from spacedg.scene.labelling import ensure_instance_ids
    from spacedg.scene.visibility import load_or_compute_visibility, with_visibility

    config = QABuildConfig()
    scene = ensure_instance_ids(_load(folder))
    if through in ("covisibility", "generate"):
        table = load_or_compute_visibility(scene, folder / "cache", image_size=config.visibility_size, progress=False)
        scene = with_visibility(scene, table)
    if through == "generate":
        scene = with_covisibility(scene, folder / "cache", image_size=config.covisibility_size, progress=False)
    return scene


def _stage_callable(stage: str, folder: Path, args: argparse.Namespace) -> tuple[Callable[[], object], dict]:
    """What the child times for ``stage`` (after its set-up) and facts about the input."""
    from spacedg.qa.index import QABuildConfig

    config = QABuildConfig()
    if stage == "build":
        def run() -> object:
            from spacedg.scene.io import save_scene

            scene = real_size_scene(args.gaussians, args.views, seed=args.seed, width=args.width, height=args.height,
                                    splats=args.splats)
            save_scene(scene, folder)
            return {"gaussians": len(scene.gaussians), "views": len(scene.views), "objects": len(scene.instances)}
        return run, {}
    if stage == "load":
        return (lambda: len(_load(folder).gaussians)), {}
    if stage == "export":
        return (lambda: _export(folder, args)), {}
    scene = _prepared(folder, stage)
    facts = {"gaussians": len(scene.gaussians), "views": len(scene.views), "objects": len(scene.instances)}
    if stage == "visibility":
        from spacedg.scene.visibility import load_or_compute_visibility

        return (lambda: len(load_or_compute_visibility(scene, folder / "cache", image_size=config.visibility_size,
                                                       progress=False))), facts
    if stage == "covisibility":
        from spacedg.scene.covisibility import with_covisibility

        return (lambda: with_covisibility(scene, folder / "cache", image_size=config.covisibility_size,
                                          progress=False).covisibility.matrix.shape), facts
    return (lambda: _generate(scene, folder, config)), facts


def _generate(scene, folder: Path, config) -> int:
    """``qa build``'s generation and index writing for a prepared scene (same key as ``qa build``)."""
    from spacedg.qa.build import generate_records
    from spacedg.qa.index import QA_INDEX_VERSION, index_key, index_paths, scene_json_path, selected_families, write_index

    records = generate_records(scene, config)
    key = index_key(scene_json_path(folder), config, selected_families(config.families), None)
    jsonl, meta_path = index_paths(scene.id, folder, config.families, config.mode)
    meta = {"format": "spacedg-qa-index", "version": QA_INDEX_VERSION, "key": key, "scene_id": scene.id,
            "config": config.to_dict(), "records": len(records), "seconds": {}}
    write_index(jsonl, meta_path, records, meta)
    return len(records)


def _export(folder: Path, args: argparse.Namespace) -> int:
    """``spacedg export`` of ``args.export_questions`` clean bench questions of the scene."""
    from spacedg.cli import main as cli

    out = folder.parent / f"{folder.name}-export"
    shutil.rmtree(out, ignore_errors=True)
    argv = ["export", "--split", "bench", "--all-bench", "--scenes", str(folder), "--out", str(out),
            "--degradations", "clean", "--max-questions", str(args.export_questions), "--answerability", "off",
            "--no-progress"]
    if args.export_size:
        argv += ["--image-size", args.export_size]
    code = cli(argv)
    if code != 0:
        raise SystemExit(f"export failed with exit code {code}")
    return len(list((out / "images").rglob("*.*"))) if (out / "images").is_dir() else 0


def run_stage(stage: str, folder: Path, args: argparse.Namespace) -> dict:
    """Child side: set the stage up, time it, return wall s, CPU s, peak RSS MB and what it made."""
    run, facts = _stage_callable(stage, folder, args)
    wall, cpu = time.perf_counter(), time.process_time()
    result = run()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux
    if isinstance(result, dict):
        facts.update(result)
    return {"stage": stage, "wall_s": wall, "cpu_s": cpu, "rss_mb": peak_mb, "result": str(result), **facts}


# --------------------------------------------------------------- parent side
@dataclass(frozen=True)
class Size:
    """One scene size: its views and target Gaussians."""

    views: int
    gaussians: int

    @property
    def name(self) -> str:
        return f"{self.views}v/{self.gaussians / 1e3:,.0f}k"


def sizes(views: int, gaussians: int, fractions: Sequence[float]) -> tuple[list[Size], list[Size]]:
    """The views sweep (Gaussians full) and the Gaussians sweep (views full), each ending at full size."""
    by_views = [Size(max(2, round(views * f)), gaussians) for f in sorted(fractions)]
    by_gaussians = [Size(views, max(10_000, round(gaussians * f))) for f in sorted(fractions)]
    return by_views, by_gaussians


def _child(stage: str, folder: Path, size: Size, args: argparse.Namespace) -> dict:
    """Run one stage in a fresh one-thread Python process; its JSON report."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", stage, "--folder", str(folder),
           "--views", str(size.views), "--gaussians", str(size.gaussians), "--seed", str(args.seed),
           "--width", str(args.width), "--height", str(args.height), "--export-questions", str(args.export_questions),
           "--splats", str(args.splats)]
    if args.export_size:
        cmd += ["--export-size", args.export_size]
    env = {**os.environ, **ONE_THREAD, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
    if done.returncode != 0 or not lines:
        sys.stderr.write(done.stdout[-3000:] + done.stderr[-3000:])
        raise SystemExit(f"stage {stage} at {size.name} failed (exit {done.returncode})")
    return json.loads(lines[-1])


def measure(size: Size, work: Path, args: argparse.Namespace) -> dict[str, dict]:
    """Every stage of one size, each in its own child; stage → report."""
    folder = work / f"real-{size.views}v-{size.gaussians}"
    shutil.rmtree(folder, ignore_errors=True)
    out = {}
    for stage in STAGES:
        if stage == "export" and args.export_questions == 0:
            continue
        out[stage] = _child(stage, folder, size, args)
        r = out[stage]
        print(f"  {size.name:<14} {stage:<13} {r['wall_s']:>8.1f} {r['cpu_s']:>8.1f} {r['rss_mb']:>9.0f}", flush=True)
    if not args.keep:
        shutil.rmtree(folder, ignore_errors=True)
        shutil.rmtree(work / f"{folder.name}-export", ignore_errors=True)
    return out


def slope(xs: Sequence[float], ys: Sequence[float]) -> float:
    """Least-squares slope of log y against log x (nan with fewer than two distinct positive points)."""
    x, y = np.log(np.asarray(xs, float)), np.log(np.maximum(np.asarray(ys, float), 1e-3))
    if len(set(xs)) < 2:
        return float("nan")
    return float(np.polyfit(x, y, 1)[0])


def print_table(results: dict[Size, dict[str, dict]]) -> None:
    print(f"\n{'size':<14} {'stage':<13} {'wall s':>8} {'CPU s':>8} {'peak RSS MB':>11}")
    for size, stages in results.items():
        first = stages.get("visibility", {})
        about = f"   ({first.get('gaussians', '?'):,} Gaussians, {first.get('objects', '?')} objects)" if first else ""
        for stage, r in stages.items():
            print(f"{size.name:<14} {stage:<13} {r['wall_s']:>8.1f} {r['cpu_s']:>8.1f} {r['rss_mb']:>11.0f}")
        index = [stages[s] for s in INDEX_STAGES if s in stages]
        if not index:
            continue
        print(f"{size.name:<14} {'= index':<13} {sum(r['wall_s'] for r in index):>8.1f} {sum(r['cpu_s'] for r in index):>8.1f} "
              f"{max(r['rss_mb'] for r in index):>11.0f}{about}")


def _stage_cpu(stages: dict[str, dict], stage: str) -> float | None:
    """CPU s of ``stage`` (``"index"``: the index stages together), None when not measured."""
    names = INDEX_STAGES if stage == "index" else (stage,)
    return sum(stages[s]["cpu_s"] for s in names) if all(s in stages for s in names) else None


def exponents(results: dict[Size, dict[str, dict]], by_views: list[Size], by_gaussians: list[Size]) -> dict[str, tuple[float, ...]]:
    """Stage → CPU-s exponents (views, Gaussians, views over the last step, Gaussians over the last step)
    over the sizes where the stage was measured; also ``"index"``. The last step (the two largest sizes)
    shows a quadratic term that small sizes hide."""
    out = {}
    for stage in (*STAGES, "index"):
        fits = []
        for sweep, axis in ((by_views, lambda s: s.views), (by_gaussians, lambda s: results[s].get("build", {}).get("gaussians", s.gaussians))):
            points = [(axis(s), _stage_cpu(results[s], stage)) for s in sweep]
            points = [(x, y) for x, y in points if y is not None]
            fits.append((slope([x for x, _ in points], [y for _, y in points]) if len(points) >= 2 else float("nan"),
                         slope([x for x, _ in points[-2:]], [y for _, y in points[-2:]]) if len(points) >= 2 else float("nan")))
        out[stage] = (fits[0][0], fits[1][0], fits[0][1], fits[1][1])
    return out


def verdict(full: dict[str, dict], slopes: dict[str, tuple[float, ...]]) -> list[str]:
    """Lines saying whether the goal holds at full size."""
    cpu = sum(full[s]["cpu_s"] for s in INDEX_STAGES)
    rss = max(full[s]["rss_mb"] for s in INDEX_STAGES)
    worst = max((max(e[0], e[2]) for e in slopes.values() if e[0] == e[0]), default=float("nan"))
    growth = (f"largest views exponent {worst:.2f} {'<=' if worst <= GOAL_VIEW_EXPONENT + 0.15 else '>'} 2 (+0.15 noise): "
              f"{'met' if worst <= GOAL_VIEW_EXPONENT + 0.15 else 'NOT met'}") if worst == worst else "views exponent unknown (one views size)"
    return [
        f"index CPU {cpu:.0f} s {'<=' if cpu <= GOAL_CPU_S else '>'} {GOAL_CPU_S:.0f} s: {'met' if cpu <= GOAL_CPU_S else 'NOT met'}",
        f"index peak RSS {rss:.0f} MB {'<=' if rss <= GOAL_RSS_MB else '>'} {GOAL_RSS_MB:.0f} MB: {'met' if rss <= GOAL_RSS_MB else 'NOT met'}",
        growth,
    ]


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--views", type=int, default=400, help="views at full size (default 400)")
    parser.add_argument("--gaussians", type=int, default=2_000_000, help="Gaussians at full size (default 2,000,000)")
    parser.add_argument("--fractions", default="0.25,0.5,1", help="sweep fractions of the full size (default 0.25,0.5,1)")
    parser.add_argument("--sweep", choices=("both", "views", "gaussians"), default="both",
                        help="which sweep to run (default both; merge separate runs with --report)")
    parser.add_argument("--width", type=int, default=1752)
    parser.add_argument("--height", type=int, default=1168)
    parser.add_argument("--seed", type=int, default=0, help="room seed")
    parser.add_argument("--export-questions", type=int, default=8, help="questions exported (0: no export; default 8)")
    parser.add_argument("--export-size", default="", help="WxH export bounding box (default: the views' own size)")
    parser.add_argument("--splats", type=Path, default=DEFAULT_SPLATS, help="shared .splat objects to place (skipped if absent)")
    parser.add_argument("--work", type=Path, default=None, help="folder for the scenes (default: a temporary one)")
    parser.add_argument("--keep", action="store_true", help="keep the scene folders")
    parser.add_argument("--quick", action="store_true", help="small run: 24 views, 60k Gaussians, 640x480, fractions 0.5,1")
    parser.add_argument("--report", type=Path, nargs="+", default=None, metavar="FILE",
                        help="only print the table of earlier runs' results files (merged)")
    parser.add_argument("--no-warm-up", action="store_true", help="skip the small uncounted first run (numba compilation)")
    parser.add_argument("--child", choices=STAGES, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--folder", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.quick:
        args.views, args.gaussians, args.fractions, args.width, args.height = 24, 60_000, "0.5,1", 640, 480
        args.export_questions = min(args.export_questions, 4)
    return args


def read_results(paths: Sequence[Path]) -> dict[Size, dict[str, dict]]:
    """Size → stage → report from results files (a later report of the same size and stage wins)."""
    out: dict[Size, dict[str, dict]] = {}
    for path in paths:
        for line in Path(path).read_text(encoding="utf-8").splitlines():
            if line.strip():
                r = json.loads(line)
                out.setdefault(Size(int(r["views_asked"]), int(r["gaussians_asked"])), {})[r["stage"]] = r
    return {size: {s: st[s] for s in STAGES if s in st} for size, st in out.items()}


def report(results: dict[Size, dict[str, dict]], project: tuple[int, int] = (500, 3_000_000)) -> None:
    """Print the table, the exponents and the verdict; the full size is the most views and Gaussians;
    ``project``: (views, Gaussians) to project the index's CPU time to (the top of ScanNet++ DSLR scale)."""
    full_v, full_g = max(s.views for s in results), max(s.gaussians for s in results)
    by_views = sorted((s for s in results if s.gaussians == full_g), key=lambda s: s.views)
    by_gaussians = sorted((s for s in results if s.views == full_v), key=lambda s: s.gaussians)
    print_table(dict(sorted(results.items(), key=lambda kv: (-kv[0].views, -kv[0].gaussians))))
    slopes = exponents(results, by_views, by_gaussians)
    print(f"\nscaling exponents of CPU s (log-log slope): views {[s.views for s in by_views]}, "
          f"Gaussians {[results[s].get('build', {}).get('gaussians', s.gaussians) for s in by_gaussians]}")
    print(f"{'stage':<13} {'views':>7} {'Gaussians':>10} {'views (last step)':>18} {'Gaussians (last step)':>22}")
    for stage, (v, g, v_last, g_last) in slopes.items():
        print(f"{stage:<13} {v:>7.2f} {g:>10.2f} {v_last:>18.2f} {g_last:>22.2f}")
    full = Size(full_v, full_g)
    if full in results and all(s in results[full] for s in INDEX_STAGES):
        print(f"\ngoal at full size {full.name}:")
        for line in verdict(results[full], slopes):
            print("  " + line)
        print("  " + projection(results[full], slopes, project))


def projection(full: dict[str, dict], slopes: dict[str, tuple[float, ...]], target: tuple[int, int]) -> str:
    """The index's CPU s projected from the full size to ``target`` (views, Gaussians), each stage
    scaled by its last-step exponents (``cpu × (V'/V)^a_views × (G'/G)^a_gaussians``; unknown: 1)."""
    views, gaussians = full["visibility"].get("views"), full["visibility"].get("gaussians")
    if not views or not gaussians:
        return "no projection (the full size's views and Gaussians are unknown)"
    if views < 100 or gaussians < 500_000:
        return "no projection from so small a full size (exponents of tiny scenes are dominated by fixed costs)"
    total = 0.0
    for stage in INDEX_STAGES:
        a_v, a_g = slopes.get(stage, (float("nan"),) * 4)[2:]
        a_v, a_g = (1.0 if a_v != a_v else a_v), (1.0 if a_g != a_g else a_g)  # unknown exponent: linear
        total += full[stage]["cpu_s"] * (target[0] / views) ** max(a_v, 0.0) * (target[1] / gaussians) ** max(a_g, 0.0)
    return f"projected index CPU at {target[0]} views x {target[1]:,} Gaussians: {total:.0f} s"


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv)
    if args.child:
        report_ = {"views_asked": args.views, "gaussians_asked": args.gaussians, **run_stage(args.child, args.folder, args)}
        with open(args.folder.parent / RESULTS, "a", encoding="utf-8") as log:  # every report, for --report
            log.write(json.dumps(report_) + "\n")
        print(json.dumps(report_))
        return
    if args.report:
        report(read_results(args.report))
        return
    by_views, by_gaussians = sizes(args.views, args.gaussians, [float(f) for f in args.fractions.split(",")])
    work = args.work or Path(tempfile.mkdtemp(prefix="spacedg-real-size-"))
    work.mkdir(parents=True, exist_ok=True)
    (work / RESULTS).unlink(missing_ok=True)
    print(f"real-size benchmark: {args.width}x{args.height}, one thread per stage, scenes in {work}")
    print(f"  {'size':<14} {'stage':<13} {'wall s':>8} {'CPU s':>8} {'RSS MB':>9}")
    if not args.no_warm_up:  # numba compiles (or loads its cache) on first use: not part of any size
        warm = argparse.Namespace(**{**vars(args), "width": 320, "height": 240, "keep": False,
                                     "export_questions": min(args.export_questions, 2)})
        print("  (warm-up, not counted)")
        (work / "warm-up").mkdir(exist_ok=True)
        measure(Size(4, 20_000), work / "warm-up", warm)
    chosen = {"both": [*by_views, *by_gaussians], "views": by_views, "gaussians": by_gaussians}[args.sweep]
    for size in dict.fromkeys(chosen):
        measure(size, work, args)
    report(read_results([work / RESULTS]))
    print(f"(reports in {work / RESULTS}: print them again, or merge runs, with --report FILE ...)")
    if args.work is None and not args.keep:
        shutil.rmtree(work, ignore_errors=True)

if __name__ == "__main__":
    main()
